"""Time-varying inputs on every back end (issue 13): the DAE, contact and fixed-step back ends
get the equations with u replaced by the signal U(t, x) (simulation/drive.py ``close_eom``),
each checked against a closed form or an independent minimal-coordinate integration; bad
input gives the same clear errors on every back end."""
import math

import casadi as ca
import numpy as np
import pytest
from scipy.integrate import solve_ivp
from scipy.optimize import brentq

import mechdsl
from conftest import simulate_with_csv_input
from mechdsl.diagnostics import UsageError

ROD = """
model ForcedRod "a point mass on a rod of length L (a constraint), pushed sideways by F"
  parameter Real m(unit = "kg") = 1;
  parameter Real L(unit = "m") = 1;
  parameter Real g(unit = "m/s2") = 9.81;
  input Real F(unit = "N", min = -5, max = 5) = 0 "horizontal force on the bob";
  coordinate Real x(start = 1, speed = 0, unit = "m");
  coordinate Real y(start = 0, speed = 0, unit = "m");
equation
  kinetic = 0.5*m*(der(x)^2 + der(y)^2);
  potential = m*g*y;
  force(x) = F;
  x^2 + y^2 = L^2 "rod";
end ForcedRod;
"""

BALL = """
model ThrustBall "a ball on a floor with an upward thrust F"
  parameter Real m(unit = "kg") = 2;
  parameter Real h(unit = "m") = 1;
  parameter Real e = 0.5;
  parameter Real g(unit = "m/s2") = 9.81;
  input Real F(unit = "N", min = -5, max = 5) = 0 "upward thrust";
  coordinate Real y(start = h, speed = 0, unit = "m") "height";
  Contact floor(gap = y, e = e);
equation
  kinetic = 1/2*m*der(y)^2;
  potential = m*g*y;
  force(y) = F;
end ThrustBall;
"""

SLIDER = """
model Slider
  parameter Real m(unit = "kg") = 2;
  input Real F(unit = "N", min = -5, max = 5) "push";
  coordinate Real x(start = 0, speed = 0, unit = "m");
equation
  kinetic = 0.5*m*der(x)^2;
  force(x) = F;
end Slider;
"""


@pytest.fixture(scope="module")
def rod():
    return mechdsl.loads(ROD, model="ForcedRod")


@pytest.fixture(scope="module")
def ball():
    return mechdsl.loads(BALL, model="ThrustBall")


@pytest.fixture(scope="module")
def slider():
    return mechdsl.loads(SLIDER, model="Slider")


def _rod_reference(force, t):
    """The same pendulum in its angle phi (x = L sin phi, y = -L cos phi), by scipy:
    m L^2 phi'' = -m g L sin phi + F(t) L cos phi (m = L = 1)."""
    sol = solve_ivp(lambda s, y: [y[1], -9.81 * math.sin(y[0]) + force(s) * math.cos(y[0])],
                    (0.0, float(t[-1])), [math.pi / 2, 0.0], t_eval=t, rtol=1e-12, atol=1e-13)
    return np.sin(sol.y[0]), -np.cos(sol.y[0])


def test_dae_with_a_time_varying_force_matches_the_minimal_coordinate_ode(rod):
    force = lambda t: 2.0 * math.sin(3.0 * t)                     # noqa: E731
    r = rod.simulate(2.0, inputs={"F": force}, rtol=1e-10, atol=1e-12, points=21)
    assert r.metadata["run"]["problem"] == "dae" and r.success, r.failure
    x, y = _rod_reference(force, r.t)
    np.testing.assert_allclose(r.q[:, 0], x, atol=1e-8)
    np.testing.assert_allclose(r.q[:, 1], y, atol=1e-8)
    np.testing.assert_allclose(r["F"], [force(t) for t in r.t], rtol=1e-12, atol=1e-12)   # recorded


