"""Optimal control and LQR on the cart-pole (issue 13): the examples of docs/control.md run
here, the model's ode is checked against an independent hand derivation, and compiled
Functions keep exact Hessians working."""
import math
import re
from pathlib import Path

import casadi as ca
import numpy as np
import pytest

import mechdsl
from mechdsl.diagnostics import UsageError

from conftest import CHECKOUT, MODELS  # noqa: E402
DOC = CHECKOUT / "docs" / "control.md"


def _examples():
    return re.findall(r"```python\n(.*?)```", DOC.read_text(), flags=re.S)


def _run(code, monkeypatch, **subs):
    for old, new in subs.items():
        assert old in code, old
        code = code.replace(old, new)
    monkeypatch.chdir(CHECKOUT)
    env: dict = {}
    exec(compile(code, str(DOC), "exec"), env)     # noqa: S102 - our own documentation
    return env


def hand_cart_pole(M=1.0, m=0.1, l=1.0, g=9.81):
    """Cart (x) and a uniform rod (length l, theta from the upward vertical, hinged at its end),
    force F on the cart; Lagrange's equations written out by hand."""
    x = ca.SX.sym("x", 4)
    F = ca.SX.sym("F")
    th, xd, thd = x[1], x[2], x[3]
    c, s = ca.cos(th), ca.sin(th)
    A = ca.blockcat([[M + m, -m * l / 2 * c], [-m * l / 2 * c, m * l ** 2 / 3]])
    b = ca.vertcat(F - m * l / 2 * s * thd ** 2, m * g * l / 2 * s)
    acc = ca.solve(A, b)
    return ca.Function("hand", [x, F], [ca.vertcat(xd, thd, acc)])


def test_cart_pole_ode_matches_hand_derivation_at_random_states():
    m = mechdsl.load(str(MODELS / "cart_pole.mech"), model="CartPole")
    ode = m.casadi()["ode"]
    hand = hand_cart_pole()
    rng = np.random.default_rng(13)
    for _ in range(20):
        x = rng.uniform(-3, 3, 4)
        F = rng.uniform(-20, 20)
        got = np.array(ode(0.0, x, [F], m.parameter_vector())).ravel()
        want = np.array(hand(x, F)).ravel()
        np.testing.assert_allclose(got, want, rtol=1e-12, atol=1e-12)


def test_fixed_parameters_give_the_same_functions_with_fewer_instructions():
    """casadi(fixed_parameters=...): the parameters built in as numbers; the same values as the
    general Functions at random states, a leaner expression, and p keeps what is not fixed."""
    m = mechdsl.load(str(MODELS / "cart_pole.mech"), model="CartPole")
    general, p = m.casadi(), m.parameter_vector()
    fixed = m.casadi(fixed_parameters=True)
    assert fixed["ode"].numel_in(3) == 0 and fixed.parameter_names == ()
    assert fixed["ode"].n_instructions() < general["ode"].n_instructions()       # 53 < 72
    some = m.casadi(fixed_parameters={"m": 0.2, "g": 9.81})
    assert some.parameter_names == ("M", "l")
    other = m.with_params(m=0.2)
    rng = np.random.default_rng(5)
    for _ in range(10):
        x, F = rng.uniform(-3, 3, 4), rng.uniform(-20, 20)
        want = np.array(general["ode"](0.0, x, F, p)).ravel()
        np.testing.assert_allclose(np.array(fixed["ode"](0.0, x, F, [])).ravel(), want, rtol=1e-13, atol=1e-13)
        np.testing.assert_allclose(np.array(fixed["energy"](0.0, x, F, [])[2]).ravel(),
                                   np.array(general["energy"](0.0, x, F, p)[2]).ravel(), rtol=1e-13)
        np.testing.assert_allclose(np.array(some["ode"](0.0, x, F, [1.0, 1.0])).ravel(),
                                   np.array(general["ode"](0.0, x, F, other.parameter_vector())).ravel(),
                                   rtol=1e-13, atol=1e-13)
    assert np.array(fixed["parameters"](m.parameter_values)).size == 0
    with pytest.raises(UsageError, match="'mm' is not a Real parameter.*did you mean 'm'"):
        m.casadi(fixed_parameters=["mm"])
    with pytest.raises(UsageError, match="'F' is not an input"):
        m.casadi(fixed_parameters=["F"])


