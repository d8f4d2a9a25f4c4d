"""Cart-pole swing-up: mechdsl's `ode` vs a hand-written CasADi cart-pole, side by side.

The same OCP (docs/control.md example 1: direct multiple shooting, RK4 with M steps per
interval, |F| <= 20 N, minimum effort, hanging -> upright in T = 3 s) is built and solved
with IPOPT (exact Hessian) on
  hand       the cart-pole written out by hand in SX, its parameters as numbers
             (tests/test_control.py checks that both give the same xdot at random states to 1e-12)
  mechdsl    m.casadi()["ode"] of models/cart_pole.mech (an SXFunction: the recursive route
             gives the accelerations explicitly), the parameters as the input p, given as
             numbers (called so in the OCP's MX graph it calls its specialization to them:
             mechdsl.eom.numeric_p)
  fixed      m.casadi(fixed_parameters=True)["ode"]: the parameters built in as numbers
             (what the hand-written model does), p empty
  compiled   m.casadi(compiled=True, derivatives=2)["ode"] (C code with its first and second derivatives)
  comp+fixed m.casadi(compiled=True, derivatives=2, fixed_parameters=True)["ode"]
and, as a last row per N, docs/control.md example 2:
  integrator multiple shooting on m.integrator(h, method="erk", rtol=1e-8, atol=1e-10,
             fixed_parameters=True): the simulator's own integrator as the OCP's dynamics
It prints, for each, the CPU time of the solve (time.process_time, best of --repeat, the
variants interleaved so that a change of machine load hits them alike; build excluded and
included), the IPOPT
iterations, the ratio to `hand`, and two gaps between the optimizer's states and the optimal
control replayed through m.simulate (zero-order hold): `replay` with the simulator at rtol
1e-10 (for `integrator`: the same method and tolerances as its OCP), `exact` at rtol 1e-12.
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
SHOOT = {"method": "erk", "rtol": 1e-8, "atol": 1e-10}     # the integrator row (docs/control.md example 2)


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


def rk4_step(ode, p, h):
    def step(x, u):
        for _ in range(M_RK):
            k1 = ode(0, x, u, p)
            k2 = ode(0, x + h / M_RK / 2 * k1, u, p)
            k3 = ode(0, x + h / M_RK / 2 * k2, u, p)
            k4 = ode(0, x + h / M_RK * k3, u, p)
            x = x + h / M_RK / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
        return x
    return step


def build(step, N):
    h = T / N
    opti = ca.Opti()
    X = opti.variable(4, N + 1)
    U = opti.variable(1, N)
    opti.subject_to(X[:, 0] == [0, math.pi, 0, 0])
    opti.subject_to(X[:, N] == [0, 0, 0, 0])
    for k in range(N):
        opti.subject_to(X[:, k + 1] == step(X[:, k], U[:, k]))
    opti.subject_to(opti.bounded(-F_MAX, U, F_MAX))
    opti.minimize(h * ca.sumsqr(U))
    opti.set_initial(X[1, :], np.linspace(math.pi, 0, N + 1))
    opti.solver("ipopt", {"print_time": False}, {"print_level": 0, "sb": "yes"})
    return opti, X, U


def solve_once(make_step, N):
    t0 = time.process_time()          # CPU time: the shared machine's load does not count
    opti, X, U = build(make_step(N), N)
    t1 = time.process_time()
    sol = opti.solve()
    t2 = time.process_time()
    return t2 - t1, t2 - t0, (sol.stats()["iter_count"], np.atleast_1d(sol.value(U)).ravel(), sol.value(X))


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
    odes = [("hand", hand, hp), ("mechdsl", m.casadi()["ode"], pv),
            ("fixed", m.casadi(fixed_parameters=True)["ode"], np.zeros(0)),
            ("compiled", m.casadi(compiled=True, derivatives=2)["ode"], pv),
            ("comp+fixed", m.casadi(compiled=True, derivatives=2, fixed_parameters=True)["ode"], np.zeros(0))]
    variants = [(n, (lambda f, p: lambda N: rk4_step(f, p, T / N))(f, p), None) for n, f, p in odes]
    variants.append(("integrator", lambda N: (lambda F: lambda x, u: F(0, x, u, []))(   # autonomous: t0 = 0 will do
        m.integrator(T / N, fixed_parameters=True, **SHOOT)), SHOOT))
    yield (f"cart-pole swing-up, T = {T} s, RK4 x {M_RK} per interval (integrator: {SHOOT['method']} at rtol "
           f"{SHOOT['rtol']:g}), |F| <= {F_MAX} N; ode classes: {', '.join(f'{n}={f.class_name()}' for n, f, _ in odes)}; "
           f"VM instructions: {', '.join(f'{n}={f.n_instructions()}' for n, f, _ in odes if f.is_a('SXFunction'))}"
           + "".join(f"; {n} called with p as numbers in the OCP's MX graph: its specialization (eom.numeric_p), "
                     f"{f.specialized(p).n_instructions()} instructions" for n, f, p in odes if hasattr(f, "specialized")))
    yield (f"{'N':>4} {'variant':>10} {'CPU s':>8} {'+build s':>9} {'iters':>6} {'x hand':>7} "
           f"{'replay gap':>11} {'exact gap':>10}")
    for N in Ns:
        best = {n: [math.inf, math.inf, None] for n, _, _ in variants}
        for _ in range(repeat):                       # interleaved: load changes hit every variant alike
            for name, make, _ in variants:
                t_solve, t_total, out = solve_once(make, N)
                b = best[name]
                b[0], b[1], b[2] = min(b[0], t_solve), min(b[1], t_total), out
        times = np.linspace(0, T, N + 1)
        for name, _, shoot in variants:
            t_solve, t_total, (iters, u, X) = best[name]
            F = {"F": mechdsl.table(times, np.r_[u, u[-1]])}
            replay = m.simulate(T, x0={"theta": math.pi}, inputs=F, points=N + 1,
                                **(shoot or {"rtol": 1e-10, "atol": 1e-12}))
            exact = m.simulate(T, x0={"theta": math.pi}, inputs=F, points=N + 1, rtol=1e-12, atol=1e-14)
            gap = float(np.abs(np.c_[replay.q, replay.qd].T - X).max())
            gap_exact = float(np.abs(np.c_[exact.q, exact.qd].T - X).max())
            yield (f"{N:>4} {name:>10} {t_solve:>8.3f} {t_total:>9.3f} {iters:>6} {t_solve / best['hand'][0]:>7.2f} "
                   f"{gap:>11.2e} {gap_exact:>10.2e}")


if __name__ == "__main__":
    main()