def test_dae_with_a_casadi_function_and_a_linear_table(rod):
    t = ca.MX.sym("t")
    f = ca.Function("f", [t], [2.0 * ca.sin(3.0 * t)])
    r = rod.simulate(1.0, inputs={"F": f}, rtol=1e-10, atol=1e-12, points=11)
    x, _ = _rod_reference(lambda s: 2.0 * math.sin(3.0 * s), r.t)
    np.testing.assert_allclose(r.q[:, 0], x, atol=1e-8)
    # a linear table: the reference integrates the same interpolant
    times, vals = np.linspace(0, 1, 6), np.array([0.0, 1.0, -1.0, 2.0, 0.5, 0.0])
    r2 = rod.simulate(1.0, inputs={"F": mechdsl.table(times, vals, hold="linear")}, rtol=1e-10, atol=1e-12,
                      points=11)
    x2, _ = _rod_reference(lambda s: float(np.interp(s, times, vals)), r2.t)
    np.testing.assert_allclose(r2.q[:, 0], x2, atol=1e-7)


def test_contact_ball_with_a_growing_thrust_closed_form_through_an_impact(ball):
    a, m, g, e = 3.0, 2.0, 9.81, 0.5                      # F = a t: y'' = -g + a t / m
    r = ball.simulate(0.9, inputs={"F": lambda t: a * t}, rtol=1e-10, atol=1e-12, points=91)
    assert r.metadata["run"]["problem"] == "hybrid" and r.success, r.failure

    def y_free(t):
        return 1.0 - g * t ** 2 / 2 + a * t ** 3 / (6 * m)

    tc = brentq(y_free, 0.1, 0.9)
    impacts = [ev for ev in r.events if ev["kind"] == "impact"]
    assert impacts[0]["time"] == pytest.approx(tc, abs=1e-9)
    before = r.t < tc
    np.testing.assert_allclose(r.q[before, 0], y_free(r.t[before]), atol=1e-10)
    v_minus = -g * tc + a * tc ** 2 / (2 * m)
    vp = -e * v_minus                                      # Newton's impact law
    after = r.t > tc
    s = r.t[after]
    y_after = vp * (s - tc) - g * (s - tc) ** 2 / 2 + a / (2 * m) * ((s ** 3 - tc ** 3) / 3 - tc ** 2 * (s - tc))
    np.testing.assert_allclose(r.q[after, 0], y_after, atol=1e-9)


@pytest.mark.parametrize("method, tol", [("rk4", 1e-9), ("gauss-legendre", 1e-9), ("stormer-verlet", 1e-4),
                                         ("implicit-midpoint", 1e-4)])
def test_fixed_step_with_a_time_varying_force_closed_form(slider, method, tol):
    A, w, m = 3.0, 2.0, 2.0                                # x'' = A sin(w t) / m from rest
    r = slider.simulate(2.0, method=method, dt=0.01, inputs={"F": lambda t: A * math.sin(w * t)}, points=21)
    assert r.metadata["run"]["problem"] == "canonical" and r.success, r.failure
    exact = A / m * (r.t / w - np.sin(w * r.t) / w ** 2)
    np.testing.assert_allclose(r.q[:, 0], exact, atol=tol)


def test_fixed_step_state_feedback_is_a_harmonic_oscillator(slider):
    t, x = ca.MX.sym("t"), ca.MX.sym("x", 2)
    k = ca.Function("k", [t, x], [-8.0 * x[0]])           # F = -8 x: omega = sqrt(8 / 2) = 2
    r = slider.simulate(3.0, method="gauss-legendre", dt=0.01, x0={"x": 0.2}, inputs={"F": k}, points=31)
    np.testing.assert_allclose(r.q[:, 0], 0.2 * np.cos(2.0 * r.t), atol=1e-8)


# ----------------------------------------------------------------------- bad input, every back end

BACKENDS = [("ode", "slider", {}), ("fixed-step", "slider", {"method": "rk4", "dt": 0.01}),
            ("dae", "rod", {}), ("hybrid", "ball", {})]


def _model(which, slider, rod, ball):
    return {"slider": slider, "rod": rod, "ball": ball}[which]


@pytest.mark.parametrize("kind, which, kw", BACKENDS)
@pytest.mark.parametrize("inputs, match", [
    ({"Fx": 1.0}, "'Fx' is not an input of .*did you mean 'F'"),
    ({"F": mechdsl.table([0.0, 0.5], [0.0, 1.0])}, "covers t = 0 .. 0.5 s, not the run's 0 .. 1 s"),
    ({"F": lambda t: [1.0, 2.0]}, "one number per call"),
    ({"F": 6.0}, "outside its declared bounds"),
    ({"F": [[0.0, 0.0], [1.0, -7.0]]}, "outside its declared bounds"),
])
def test_bad_inputs_are_the_same_usage_errors_on_every_back_end(slider, rod, ball, kind, which, kw, inputs, match):
    m = _model(which, slider, rod, ball)
    assert m.problem(t_end=1.0, **kw).kind == {"fixed-step": "canonical"}.get(kind, kind)
    with pytest.raises(UsageError, match=match):
        m.simulate(1.0, inputs=inputs, points=3, **kw)