def test_terms_that_cancel_are_dropped_only_when_safe():
    """codegen.drop_cancelled: an output entry that does not depend on an input (zero derivative
    at random states) loses the terms that cancel; piecewise expressions are left alone."""
    from mechdsl.eom.codegen import drop_cancelled

    t, x, u, p = ca.SX.sym("t"), ca.SX.sym("x", 2), ca.SX.sym("u"), ca.SX.sym("p", 0)
    rest = ca.sin(x[0]) * x[1] * ca.cos(x[0]) - x[1] * ca.cos(x[0]) * ca.sin(x[0])   # zero, not folded
    f = ca.Function("ode", [t, x, u, p], [ca.vertcat(x[1], ca.exp(x[0]) + rest + u)], ["t", "x", "u", "p"], ["xdot"])
    g = drop_cancelled(f)
    assert g.n_instructions() < f.n_instructions()
    for v in np.random.default_rng(1).uniform(-3, 3, (20, 4)):
        want = [v[2], math.exp(v[1]) + v[3]]
        np.testing.assert_allclose(np.array(g(v[0], v[1:3], v[3], [])).ravel(), want, rtol=1e-13)
    kink = ca.if_else(x[0] > 5, x[0] - 5, 0)          # zero at every probe state, not beyond x = 5
    h = ca.Function("ode", [t, x, u, p], [ca.vertcat(x[1], kink + rest + u)], ["t", "x", "u", "p"], ["xdot"])
    assert drop_cancelled(h) is h


def test_fixing_a_parameter_fixes_the_ones_computed_from_it():
    src = """
model Rod
  parameter Real m = 2;
  parameter Real l = 3;
  parameter Real I = m * l^2 / 3;
  coordinate Real phi(start = 0.1);
equation
  kinetic = 0.5*I*der(phi)^2;
  potential = m*9.81*l/2*(1 - cos(phi));
end Rod;
"""
    m = mechdsl.loads(src, model="Rod")
    fs = m.casadi(fixed_parameters={"m": 4.0})
    assert fs.parameter_names == ("l", "I")                 # I depends on l too: stays in p
    fs = m.casadi(fixed_parameters={"m": 4.0, "l": 1.0})
    assert fs.parameter_names == ()                         # I = 4/3 built in, not stale 6
    xd = np.array(fs["ode"](0.0, [0.5, 0.0], [], [])).ravel()
    assert xd[1] == pytest.approx(-4.0 * 9.81 * 0.5 * math.sin(0.5) / (4.0 / 3.0), rel=1e-13)


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
def test_swing_up_example_coarse(monkeypatch):
    """docs/control.md example 1 on a coarse grid: IPOPT converges, the pole ends upright and
    the replay through m.simulate matches the optimizer's states to its RK4 discretization."""
    env = _run(_examples()[0], monkeypatch, **{"T, N, M = 3.0, 60, 2": "T, N, M = 3.0, 30, 3"})
    assert env["sol"].stats()["success"]
    assert np.abs(env["u_opt"]).max() <= 20.0 + 1e-6
    r = env["r"]
    assert r.success
    assert abs(r.q[-1, 1]) < 5e-3 and abs(r.q[-1, 0]) < 5e-3     # upright, over the start
    assert env["gap"] < 2e-2                                     # RK4 with h/M = 33 ms, a coarse grid
    assert r["F"][0] == pytest.approx(env["u_opt"][0])          # the input is recorded


