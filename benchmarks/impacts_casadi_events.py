"""Bouncing ball: CasADi 3.8's experimental event support against mechdsl.impacts.

A ball dropped from h = 1 m onto a floor, e = 0.8, integrated over 3.5 s (9 impacts)
with output grids of 351 points (at most one impact per output interval) and of 4 points
(several impacts per interval).  Error: the largest deviation of the height at the output
points from the closed form; time: wall clock of the integration call (functions built
beforehand), best of 3.  Run:

    PYTHONPATH=src python benchmarks/impacts_casadi_events.py

Measured on the development machine (2 shared cores), see docs/internals/impacts.md.
"""
from __future__ import annotations

import os
import sys
import time

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(__file__), "..", "tests"))

H0, E, G, T_END = 1.0, 0.8, 9.81, 3.5
RTOL, ATOL = 1e-10, 1e-12


def closed_form(ts):
    from imp_models import ball_height

    return ball_height(ts, H0, E, G)


TOLERANCE_OPTS = {s: {"abstol": ATOL, "reltol": RTOL} for s in ("cvodes", "erk", "rosenbrock")}


def casadi_run(solver, grid):
    import casadi as ca

    x = ca.SX.sym("x", 2)
    dae = {"x": x, "ode": ca.vertcat(x[1], -G), "zero": x[0]}
    idx, t = ca.SX.sym("index"), ca.SX.sym("t")
    tr = ca.Function("tr", {"index": idx, "t": t, "x": x, "post_x": ca.vertcat(x[0], -E * x[1])},
                     ca.event_in(), ca.event_out())
    opts = {"transition": tr, "max_events": 10000}
    if solver in TOLERANCE_OPTS:
        opts.update(TOLERANCE_OPTS[solver])
    from mechdsl.integrators import make_integrator    # the one place integrators are built

    F = make_integrator("F", solver, dae, 0, list(grid[1:]), opts)

    def call():
        return np.array(F(x0=[H0, 0.0])["xf"])[0]

    return call


def impacts_run(grid):
    import casadi as ca

    from mechdsl.model import ir
    from mechdsl.eom import from_lagrangian
    from mechdsl.impacts import simulate_with_contacts

    q, qd, t, p = ca.SX.sym("q", 1), ca.SX.sym("qd", 1), ca.SX.sym("t"), ca.SX.sym("p", 0)
    eom = from_lagrangian("ball", ["y"], [], [], q, qd, t, p, T=0.5 * qd[0] ** 2, V=G * q[0], q0=[H0], qd0=[0.0],
                          point_position=lambda n: ca.vertcat(0, q[0], 0))
    floor = ir.Contact("floor", "gap", (("gap", ir.Coord("y")), ("e", ir.Const(E))))

    def call():
        r = simulate_with_contacts(eom, [floor], T_END, points=len(grid), rtol=RTOL, atol=ATOL)
        return r.q[1:, 0]

    return call


def measure(make, grid):
    try:
        call = make(grid)
        best, y = np.inf, None
        for _ in range(3):
            t0 = time.perf_counter()
            y = call()
            best = min(best, time.perf_counter() - t0)
        err = float(np.max(np.abs(y - closed_form(grid[1:]))))
        return f"{err:.2e}", f"{best * 1e3:.1f}"
    except Exception as ex:  # noqa: BLE001 -- a failure is a result here
        import re

        msg = str(ex).strip().splitlines()[-1]
        m = re.search(r'returned "(\w+)"', msg)
        return "failed: " + (m.group(1) if m else msg[:50]), "-"


def main():
    import casadi as ca

    rows = []
    for npts in (351, 4):
        grid = np.linspace(0, T_END, npts)
        for solver in ("cvodes", "erk", "rk", "rosenbrock"):
            rows.append((f"casadi {solver}", npts, *measure(lambda g, s=solver: casadi_run(s, g), grid)))
        rows.append(("mechdsl.impacts (dop853)", npts, *measure(impacts_run, grid)))
    print(f"Bouncing ball, h = {H0} m, e = {E}, {T_END} s ({n_impacts()} impacts), rtol = {RTOL}, atol = {ATOL}; "
          f"CasADi {ca.__version__}")
    print(f"{'integrator':<26} {'points':>6}  {'max height error':<22} {'ms':>8}")
    for name, npts, err, ms in rows:
        print(f"{name:<26} {npts:>6}  {err:<22} {ms:>8}")


def n_impacts() -> int:
    from imp_models import ball_closed_form

    return int(np.sum(ball_closed_form(H0, E, G, 100)[0] < T_END))


def tolerance_table():
    """Impact-time error against the tolerance, on a flow that is not polynomial: a pendulum
    (L = 1 m) released from -1 rad against a wall at 0.3 rad, e = 0.7, 10 s, 2 output points;
    exact impact times from elliptic integrals.  Events are located to the integrator's accuracy."""
    from imp_models import pendulum, pendulum_wall_impacts, wall
    from mechdsl.impacts import simulate_with_contacts

    eom = pendulum(1.0, G, 1.0, -1.0)
    contact = wall(np.sin(0.3), 0.7)
    exact, _ = pendulum_wall_impacts(7, 1.0, G, -1.0, 0.3, 0.7)
    print()
    print("Pendulum against a wall: 7 impacts in 10 s, 2 output points (mechdsl.impacts)")
    print(f"{'method':<8} {'rtol':>8} {'atol':>8} {'max |t - t_exact|':>18} {'steps':>6} {'rhs':>6} {'ms':>8}")
    for method in ("dop853", "radau"):
        for rtol in (1e-6, 1e-8, 1e-10, 1e-12):
            best = np.inf
            for _ in range(2):
                t0 = time.perf_counter()
                r = simulate_with_contacts(eom, [contact], 10.0, points=2, rtol=rtol, atol=rtol * 1e-2,
                                           method=method)
                best = min(best, time.perf_counter() - t0)
            got = np.array([e["time"] for e in r.events if e["kind"] == "impact"])
            err = float(np.max(np.abs(got - exact))) if got.size == exact.size else float("nan")
            print(f"{method:<8} {rtol:>8.0e} {rtol * 1e-2:>8.0e} {err:>18.2e} {r.stats['steps']:>6} "
                  f"{r.stats['rhs_evals']:>6} {best * 1e3:>8.1f}")


if __name__ == "__main__":
    main()
    tolerance_table()