@pytest.mark.parametrize("kind, which, kw", BACKENDS)
def test_a_signal_outside_its_bounds_during_the_run_warns_on_every_back_end(slider, rod, ball, kind, which, kw):
    r = _model(which, slider, rod, ball).simulate(0.2, inputs={"F": lambda t: 40.0 * t}, points=5, **kw)
    assert r.success, r.failure
    assert any("input 'F' went above its maximum 5" in w for w in r.metadata["warnings"])


SIGNAL_FAILURES = [(lambda t: 1.0 if t < 0.6 else [1.0, 2.0], "returned 2 values"),
                   (lambda t: 1.0 if t < 0.6 else 1 / 0, "ZeroDivisionError")]


# every back end with both failures, less the constrained one's wrong-shape case (the same
# contract as its ZeroDivisionError case, a second of CPU): that one in the slow set
@pytest.mark.slow_cases('dae-ZeroDivisionError')  # CPU budget: the cheaper tests of this file stay in the default run
@pytest.mark.parametrize("kind, which, kw, signal, what", [
    pytest.param(kind, which, kw, signal, what, id=f"{kind}-{what}",
                 marks=[pytest.mark.slow] if (kind, what) == ("dae", "returned 2 values") else [])
    for kind, which, kw in BACKENDS for signal, what in SIGNAL_FAILURES])
def test_a_signal_failing_during_the_run_stops_it_there_on_every_back_end(slider, rod, ball, kind, which, kw,
                                                                          signal, what, capfd):
    r = _model(which, slider, rod, ball).simulate(1.0, inputs={"F": signal}, points=11, **kw)
    assert not r.success
    assert r.failure.cause == "input signal failed" and what in r.failure.detail and "input 'F'" in r.failure.detail
    assert 0.5 <= r.failure.time <= 0.7 and r.t[-1] <= 0.6 + 1e-12      # results kept up to the failure
    assert "Traceback" not in capfd.readouterr().err                     # no Python traceback printed


# ----------------------------------------------------------------------- zero-order hold, ODE back end

@pytest.mark.parametrize("method", ["auto", "cvodes-adams", "scipy-dop853"])
def test_zero_order_hold_at_a_tight_tolerance_is_exact_piece_by_piece(slider, method):
    """The integrator restarts at the table's samples: at rtol 1e-12 a run through 20 jumps of
    the force matches the piecewise closed form (before: no restarts; CVODES failed at a jump,
    CV_ERR_FAILURE, and on the cart-pole erk too, 'step size too small')."""
    rng = np.random.default_rng(7)
    times = np.linspace(0.0, 2.0, 21)
    vals = rng.uniform(-4, 4, 21)
    r = slider.simulate(2.0, inputs={"F": mechdsl.table(times, vals)}, method=method, rtol=1e-12, atol=1e-14,
                        points=41)
    assert r.success, r.failure
    x, v, exact = 0.0, 0.0, {0.0: 0.0}
    for k in range(20):                                  # x'' = F_k / 2 on [t_k, t_k+1)
        h, a = times[k + 1] - times[k], vals[k] / 2.0
        for s in r.t[(r.t > times[k] + 1e-12) & (r.t <= times[k + 1] + 1e-12)]:
            exact[float(s)] = x + v * (s - times[k]) + a * (s - times[k]) ** 2 / 2
        x, v = x + v * h + a * h ** 2 / 2, v + a * h
    np.testing.assert_allclose(r.q[:, 0], [exact[float(s)] for s in r.t], atol=1e-10)
    np.testing.assert_allclose(r["F"][:-1:2], vals[:-1], rtol=1e-15)      # recorded: value k from t_k on


