"""Stiff spring pendulum: explicit methods need tiny steps or blow up, implicit ones do not.

benchmarks/stability/stiff_spring_pendulum.mech: a pendulum on a critically damped spring
(k = 1e8 N/m, eigenvalues of the spring mode -1e4/s) swinging with a period of about 2 s.
At the same tolerance the explicit adaptive methods are held to steps of about 3/1e4 s by
stability alone; the fixed-step classical Runge-Kutta method with a step that resolves the
swing (dt = 0.01 s, 200 steps a period) blows up, while the L-stable Radau IIA collocation
with the same step integrates it accurately.
"""
from __future__ import annotations

import numpy as np

from .suite import Case, check_size, fmt_fail, load, pyplot, save

MODEL = "benchmarks/stability/stiff_spring_pendulum.mech"
TOL = 1e-6
EXPLICIT = ("erk", "scipy-rk45")
IMPLICIT = ("cvodes-bdf", "rosenbrock", "scipy-radau")
DT = 0.01


def run(size: str = "small") -> Case:
    from mechdsl.eom.codegen import casadi_functions
    from mechdsl.eom import parameter_vector
    from mechdsl.simulate import simulate
    from mechdsl.eom.start import start_vector

    check_size(size)
    T = 1.0 if size == "small" else 10.0
    m = load(MODEL, scene="Swing")
    e = m.eom
    pts = 101
    case = Case(name="stiff", title="Stiff spring pendulum", size=size)
    pv = parameter_vector(e, None)
    J = np.array(casadi_functions(e, names=("ode", "ode_jacobian"))["ode_jacobian"](0.0, start_vector(e, None, pv), [], pv))
    lam = float(np.abs(np.linalg.eigvals(J)).max())
    ref = simulate(e, T, rtol=1e-11, atol=1e-11, method="rosenbrock", points=pts, error_estimate="off")
    chk = simulate(e, T, rtol=1e-11, atol=1e-11, method="scipy-radau", points=pts, error_estimate="off")
    ref_acc = float(np.abs(ref.q - chk.q).max())
    runs = {}
    for meth in EXPLICIT + IMPLICIT + ("auto",):
        runs[meth] = simulate(e, T, rtol=TOL, atol=TOL, method=meth, points=pts, error_estimate="off")
    fixed = {meth: simulate(e, T, method=meth, dt=DT, points=pts, error_estimate="off") for meth in ("rk", "collocation")}
    case.data.update(T=T, lam=lam, ref=ref, runs=runs, fixed=fixed, ref_acc=ref_acc)

    def err(r):
        return float(np.abs(r.q - ref.q).max()) if r.success else float("inf")

    case.table.append(f"  spring mode |lambda| = {lam:.3g} /s; T = {T:g} s; reference rosenbrock at 1e-11 "
                      f"(differs from scipy-radau at 1e-11 by {ref_acc:.1e})")
    case.table.append(f"  {'method':20s} {'steps':>8s} {'RHS evals':>10s} {'max |q - q_ref|':>16s}  status")
    for meth, r in list(runs.items()) + [(f"{k} dt={DT:g}", v) for k, v in fixed.items()]:
        case.table.append(f"  {meth:20s} {r.stats.get('steps', 0):8d} {str(r.stats.get('rhs_evals', '-')):>10s} "
                          f"{err(r):16.2e}  {fmt_fail(r)}")
    case.check("auto detects the stiffness and chooses cvodes-bdf", runs["auto"].metadata.get("method") == "cvodes-bdf",
               f"auto chose {runs['auto'].metadata.get('method')}: {runs['auto'].metadata.get('method_reason', '')[:90]}")
    exp_steps = min(runs[k].stats["steps"] for k in EXPLICIT)
    imp_steps = max(runs[k].stats["steps"] for k in IMPLICIT)
    case.check("explicit adaptive methods take >= 10x the steps of the implicit ones at the same tolerance",
               exp_steps >= 10 * imp_steps, f"fewest explicit {exp_steps}, most implicit {imp_steps} "
                                            f"(ratio {exp_steps / imp_steps:.1f}) at rtol = atol = {TOL:g}")
    bound = T * lam / 3.5
    case.check("the explicit steps are set by stability (h < ~3.3/|lambda|), not by the motion",
               exp_steps >= 0.8 * bound, f"{exp_steps} steps >= 0.8 x T |lambda| / 3.5 = {0.8 * bound:.0f}")
    case.check("every adaptive run finishes with an error below 1000 x the tolerance",
               all(r.success and err(r) <= 1000 * TOL for r in runs.values()),
               ", ".join(f"{k} {err(r):.1e}" for k, r in runs.items()))
    case.check(f"fixed-step RK4 with dt = {DT:g} s (200 steps a swing) fails", not fixed["rk"].success,
               fmt_fail(fixed["rk"]))
    case.check(f"fixed-step Radau IIA collocation with the same dt is accurate (error <= 1e-4)",
               fixed["collocation"].success and err(fixed["collocation"]) <= 1e-4,
               f"{fmt_fail(fixed['collocation'])}, error {err(fixed['collocation']):.1e}")
    return case


def chart(case: Case, out_dir) -> list:
    plt = pyplot()
    d = case.data
    fig, (a1, a2) = plt.subplots(1, 2, figsize=(11, 4.3))
    names = list(d["runs"])
    steps = [d["runs"][k].stats["steps"] for k in names]
    colors = ["tab:red" if k in EXPLICIT else "tab:blue" if k in IMPLICIT else "tab:gray" for k in names]
    a1.bar(names, steps, color=colors)
    a1.set_yscale("log")
    a1.set_ylabel(f"steps at rtol = atol = {TOL:g}")
    a1.set_title("adaptive steps (red: explicit, blue: implicit)", fontsize="medium")
    a1.tick_params(axis="x", labelrotation=30)
    a1.axhline(d["T"] * d["lam"] / 3.3, color="tab:red", ls=":", lw=1)
    a1.annotate("T |lambda| / 3.3 (explicit stability limit)", xy=(0.02, d["T"] * d["lam"] / 3.3),
                xycoords=("axes fraction", "data"), xytext=(0, 3), textcoords="offset points", fontsize="x-small")
    ref = d["ref"]
    a2.plot(ref.t, ref["theta"], color="k", lw=2.5, alpha=0.35, label="reference")
    for k, style in (("collocation", "-"), ("rk", "--")):
        r = d["fixed"][k]
        a2.plot(r.t, r["theta"], style, lw=1.3, label=f"{k}, dt = {DT:g}: {fmt_fail(r)}")
        if not r.success:
            a2.axvline(r.failure.time, color="tab:red", lw=0.8, ls=":")
    lo, hi = float(ref["theta"].min()), float(ref["theta"].max())
    a2.set_ylim(lo - 0.3 * (hi - lo), hi + 0.3 * (hi - lo))          # the blow-up leaves the frame
    a2.set_xlabel("t [s]")
    a2.set_ylabel("theta [rad]")
    a2.set_title("fixed step resolving the swing", fontsize="medium")
    a2.legend(fontsize="x-small")
    fig.suptitle(f"Stiff spring pendulum (spring mode {d['lam']:.0f}/s, swing period ~2 s)", fontsize="medium")
    fig.tight_layout()
    return save(fig, out_dir, "stability_stiff")
