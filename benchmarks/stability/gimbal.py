"""A spherical joint in Euler angles through gimbal lock, against quaternions.

benchmarks/stability/gimbal_lock.mech: a free box (no gravity) spinning about its long
axis with a small wobble; with z-y-x Cardan angles the spin drives theta through +-pi/2
(gimbal lock: the mass matrix of the angles is singular there), with a quaternion the
orientation has no singular value.  Both are checked against an independent solution:
Euler's rigid-body equations I w' = -w x I w with R' = R [w]x, integrated by scipy's DOP853
at 1e-13 (no mechdsl code involved), compared on the long axis e_y = R (0, 1, 0).
"""
from __future__ import annotations

import numpy as np

from .suite import Case, check_size, fmt_fail, load, pyplot, save

MODEL = "benchmarks/stability/gimbal_lock.mech"
TOL = 1e-8
DT_OK, DT_BIG = 0.01, 0.05
SIZE = (0.1, 0.4, 0.2)


def euler_reference(eps, w0, T, ts, m=1.0):
    """Long axis e_y(t) from Euler's equations (body angular velocity w, rotation R)."""
    from scipy.integrate import solve_ivp

    a, b, c = SIZE
    inertia = m / 12 * np.array([b * b + c * c, a * a + c * c, a * a + b * b])

    def f(t, y):
        w, R = y[:3], y[3:].reshape(3, 3)
        W = np.array([[0, -w[2], w[1]], [w[2], 0, -w[0]], [-w[1], w[0], 0]])
        return np.r_[-np.cross(w, inertia * w) / inertia, (R @ W).ravel()]

    s = solve_ivp(f, (0, T), np.r_[eps, w0, eps, np.eye(3).ravel()], method="DOP853", rtol=1e-13, atol=1e-13,
                  t_eval=ts)
    return s.y[3:].T.reshape(-1, 3, 3)[:, :, 1]


def run(size: str = "small") -> Case:
    from mechdsl.simulate import simulate

    check_size(size)
    T = 10.0 if size == "small" else 60.0
    pts = int(T * 20) + 1
    case = Case(name="gimbal", title="Gimbal lock: Euler angles vs quaternions", size=size)
    models = {k: load(MODEL, model=f"TumblingBox{k}") for k in ("Euler", "Quaternion")}
    eps, w0 = (float(models["Euler"].parameters[k]) for k in ("eps", "w0"))
    ts = np.linspace(0, T, pts)
    ey_ref = euler_reference(eps, w0, T, ts)
    runs = {}
    for k, m in models.items():
        e = m.eom
        runs[(k, "erk")] = simulate(e, T, rtol=TOL, atol=TOL, method="erk", points=pts, error_estimate="off")
        runs[(k, f"rk dt={DT_OK:g}")] = simulate(e, T, method="rk", dt=DT_OK, points=pts, error_estimate="off")
        runs[(k, f"rk dt={DT_BIG:g}")] = simulate(e, T, method="rk", dt=DT_BIG, points=pts, error_estimate="off")

    def err(r):
        n = len(r.t)
        ey = np.column_stack([r[f"ey[{i}]"] for i in (1, 2, 3)])
        return float(np.abs(ey - ey_ref[:n]).max()) if n else float("inf")

    errs = {k: err(r) for k, r in runs.items()}
    sing = runs[("Euler", "erk")].metadata.get("singularity", {}).get("hinge.gimbal", {})
    case.data.update(runs=runs, errs=errs, ts=ts, ey_ref=ey_ref, T=T)
    case.table.append(f"  {'parametrization':16s} {'method':12s} {'steps':>7s} {'max |e_y - ref|':>16s}  status")
    for (k, meth), r in runs.items():
        case.table.append(f"  {k:16s} {meth:12s} {r.stats.get('steps', 0):7d} {errs[(k, meth)]:16.2e}  {fmt_fail(r)}")
    case.table.append(f"  Euler run's closest approach to gimbal lock |cos theta| = {sing.get('closest', float('nan')):.3g} "
                      f"at t = {sing.get('time', float('nan')):.3g} (output grid)")
    eu, qu = runs[("Euler", "erk")], runs[("Quaternion", "erk")]
    case.check("the Euler-angle run passes near gimbal lock and the simulator warns",
               any("singular configuration" in w for w in eu.metadata.get("warnings", [])),
               f"closest |cos theta| on the grid {sing.get('closest', float('nan')):.3g}")
    case.check("adaptive erk: the Euler angles need >= 5x the steps of the quaternion at the same tolerance",
               eu.stats["steps"] >= 5 * qu.stats["steps"], f"{eu.stats['steps']} vs {qu.stats['steps']} steps")
    case.check("the quaternion run agrees with the independent solution to 100 x tolerance",
               qu.success and errs[("Quaternion", "erk")] <= 100 * TOL, f"error {errs[('Quaternion', 'erk')]:.2e}")
    case.check("quaternion: |q| - 1 and the energy stay at the tolerance",
               float(np.abs(qu["hinge.quaternion_norm"]).max()) <= 10 * TOL
               and qu.stats["energy_drift_relative"] <= 10 * TOL,
               f"max ||q| - 1| {float(np.abs(qu['hinge.quaternion_norm']).max()):.1e}, energy "
               f"{qu.stats['energy_drift_relative']:.1e}")
    eo, qo = errs[("Euler", f"rk dt={DT_OK:g}")], errs[("Quaternion", f"rk dt={DT_OK:g}")]
    case.check(f"fixed-step RK4, dt = {DT_OK:g}: the Euler angles lose >= 10^5 times more accuracy",
               eo >= 1e5 * qo, f"Euler {eo:.1e}, quaternion {qo:.1e}")
    eb, qb = runs[("Euler", f"rk dt={DT_BIG:g}")], runs[("Quaternion", f"rk dt={DT_BIG:g}")]
    case.check(f"fixed-step RK4, dt = {DT_BIG:g}: the Euler-angle run fails or is wrong (error > 0.1), "
               f"the quaternion run stays within 1e-5",
               (not eb.success or errs[("Euler", f"rk dt={DT_BIG:g}")] > 0.1) and qb.success
               and errs[("Quaternion", f"rk dt={DT_BIG:g}")] <= 1e-5,
               f"Euler: {fmt_fail(eb)}, error {errs[('Euler', f'rk dt={DT_BIG:g}')]:.1e}; quaternion: "
               f"{fmt_fail(qb)}, error {errs[('Quaternion', f'rk dt={DT_BIG:g}')]:.1e}")
    return case