def test_cli_drives_a_constrained_model_from_a_csv(tmp_path, capsys):
    """mech simulate --input F=file.csv on a DAE model (before: 'ODE problems only', exit 2)."""
    from mechdsl.cli import main

    rc, head, rows = simulate_with_csv_input(tmp_path, ROD, "time,F\n0,0\n0.5,2\n1,-1\n", "--t-end", "1",
                                             "--points", "5", "--input", "F={csv}:linear", "--rtol", "1e-10",
                                             "--atol", "1e-12")
    assert rc == 0, capsys.readouterr().err
    col = [row[head.index("F")] for row in rows]
    assert col == pytest.approx([0.0, 1.0, 2.0, 0.5, -1.0])          # linear between the samples
    x = np.array([row[head.index("x")] for row in rows])
    ref, _ = _rod_reference(lambda s: float(np.interp(s, [0, 0.5, 1], [0, 2, -1])), np.linspace(0, 1, 5))
    np.testing.assert_allclose(x, ref, atol=1e-7)
    capsys.readouterr()
    src, csv_in = tmp_path / "model.mech", tmp_path / "f.csv"
    assert main(["simulate", str(src), "--t-end", "2", "--input", f"F={csv_in}", "--no-progress"]) == 2
    assert "covers t = 0 .. 1 s, not the run's 0 .. 2 s" in capsys.readouterr().err


@pytest.mark.parametrize("signal", [1.0, lambda t: math.sin(t)])
def test_error_estimate_of_a_driven_constrained_run(rod, signal):
    """estimate_error reruns the problem tighter; its equations already hold the inputs (before:
    'F' is not an input of ForcedRod, a usage error, for constant inputs too)."""
    r = rod.simulate(1.0, inputs={"F": signal}, estimate_error=True, points=5)
    est = r.metadata["error_estimate"]
    assert est["reference_failed"] is None and 0 < est["max_abs_difference"]["x"] < 1e-5


def test_compiled_dae_with_a_python_signal_runs_in_the_virtual_machine_and_says_so(rod, capfd):
    """C cannot call a Python signal: the run uses the virtual machine with a note, and CasADi's
    'cannot be code generated' warning is never printed (generating C for the equations with
    the signal's call node printed it, then the compilation failed)."""
    r = rod.simulate(0.5, inputs={"F": lambda t: math.sin(t)}, compiled=True, points=3)
    assert r.success and r.metadata["run"]["compiled"] is False
    assert any("Python functions, which compiled code cannot call" in n for n in r.metadata["notes"])
    err = capfd.readouterr()
    assert "cannot be code generated" not in err.err + err.out


def test_a_signal_failing_where_the_fixed_step_back_end_probes_is_named(slider):
    """The fixed-step back end probes the equations at sample times within the run before it
    starts; a signal failing at all of them is the error reported (not E902, 'could not be
    evaluated at any probe state', naming no input)."""
    with pytest.raises(UsageError, match="input 'F' at t = .*ZeroDivisionError.*fixed-step back end"):
        slider.simulate(1.0, method="rk4", dt=0.01, inputs={"F": lambda t: 1.0 if t < 0.2 else 1 / 0}, points=3)


@pytest.mark.parametrize("method", ["rk4", "stormer-verlet", "implicit-midpoint", "gauss-legendre"])
def test_fixed_step_holds_a_zero_order_hold_over_each_step(slider, method):
    """A zero-order-hold table is held over each step (read at its midpoint), and the steps land
    on the samples: every method is exact for x'' = F/m with F constant over a step (closed
    form v(1) = sum F_k * 0.1 / m, x(1) likewise), and no warning (before: a stage at a step's
    end saw the next sample, an error of first order in dt, and a warning said so)."""
    m_ = 2.0
    times = np.linspace(0.0, 1.0, 11)
    F = np.where(np.arange(11) % 2 == 0, 1.0, -1.0)
    tab = mechdsl.table(times, F, hold="zoh")
    v_exact = F[:10].sum() * 0.1 / m_
    x_exact = sum(F[k] / m_ * (0.1 * 0.1 / 2 + 0.1 * (0.9 - 0.1 * k)) for k in range(10))
    r = slider.simulate(1.0, method=method, dt=0.01, inputs={"F": tab}, points=11, estimate_error=True)
    assert r.success, r.failure
    assert r.qd[-1, 0] == pytest.approx(v_exact, abs=1e-12)
    # the error estimate's run (dt/4) holds the values over its steps too (it read them at t before)
    assert max(r.metadata["error_estimate"]["max_abs_difference"].values()) < 1e-12
    assert r.q[-1, 0] == pytest.approx(x_exact, abs=1e-12)
    np.testing.assert_allclose(r["F"], F, rtol=1e-15)          # recorded: value k from t_k on
    assert not any("zero-order hold" in w for w in r.metadata["warnings"])