@pytest.mark.slow
def test_swing_up_example_full(monkeypatch):
    env = _run(_examples()[0], monkeypatch)
    r = env["r"]
    assert env["sol"].stats()["success"] and r.success
    assert env["gap"] < 2e-4                                     # 16x finer than the coarse grid's bound
    assert np.abs(r.q[-1]).max() < 2e-4 and np.abs(r.qd[-1]).max() < 2e-4


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
def test_shooting_on_the_simulators_integrator_replays_to_round_off(monkeypatch):
    """docs/control.md example 2 on a coarse grid: multiple shooting on m.integrator; the replay
    through m.simulate with the same method and tolerances reproduces the optimizer's states
    (before: only to the optimizer's RK4 error), and both are near the exact solution."""
    env = _run(_examples()[1], monkeypatch, **{"T, N, F_max = 3.0, 60, 20.0": "T, N, F_max = 3.0, 30, 20.0"})
    assert env["sol"].stats()["success"] and env["r"].success
    assert env["gap"] < 1e-9                       # same integrator: round-off (measured 1e-11)
    assert env["gap_exact"] < 1e-4                 # rtol 1e-8 amplified by the unstable pole (measured 8e-7)
    assert abs(env["r"].q[-1, 1]) < 1e-6


@pytest.mark.slow
def test_shooting_on_the_simulators_integrator_full(monkeypatch):
    env = _run(_examples()[1], monkeypatch)
    assert env["sol"].stats()["success"] and env["sol"].stats()["iter_count"] == 47
    assert env["gap"] < 1e-10 and env["gap_exact"] < 1e-6      # measured 6e-13 and 1e-8


def test_integrator_function_matches_a_simulated_interval():
    m = mechdsl.load(str(MODELS / "cart_pole.mech"), model="CartPole")
    Phi = m.integrator(0.1, method="cvodes-bdf", rtol=1e-10, atol=1e-12)
    assert Phi.name_in() == ["t0", "x0", "u", "p"] and Phi.name_out() == ["xf"]
    x0 = np.array([0.1, 0.4, -0.2, 0.3])
    xf = np.array(Phi(0.0, x0, 2.5, m.parameter_vector())).ravel()
    r = m.simulate(0.1, x0=x0, inputs={"F": 2.5}, rtol=1e-12, atol=1e-14, points=2)
    np.testing.assert_allclose(xf, np.r_[r.q[-1], r.qd[-1]], atol=1e-9)
    with pytest.raises(UsageError, match="dt must be a positive"):
        m.integrator(-0.1)
    with pytest.raises(UsageError, match="no CasADi integrator plug-in"):
        m.integrator(0.1, method="scipy-rk45")
    for steps in (0, 2.5):      # was CasADi's RuntimeError (an assertion in RungeKutta::init)
        with pytest.raises(UsageError, match="steps must be a whole number of at least 1"):
            m.integrator(0.1, method="rk", steps=steps)
    bead = mechdsl.load(str(MODELS / "pendulum_cartesian.mech"))
    with pytest.raises(UsageError, match="constraints or contacts"):
        bead.integrator(0.1)


def test_integrator_of_a_time_dependent_model_starts_at_t0():
    """A mass pushed by sin(3 time): one interval from t0 = 0.7 is the closed form from there
    (x'' = sin(3 t) / m), not the interval from 0."""
    m = mechdsl.loads("""
model Pushed
  parameter Real m(unit = "kg") = 2;
  parameter Real w(unit = "1/s") = 3;
  parameter Real A(unit = "N") = 1;
  coordinate Real x(start = 0, speed = 0, unit = "m");
equation
  kinetic = 0.5*m*der(x)^2;
  force(x) = A*sin(w*time);
end Pushed;
""", model="Pushed")
    Phi = m.integrator(0.3, method="cvodes-adams", rtol=1e-11, atol=1e-13)
    a, b, x0, v0 = 0.7, 1.0, 0.2, -0.1

    def exact(t):       # from (x0, v0) at a: v = v0 + (cos 3a - cos 3t) / (3 m), x by integrating once more
        return (x0 + (v0 + math.cos(3 * a) / 6) * (t - a) - (math.sin(3 * t) - math.sin(3 * a)) / 18,
                v0 + (math.cos(3 * a) - math.cos(3 * t)) / 6)

    xf = np.array(Phi(a, [x0, v0], [], m.parameter_vector())).ravel()
    np.testing.assert_allclose(xf, exact(b), atol=1e-9)
    at0 = np.array(Phi(0.0, [x0, v0], [], m.parameter_vector())).ravel()
    assert np.abs(at0 - xf).max() > 1e-3                 # the start time matters here


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
def test_lqr_example_stabilizes_upright(monkeypatch):
    env = _run(_examples()[2], monkeypatch)
    reg, r = env["reg"], env["r"]
    assert (reg.closed_loop_eigenvalues.real < 0).all()
    # slowest closed-loop rate 1.26/s: after 6 s the 0.2 rad tilt is down to a few mrad
    assert r.success and np.abs(r.q[-1]).max() < 1e-2 and np.abs(r.qd[-1]).max() < 1e-2
    assert abs(r.q[-1, 1]) < 0.01 * 0.2
    # the recorded force is the feedback law on the recorded states
    X = np.c_[r.q, r.qd]
    np.testing.assert_allclose(r["F"], -(X @ reg.K[0]), rtol=1e-9, atol=1e-9)