def chart(case: Case, out_dir) -> list:
    plt = pyplot()
    d = case.data
    fig, (a1, a2) = plt.subplots(1, 2, figsize=(11, 4.3))
    colors = {"Euler": "tab:red", "Quaternion": "tab:blue"}
    styles = {"erk": "-", f"rk dt={DT_OK:g}": "--", f"rk dt={DT_BIG:g}": ":"}
    for (k, meth), r in d["runs"].items():
        n = len(r.t)
        ey = np.column_stack([r[f"ey[{i}]"] for i in (1, 2, 3)])
        e = np.maximum(np.abs(ey - d["ey_ref"][:n]).max(axis=1), 1e-17)
        a1.plot(r.t, e, styles[meth], color=colors[k], lw=1.1, label=f"{k}, {meth}" + ("" if r.success else " (failed)"))
    a1.set_yscale("log")
    a1.set_xlabel("t [s]")
    a1.set_ylabel("|e_y - e_y,ref| (independent solution)")
    a1.legend(fontsize="x-small")
    a1.grid(True, alpha=0.3)
    eu = d["runs"][("Euler", "erk")]
    a2.plot(eu.t, np.abs(eu["singularity(hinge.gimbal)"]), color="tab:red", lw=1, label="|cos theta| (Euler run)")
    a2.plot(eu.t, np.abs(eu["der(hinge.phi)"]), color="0.4", lw=0.8, label="|der(phi)| [rad/s]")
    a2.set_yscale("log")
    a2.set_xlabel("t [s]")
    a2.legend(fontsize="x-small")
    a2.grid(True, alpha=0.3)
    a2.set_title("near gimbal lock the angle rates spike", fontsize="medium")
    fig.suptitle("Tumbling box: z-y-x Cardan angles through gimbal lock vs a unit quaternion", fontsize="medium")
    fig.tight_layout()
    return save(fig, out_dir, "stability_gimbal")
