"""Energy over 10^5 periods: non-symplectic methods drift, symplectic ones stay bounded.

The pendulum of models/pendulum.mech released from the horizontal (period P =
2.367841947576237 s, a closed form: docs/../references).  Methods, at equal cost where
they are fixed-step: Stormer-Verlet with P/200 (one force evaluation a step) and the
classical Runge-Kutta method with P/50 (four a step: the same number of evaluations);
the 4th-order symplectic Gauss-Legendre method with P/50; the adaptive erk at
rtol = atol = 1e-8.  The energy error of the symplectic methods oscillates with a bounded
amplitude; that of the others grows linearly with time.

Sampling: the energy is recorded every (k + 0.38) periods, so that the samples sweep
every phase of the swing (recording at a fixed phase hides the oscillating error of a
symplectic method).
"""
from __future__ import annotations


import numpy as np

from .suite import Case, check_size, fmt_fail, load, pyplot, save

MODEL = "models/pendulum.mech"
PERIOD = 2.367841947576237
SYMPLECTIC = {"stormer-verlet": 200, "gauss-legendre": 50}          # steps a period
OTHERS = {"rk4": 50}
ADAPTIVE_TOL = 1e-8
SAMPLES = 20000


def _stride(periods: int, per_period: int) -> int:
    k = max(0, round(periods / SAMPLES - 0.38))
    return per_period * k + round(0.38 * per_period)


def run(size: str = "small") -> Case:
    from mechdsl.simulate import simulate

    check_size(size)
    periods = 200 if size == "small" else 100_000
    T = periods * PERIOD
    e = load(MODEL, model="Pendulum").eom
    case = Case(name="energy", title=f"Energy over {periods:g} periods", size=size)
    runs = {}
    for meth, spp in {**SYMPLECTIC, **OTHERS}.items():
        nsteps = periods * spp
        pts = nsteps // _stride(periods, spp) + 1
        # (the full size takes up to 2e7 steps, past the default step budget's 10 x 1e6: asked for)
        runs[meth] = simulate(e, T, method=meth, dt=PERIOD / spp, points=pts, error_estimate="off",
                              budget=max(1_000_000, nsteps // 10 + 1))
    pts = periods * 200 // _stride(periods, 200) + 1
    runs["erk"] = simulate(e, T, rtol=ADAPTIVE_TOL, atol=ADAPTIVE_TOL, method="erk", points=pts, error_estimate="off")
    scale = 9.81          # m g L: the energy scale (E(0) = 0 from the horizontal)
    curves, growth = {}, {}
    for k, r in runs.items():
        dE = np.abs(r["energy"] - r["energy"][0]) / scale
        curves[k] = (r.t, dE)
        tenth = r.t <= r.t[-1] / 10
        growth[k] = float(dE.max() / max(dE[tenth].max(), 1e-300))
    case.data.update(runs=runs, curves=curves, growth=growth, periods=periods)
    case.table.append(f"  {'method':16s} {'dt':>10s} {'steps':>10s} {'max|dE|/mgL':>12s} {'first 10%':>10s} "
                      f"{'growth':>8s}  status")
    for k, r in runs.items():
        t, dE = curves[k]
        dt = r.metadata.get("dt") or float("nan")
        case.table.append(f"  {k:16s} {dt:10.4g} {r.stats.get('steps', 0):10d} {dE.max():12.3e} "
                          f"{dE[t <= t[-1] / 10].max():10.3e} {growth[k]:8.2f}  {fmt_fail(r)}")
    for k in SYMPLECTIC:
        case.check(f"{k} (symplectic): the energy error stays bounded (max over the run <= 1.5 x max over "
                   f"the first tenth)", runs[k].success and growth[k] <= 1.5, f"ratio {growth[k]:.3f}")
    for k in list(OTHERS) + ["erk"]:
        case.check(f"{k} (not symplectic): the energy error grows (max over the run >= 5 x max over the first "
                   f"tenth)", runs[k].success and growth[k] >= 5, f"ratio {growth[k]:.2f}")
    sv, rk = curves["stormer-verlet"][1].max(), curves["rk4"][1].max()
    case.check("at equal cost (force evaluations) RK4 ends with a larger energy error than Stormer-Verlet",
               rk > sv, f"rk4 {rk:.2e}, stormer-verlet {sv:.2e}")
    return case


def chart(case: Case, out_dir) -> list:
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(8, 4.6))
    styles = {"stormer-verlet": "tab:blue", "gauss-legendre": "tab:green", "rk4": "tab:red", "erk": "tab:orange"}
    for k, (t, dE) in case.data["curves"].items():
        r = case.data["runs"][k]
        tt = t[1:] / PERIOD
        lab = {"stormer-verlet": "Stormer-Verlet, P/200 (symplectic)", "gauss-legendre": "Gauss-Legendre, P/50 "
               "(symplectic)", "rk4": "RK4, P/50 (same force evaluations as S-V)",
               "erk": f"erk, adaptive, tol {ADAPTIVE_TOL:g}"}[k]
        ax.plot(tt, np.maximum(dE[1:], 1e-17), lw=0.6, color=styles[k], label=f"{lab}: growth x{case.data['growth'][k]:.1f}"
                + ("" if r.success else " (failed)"))
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("time [periods]")
    ax.set_ylabel("|E(t) - E(0)| / (m g L)")
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize="x-small", loc="lower right")
    ax.set_title(f"Pendulum from the horizontal, {case.data['periods']:g} periods: energy error", fontsize="medium")
    fig.tight_layout()
    return save(fig, out_dir, "stability_energy")
