"""The Bricard mechanism's redundant constraint.

benchmarks/stability/bricard.mech: five rods and the ground in a closed loop of six
revolute joints (Bricard's orthogonal linkage, the IFToMM A04 type).  Cutting the loop at
the last joint gives five constraints on five joint angles: counting says the linkage is
rigid, yet it moves with one degree of freedom, because one constraint is redundant
everywhere (G has rank 4).  With every constraint row kept, the augmented (KKT) system is
singular: the multipliers come out at 1e15 and every integrator fails at the first step.
mechdsl.dae finds the rank, drops the redundant row and simulates; the run keeps the loop
closed and the energy constant, and three methods on the reduced system agree.
"""
from __future__ import annotations

import warnings

import numpy as np

from .suite import Case, check_size, fmt_fail, load, pyplot, save

MODEL = "benchmarks/stability/bricard.mech"
TOL = 1e-10
NAIVE = ("erk", "cvodes-bdf", "scipy-dop853")   # naive runs: 10 ms, 500 steps an output interval (they stop at once)
REDUCED = {"projection+cvodes-bdf": ("projection", "cvodes-bdf"), "ggl+idas": ("ggl", "idas")}


def run(size: str = "small") -> Case:
    from mechdsl.bench.index1 import simulate_index1
    from mechdsl.dae.dof import dof_report
    from mechdsl.simulate import simulate

    check_size(size)
    T = 1.0 if size == "small" else 10.0
    pts = int(T * 20) + 1
    e = load(MODEL, scene="Fall").eom
    q0, _ = e.start()
    dof = dof_report(e, q0, 0.0, np.array(e.param_values, float))
    case = Case(name="bricard", title="Bricard mechanism: a permanently redundant constraint", size=size)
    naive, reduced = {}, {}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for meth in NAIVE:
            naive[meth] = simulate_index1(e, 0.01, method=meth, constraints="all", rtol=TOL, atol=TOL, points=11,
                                          max_steps=500)
            reduced[f"index1-ode+{meth}"] = simulate_index1(e, T, method=meth, rtol=TOL, atol=TOL, points=pts)
        for lab, (form, meth) in REDUCED.items():
            reduced[lab] = simulate(e, T, rtol=TOL, atol=TOL, method=meth, formulation=form, points=pts, error_estimate="off")

    def res(r):
        return max(float(np.abs(r.signals[k]).max()) for k in r.signals if k.startswith("residual("))

    def edrift(r):
        E = r["energy"]
        return float(np.abs(E - E[0]).max() / max(abs(E[0]), np.abs(r["kinetic_energy"]).max(),
                                                   np.abs(r["potential_energy"]).max()))

    base = reduced["projection+cvodes-bdf"]
    spread = max(float(np.abs(r.q[-1] - base.q[-1]).max()) for r in reduced.values() if r.success)
    case.data.update(dof=dof, naive=naive, reduced=reduced, T=T)
    case.table.append(f"  {dof.coordinates} coordinates, {dof.constraints} constraints, rank of G {dof.rank}: "
                      f"{dof.dof} degree(s) of freedom, redundant: {', '.join(dof.redundant_names) or 'none'}; "
                      f"singular values {', '.join(f'{s:.2g}' for s in dof.singular_values)}")
    for meth, r in naive.items():
        case.table.append(f"  all 5 constraint rows, {meth:12s}: {fmt_fail(r)}")
    for lab, r in reduced.items():
        case.table.append(f"  {lab:28s}: {fmt_fail(r)}; max |g| {res(r):.1e}, energy drift {edrift(r):.1e}, "
                          f"angles at T {np.array2string(r.q[-1], precision=5)}")
    case.check("the rank test finds one degree of freedom and one redundant constraint where counting finds none",
               dof.dof == 1 and dof.redundant == 1 and dof.coordinates - dof.constraints == 0,
               f"dof {dof.dof}, redundant {dof.redundant_names}")
    case.check("with the redundant row kept, every integrator fails at once (singular KKT system)",
               all(not r.success and r.failure.time < 1e-3 for r in naive.values()),
               "; ".join(f"{m}: {fmt_fail(r)[:50]}" for m, r in naive.items()))
    case.check("with it dropped every method runs, keeps the loop closed (max |g| <= 1e-6) and the energy (<= 1e-6)",
               all(r.success and res(r) <= 1e-6 and edrift(r) <= 1e-6 for r in reduced.values()),
               ", ".join(f"{k} {res(r):.0e}/{edrift(r):.0e}" for k, r in reduced.items()))
    case.check("the linkage really moves and the methods agree on where it is at T (angles within 1e-5)",
               float(np.abs(base.q[-1] - base.q[0]).max()) > 0.1 and spread <= 1e-5,
               f"largest angle change {np.abs(base.q[-1] - base.q[0]).max():.2f} rad, spread at T {spread:.1e}")
    return case


def chart(case: Case, out_dir) -> list:
    plt = pyplot()
    d = case.data
    fig, (a1, a2) = plt.subplots(1, 2, figsize=(11, 4.3))
    r = d["reduced"]["projection+cvodes-bdf"]
    for i, c in enumerate(r.coordinates):
        a1.plot(r.t, r.q[:, i], lw=1.2, label=c)
    a1.set_xlabel("t [s]")
    a1.set_ylabel("joint angle [rad]")
    a1.legend(fontsize="x-small")
    a1.grid(True, alpha=0.3)
    a1.set_title("redundant row dropped: the linkage moves (1 dof)", fontsize="medium")
    names = list(d["reduced"]) + [f"all rows, {m}" for m in d["naive"]]
    reached = [d["reduced"][k].t[-1] for k in d["reduced"]] + [max(v.failure.time if v.failure else v.t[-1], 1e-9)
                                                               for v in d["naive"].values()]
    colors = ["tab:blue"] * len(d["reduced"]) + ["tab:red"] * len(d["naive"])
    a2.barh(names, reached, color=colors)
    a2.set_xscale("log")
    a2.set_xlabel("simulated time reached [s]")
    a2.tick_params(axis="y", labelsize="x-small")
    a2.set_title("with all five rows the KKT system is singular", fontsize="medium")
    fig.suptitle("Bricard's orthogonal linkage: counting gives 0 dof, the rank of G gives 1", fontsize="medium")
    fig.tight_layout()
    return save(fig, out_dir, "stability_bricard")