def test_fixed_step_with_samples_inside_steps_says_its_order_is_lost(slider):
    """dt = 0.03 does not divide the samples' spacing 0.1: steps cross samples, read the value at
    their midpoint, and the run says so; the adaptive method restarts at every jump."""
    m_ = 2.0
    times = np.linspace(0.0, 1.0, 11)
    F = np.random.default_rng(3).uniform(-4, 4, 11)
    tab = mechdsl.table(times, F, hold="zoh")
    v_exact = F[:10].sum() * 0.1 / m_
    r = slider.simulate(1.0, method="rk4", dt=0.03, inputs={"F": tab}, points=11)
    assert abs(r.qd[-1, 0] - v_exact) > 1e-4
    assert any("zero-order hold of F" in w and "inside a step" in w for w in r.metadata["warnings"])
    adaptive = slider.simulate(1.0, inputs={"F": tab}, points=11, rtol=1e-10, atol=1e-12)
    assert adaptive.qd[-1, 0] == pytest.approx(v_exact, abs=1e-9)
    assert not any("zero-order hold" in w for w in adaptive.metadata["warnings"])
    flat = slider.simulate(1.0, method="rk4", dt=0.03, inputs={"F": mechdsl.table([0.0, 1.0], [1.0, 1.0])}, points=11)
    assert not any("zero-order hold" in w for w in flat.metadata["warnings"])


DUFFING = """
model Duffing
  parameter Real m(unit = "kg") = 2;
  parameter Real k(unit = "N/m") = 3;
  parameter Real c(unit = "N.s/m") = 0.4;
  input Real F(unit = "N") "push";
  coordinate Real x(start = 0.3, speed = -0.2, unit = "m");
equation
  kinetic = 0.5*m*der(x)^2;
  potential = 0.25*k*x^4;
  force(x) = F - c*der(x);
end Duffing;
"""


def test_rk4_replays_an_rk4_discretized_control_to_round_off():
    """The docs/control.md replay: an optimizer's RK4 recursion (M steps of h/M per interval,
    the control held over each interval) written here on the state (x, v), against the fixed-step
    rk4 run with dt = h/M driven by the same zero-order-hold table.  The mass is constant, so
    RK4 in the canonical (x, p = m v) is the same map and the gap is round-off (before: the stage
    at a step's end read the next interval's control, a gap of order dt)."""
    model = mechdsl.loads(DUFFING, model="Duffing")
    m_, k_, c_ = 2.0, 3.0, 0.4
    T, N, M = 2.0, 20, 3
    h = T / N
    u = np.random.default_rng(11).uniform(-5, 5, N)

    def f(s, F):
        x, v = s
        return np.array([v, (F - c_ * v - k_ * x ** 3) / m_])

    s, ref = np.array([0.3, -0.2]), [np.array([0.3, -0.2])]
    for j in range(N):
        for _ in range(M):
            d = h / M
            k1 = f(s, u[j])
            k2 = f(s + d / 2 * k1, u[j])
            k3 = f(s + d / 2 * k2, u[j])
            k4 = f(s + d * k3, u[j])
            s = s + d / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
        ref.append(s)
    ref = np.array(ref)
    tab = mechdsl.table(np.linspace(0, T, N + 1), np.r_[u, u[-1]], hold="zoh")
    r = model.simulate(T, method="rk4", dt=h / M, inputs={"F": tab}, points=N + 1)
    assert r.success, r.failure
    np.testing.assert_allclose(r.t, np.linspace(0, T, N + 1), atol=1e-12)
    np.testing.assert_allclose(np.c_[r.q, r.qd], ref, atol=1e-12)
    assert not any("zero-order hold" in w for w in r.metadata["warnings"])
    # the ODE back end (restarts at every sample) agrees to the RK4 error only: the check is not vacuous
    ode = model.simulate(T, inputs={"F": tab}, points=N + 1, rtol=1e-11, atol=1e-13)
    assert 1e-9 < np.abs(np.c_[ode.q, ode.qd] - ref).max() < 1e-4
