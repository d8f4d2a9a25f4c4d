"""The chaotic double pendulum: nearby starts diverge while the energy error stays at the
tolerance.

models/double_pendulum.mech (two uniform rods, released from the horizontal).  Two starts
1e-9 rad apart, each integrated by erk at 1e-12 and 1e-10: the trajectories separate
exponentially (about a factor e each second) to order one, while every run keeps its
energy to about the tolerance.  That the separation is the dynamics and not the numerics
is shown by two independent methods (erk and scipy's DOP853) at 1e-12 for the same start:
they agree to a small fraction of the separation throughout.  A conserved energy does not
make a trajectory right: the run at 1e-10 keeps its energy to 1e-9 yet ends far from the
run at 1e-12.
"""
from __future__ import annotations

import numpy as np

from .suite import Case, check_size, load, pyplot, save

MODEL = "models/double_pendulum.mech"
DELTA = 1e-9
TOLS = (1e-12, 1e-10)


def run(size: str = "small") -> Case:
    from mechdsl.simulate import simulate

    check_size(size)
    T = 16.0 if size == "small" else 20.0
    pts = int(T * 100) + 1
    e = load(MODEL, scene="Chaos").eom
    case = Case(name="chaos", title="Chaotic double pendulum", size=size)
    th0 = float(e.start()[0][0])

    def go(tol, d=0.0, meth="erk"):
        return simulate(e, T, rtol=tol, atol=tol, method=meth, points=pts, x0={"j1.phi": th0 + d}, error_estimate="off")

    runs = {(tol, d): go(tol, d) for tol in TOLS for d in (0.0, DELTA)}
    other = go(TOLS[0], meth="scipy-dop853")
    t = runs[(TOLS[0], 0.0)].t
    A, B = runs[(TOLS[0], 0.0)].q, runs[(TOLS[0], DELTA)].q
    sep = np.abs(A - B).max(axis=1)
    num = np.abs(A - other.q).max(axis=1)
    loose = np.abs(A - runs[(TOLS[1], 0.0)].q).max(axis=1)
    drift = {k: r.stats["energy_drift_relative"] for k, r in runs.items()}
    win = (sep > 1e-8) & (sep < 1e-2)
    lyap = float(np.polyfit(t[win], np.log(sep[win]), 1)[0]) if win.sum() > 10 else float("nan")
    case.data.update(t=t, sep=sep, num=num, loose=loose, runs=runs, T=T, lyap=lyap)
    case.table.append(f"  start difference {DELTA:g} rad in j1.phi; T = {T:g} s; separation growth rate "
                      f"(fit where 1e-8 < sep < 1e-2) {lyap:.2f} /s")
    case.table.append(f"  {'t [s]':>6s} {'separation':>11s} {'erk vs DOP853':>14s} {'tol 1e-10 vs 1e-12':>19s}")
    for tk in np.linspace(0, T, 9):
        i = int(round(tk / T * (pts - 1)))
        case.table.append(f"  {t[i]:6.1f} {sep[i]:11.2e} {num[i]:14.2e} {loose[i]:19.2e}")
    for (tol, d), r in runs.items():
        case.table.append(f"  erk tol {tol:g}, start + {d:g}: energy drift (relative) {drift[(tol, d)]:.2e}, "
                          f"{r.stats['steps']} steps")
    case.check("nearby starts diverge: the separation grows by >= 10^6", all(r.success for r in runs.values())
               and sep[-1] >= 1e6 * DELTA, f"{DELTA:g} -> {sep[-1]:.2e} at t = {T:g}")
    case.check("every run keeps its energy to within 20 x its tolerance",
               all(drift[(tol, d)] <= 20 * tol for tol, d in runs),
               ", ".join(f"{drift[k] / k[0]:.1f} x tol" for k in runs))
    after = (t >= 1.0) & (sep <= 0.1)          # before the separation saturates at order one
    ratio = float((num[after] / sep[after]).max())
    case.check("the divergence is the dynamics: two independent methods at 1e-12 agree to < 1% of the separation",
               other.success and ratio < 1e-2,
               f"max (erk - DOP853) / separation for t >= 1 s while the separation is below 0.1: {ratio:.1e}")
    dl = drift[(TOLS[1], 0.0)]
    case.check("a conserved energy is no proof of accuracy: at 1e-10 the energy holds to ~1e-9, the trajectory "
               "ends >= 10^4 times further off", loose[-1] >= 1e4 * dl,
               f"energy {dl:.1e}, |q(1e-10) - q(1e-12)| at T = {loose[-1]:.1e}")
    return case


def chart(case: Case, out_dir) -> list:
    plt = pyplot()
    d = case.data
    fig, (a1, a2) = plt.subplots(1, 2, figsize=(11, 4.3))
    t = d["t"]
    a1.semilogy(t[1:], d["sep"][1:], color="tab:red", lw=1.3, label=f"starts {DELTA:g} rad apart (erk, 1e-12)")
    a1.semilogy(t[1:], np.maximum(d["loose"][1:], 1e-17), color="tab:orange", lw=1,
                label="same start, tolerance 1e-10 vs 1e-12")
    a1.semilogy(t[1:], np.maximum(d["num"][1:], 1e-17), color="tab:blue", lw=1,
                label="same start, erk vs DOP853 at 1e-12")
    if np.isfinite(d["lyap"]):
        a1.semilogy(t, DELTA * np.exp(d["lyap"] * t), "k:", lw=0.8, label=f"exp({d['lyap']:.2f} t)")
    a1.set_xlabel("t [s]")
    a1.set_ylabel("max |q_a - q_b| [rad]")
    a1.set_ylim(1e-16, 10)
    a1.legend(fontsize="x-small", loc="lower right")
    a1.grid(True, alpha=0.3)
    colors = {TOLS[0]: "tab:blue", TOLS[1]: "tab:orange"}
    for (tol, dd), r in d["runs"].items():
        E = r["energy"]
        scale = max(abs(E[0]), np.abs(r["kinetic_energy"]).max(), np.abs(r["potential_energy"]).max())
        a2.semilogy(r.t[1:], np.maximum(np.abs(E[1:] - E[0]) / scale, 1e-17), color=colors[tol],
                    lw=0.8, ls="-" if dd == 0 else "--", label=f"erk tol {tol:g}, start + {dd:g}")
        a2.axhline(tol, color=colors[tol], lw=0.6, ls=":")
    a2.set_xlabel("t [s]")
    a2.set_ylabel("|E - E(0)| / energy scale")
    a2.legend(fontsize="x-small")
    a2.grid(True, alpha=0.3)
    fig.suptitle("Double pendulum: the trajectories separate, the energy error stays at the tolerance (dotted)",
                 fontsize="medium")
    fig.tight_layout()
    return save(fig, out_dir, "stability_chaos")
