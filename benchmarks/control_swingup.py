"""Cart-pole swing-up: mechdsl's `ode` vs a hand-written CasADi cart-pole, side by side.

The same OCP (docs/control.md example 1: direct multiple shooting, RK4 with M steps per
interval, |F| <= 20 N, minimum effort, hanging -> upright in T = 3 s) is built and solved
with IPOPT (exact Hessian) on
  hand       the cart-pole written out by hand in SX (tests/test_control.py checks that both
             give the same xdot at random states to 1e-12)
  mechdsl    m.casadi()["ode"] of models/cart_pole.mech (an SXFunction: the recursive route
             gives the accelerations explicitly), the parameters as the input p
  fixed      m.casadi(fixed_parameters=True)["ode"]: the parameters built in as numbers
             (what the hand-written model does), p empty
  compiled   m.casadi(compiled=True)["ode"] (C code, derivatives included)
  comp+fixed m.casadi(compiled=True, fixed_parameters=True)["ode"]
and prints, for each, the wall time of the solve (best of --repeat, build excluded and
included), the IPOPT iterations, the ratio to `hand`, and the gap between the optimizer's
states and the optimal control replayed through m.simulate (rtol 1e-10), for several N.
Run:  PYTHONPATH=src python benchmarks/control_swingup.py [--N 30,60,120] [--repeat 3]
"""
from __future__ import annotations

import argparse
import math
import os
import tempfile
import time
from pathlib import Path

import casadi as ca
import numpy as np

ROOT = Path(__file__).resolve().parents[1]
T, M_RK, F_MAX = 3.0, 2, 20.0


def hand_ode(Mc=1.0, m=0.1, l=1.0, g=9.81):
    t = ca.SX.sym("t")
    x = ca.SX.sym("x", 4)
    u = ca.SX.sym("u")
    p = ca.SX.sym("p", 0)
    th, xd, thd = x[1], x[2], x[3]
    c, s = ca.cos(th), ca.sin(th)
    A = ca.blockcat([[Mc + m, -m * l / 2 * c], [-m * l / 2 * c, m * l ** 2 / 3]])
    b = ca.vertcat(u - m * l / 2 * s * thd ** 2, m * g * l / 2 * s)
    return ca.Function("hand", [t, x, u, p], [ca.vertcat(xd, thd, ca.solve(A, b))]), np.zeros(0)


def build(ode, p, N):
    h = T / N
    opti = ca.Opti()
    X = opti.variable(4, N + 1)
    U = opti.variable(1, N)

    def step(x, u):
        for _ in range(M_RK):
            k1 = ode(0, x, u, p)
            k2 = ode(0, x + h / M_RK / 2 * k1, u, p)
            k3 = ode(0, x + h / M_RK / 2 * k2, u, p)
            k4 = ode(0, x + h / M_RK * k3, u, p)
            x = x + h / M_RK / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
        return x

    opti.subject_to(X[:, 0] == [0, math.pi, 0, 0])
    opti.subject_to(X[:, N] == [0, 0, 0, 0])
    for k in range(N):
        opti.subject_to(X[:, k + 1] == step(X[:, k], U[:, k]))
    opti.subject_to(opti.bounded(-F_MAX, U, F_MAX))
    opti.minimize(h * ca.sumsqr(U))
    opti.set_initial(X[1, :], np.linspace(math.pi, 0, N + 1))
    opti.solver("ipopt", {"print_time": False}, {"print_level": 0, "sb": "yes"})
    return opti, X, U


def solve(ode, p, N, repeat):
    best, best_total, out = math.inf, math.inf, None
    for _ in range(repeat):
        t0 = time.perf_counter()
        opti, X, U = build(ode, p, N)
        t1 = time.perf_counter()
        sol = opti.solve()
        t2 = time.perf_counter()
        best, best_total = min(best, t2 - t1), min(best_total, t2 - t0)
        out = (sol.stats()["iter_count"], np.atleast_1d(sol.value(U)).ravel(), sol.value(X))
    return best, best_total, out


def main(argv=None):
    ap = argparse.ArgumentParser()
    ap.add_argument("--N", default="30,60,120")
    ap.add_argument("--repeat", type=int, default=3)
    a = ap.parse_args(argv)
    for line in rows([int(v) for v in a.N.split(",")], a.repeat):
        print(line, flush=True)


def rows(Ns, repeat):
    """The table, line by line (also used by benchmarks/make_performance.py)."""
    import mechdsl

    os.environ.setdefault("MECHDSL_CACHE", os.path.join(tempfile.gettempdir(), "mechdsl-bench-cache"))
    m = mechdsl.load(str(ROOT / "models" / "cart_pole.mech"), model="CartPole")
    pv = m.parameter_vector()
    hand, hp = hand_ode()
    variants = [("hand", hand, hp), ("mechdsl", m.casadi()["ode"], pv),
                ("fixed", m.casadi(fixed_parameters=True)["ode"], np.zeros(0)),
                ("compiled", m.casadi(compiled=True)["ode"], pv),
                ("comp+fixed", m.casadi(compiled=True, fixed_parameters=True)["ode"], np.zeros(0))]
    yield (f"cart-pole swing-up, T = {T} s, RK4 x {M_RK} per interval, |F| <= {F_MAX} N; "
           f"ode classes: {', '.join(f'{n}={f.class_name()}' for n, f, _ in variants)}; "
           f"VM instructions: {', '.join(f'{n}={f.n_instructions()}' for n, f, _ in variants if f.is_a('SXFunction'))}")
    yield f"{'N':>4} {'variant':>10} {'solve s':>8} {'+build s':>9} {'iters':>6} {'x hand':>7} {'replay gap':>11}"
    for N in Ns:
        base = None
        for name, f, p in variants:
            t_solve, t_total, (iters, u, X) = solve(f, p, N, repeat)
            base = base or t_solve
            times = np.linspace(0, T, N + 1)
            r = m.simulate(T, x0={"theta": math.pi}, inputs={"F": mechdsl.table(times, np.r_[u, u[-1]])},
                           rtol=1e-10, atol=1e-12, points=N + 1)
            gap = float(np.abs(np.c_[r.q, r.qd].T - X).max())
            yield f"{N:>4} {name:>10} {t_solve:>8.3f} {t_total:>9.3f} {iters:>6} {t_solve / base:>7.2f} {gap:>11.2e}"


if __name__ == "__main__":
    main()
