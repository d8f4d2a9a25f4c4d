"""Bouncing ball: CasADi 3.8's experimental event support against mechdsl.impacts.

A ball dropped from h = 1 m onto a floor, e = 0.8, integrated over 3.5 s (17 impacts)
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
    F = ca.integrator("F", solver, dae, 0, list(grid[1:]), opts)

    def call():
        return np.array(F(x0=[H0, 0.0])["xf"])[0]

    return call


def impacts_run(grid):
    import casadi as ca

    from mechdsl import ir
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
    print(f"Bouncing ball, h = {H0} m, e = {E}, {T_END} s (17 impacts), rtol = {RTOL}, atol = {ATOL}; "
          f"CasADi {ca.__version__}")
    print(f"{'integrator':<26} {'points':>6}  {'max height error':<62} {'ms':>8}")
    for name, npts, err, ms in rows:
        print(f"{name:<26} {npts:>6}  {err:<62} {ms:>8}")


if __name__ == "__main__":
    main()