def test_lqr_gain_satisfies_the_riccati_equation():
    m = mechdsl.load(str(MODELS / "cart_pole.mech"), model="CartPole")
    lin = m.linearize(at={"x": 0, "theta": 0})
    Q, R = np.diag([1.0, 10.0, 1.0, 1.0]), np.array([[0.1]])
    reg = lin.lqr(Q, R)
    A, B, P = lin.A, lin.B, reg.P
    res = A.T @ P + P @ A - P @ B @ np.linalg.solve(R, B.T @ P) + Q
    assert np.abs(res).max() < 1e-8 * np.abs(P).max()
    # B of the upright cart-pole by hand: d(xdot)/dF from the hand model's mass matrix
    M_, m_, l_ = 1.0, 0.1, 1.0
    Mass = np.array([[M_ + m_, -m_ * l_ / 2], [-m_ * l_ / 2, m_ * l_ ** 2 / 3]])
    np.testing.assert_allclose(B[2:, 0], np.linalg.solve(Mass, [1.0, 0.0]), rtol=1e-12)
    np.testing.assert_allclose(B[:2, 0], 0.0, atol=1e-15)


@pytest.mark.slow          # compiles C (about 5 s)
def test_compiled_functions_support_exact_hessian(tmp_path, monkeypatch):
    """Model.casadi(compiled=True, derivatives=2): IPOPT with the exact Hessian of the Lagrangian
    works and takes the same iterations as the virtual machine (before: 'Derivatives cannot be
    calculated')."""
    from mechdsl.eom.codegen import find_compiler

    if find_compiler() is None:
        pytest.skip("no C compiler")
    monkeypatch.setenv("MECHDSL_CACHE", str(tmp_path))
    m = mechdsl.load(str(MODELS / "cart_pole.mech"), model="CartPole")
    p = m.parameter_vector()

    def solve(ode):
        opti = ca.Opti()
        x = opti.variable(4)
        u = opti.variable()
        xd = ode(0, x, u, p)
        opti.minimize(ca.sumsqr(xd[2:]) + ca.sumsqr(x - [0.1, 0.5, 0.2, -0.3]) + 0.01 * u ** 2)
        opti.solver("ipopt", {"print_time": False}, {"print_level": 0, "sb": "yes",
                                                     "hessian_approximation": "exact"})
        sol = opti.solve()
        return sol.value(x), sol.stats()["iter_count"]

    fs = m.casadi(compiled=True, derivatives=2)     # derivatives only when asked (issue 22)
    ode_c = fs["ode"]                      # compiles on first use
    assert fs.compiled and ode_c.class_name() == "External", fs.notes
    x_c, it_c = solve(ode_c)
    x_v, it_v = solve(m.casadi()["ode"])
    assert it_c == it_v
    np.testing.assert_allclose(x_c, x_v, rtol=1e-8, atol=1e-10)
    assert math.isfinite(float(np.sum(x_c)))
