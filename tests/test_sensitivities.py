"""Model.sensitivities (issue 28): forward and adjoint derivatives against central finite
differences of independent runs (Model.simulate at other values) to 1e-6 relative, against
closed forms (the linear pendulum's motion, the small-angle period's dT/dL = pi/sqrt(g L)),
on ODE, constrained and input-driven runs, in declared units; contacts and bad names refused."""
from __future__ import annotations

import math

import numpy as np
import pytest

import mechdsl
from mechdsl.diagnostics import MechError, UsageError
from mechdsl.simulation.drive import table

from conftest import MODELS

TIGHT = dict(rtol=1e-12, atol=1e-12)

LINEAR = """
model Linear "a pendulum linearized: theta'' = -(g/L) theta"
  parameter Real m(unit = "kg") = 1;
  parameter Real L(unit = "m") = 0.8;
  parameter Real g(unit = "m/s2") = 9.81;
  parameter Real a(unit = "deg") = 10 "release angle";
  coordinate Real theta(start = a, speed = 0.3, unit = "rad");
equation
  kinetic = 1/2*m*L^2*der(theta)^2;
  potential = 1/2*m*g*L*theta^2;
end Linear;
"""


def _rel(a, b):
    a, b = np.asarray(a, float), np.asarray(b, float)
    return float(np.max(np.abs(a - b)) / max(np.max(np.abs(b)), 1e-300))


def _run_kw(kw):
    """The settings of Model.sensitivities as Model.simulate takes them (integrator -> method)."""
    kw = dict(kw)
    if "integrator" in kw:
        kw["method"] = kw.pop("integrator")
    return kw


def _fd_param(m, name, h, out, t_end, **kw):
    kw = _run_kw(kw)
    v = m.parameters[name]
    rp = m._with_real({name: v + h}).simulate(t_end, **kw)
    rm = m._with_real({name: v - h}).simulate(t_end, **kw)
    return (rp[out] - rm[out]) / (2 * h)


def _fd_start(m, key, h, out, t_end, base, **kw):
    kw = _run_kw(kw)
    rp = m.simulate(t_end, x0={key: base + h}, **kw)
    rm = m.simulate(t_end, x0={key: base - h}, **kw)
    return (rp[out] - rm[out]) / (2 * h)


@pytest.fixture(scope="module")
def double():
    return mechdsl.load(MODELS / "double_pendulum.mech", model="DoublePendulum")


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
def test_forward_against_central_differences_of_runs(double):
    """Fixed steps (rk, dt given): the run is a smooth function of the values, so central
    differences of Model.simulate are accurate to ~1e-10; the forward sensitivities agree to
    1e-6 relative for parameters and start values, on coordinates, speeds and outputs."""
    kw = dict(integrator="rk", dt=2e-3, points=51)
    S = double.sensitivities(1.0, params=["l", "g", "m"], starts=["j1.phi", "der(j2.phi)"], **kw)
    assert S.metadata["integration"]["method"] == "rk"
    for name in ("l", "g"):
        for out in ("j2.phi", "x2", "der(j1.phi)"):
            assert _rel(S[out, name], _fd_param(double, name, 1e-5, out, 1.0, **kw)) < 1e-6, (out, name)
    # the motion does not depend on the mass (both rods carry it); the potential energy does, as V / m
    assert np.max(np.abs(S["x2", "m"])) < 1e-9 * np.max(np.abs(S["x2", "l"]))
    assert _rel(S["potential_energy", "m"], _fd_param(double, "m", 1e-5, "potential_energy", 1.0, **kw)) < 1e-6
    assert _rel(S["x2", "j1.phi"], _fd_start(double, "j1.phi", 1e-6, "x2", 1.0, math.pi / 2, **kw)) < 1e-6
    assert _rel(S["y2", "der(j2.phi)"], _fd_start(double, "der(j2.phi)", 1e-6, "y2", 1.0, 0.0, **kw)) < 1e-6


def test_forward_and_adjoint_with_adaptive_steps(double):
    """erk at rtol 1e-12 (the method auto picks here): both methods against central differences
    of adaptive runs (1e-6 relative), and against each other (1e-9)."""
    kw = dict(points=11, **TIGHT)
    S = double.sensitivities(1.0, params=["l", "g"], starts=["j1.phi"], **kw)
    assert S.metadata["integration"]["method"] == "erk"
    A = double.sensitivities(1.0, params=["l", "g"], starts=["j1.phi"], method="adjoint", outputs=["x2", "j2.phi"],
                             times=[0.5, 1.0], **TIGHT)
    assert A.t.tolist() == [0.5, 1.0]
    for name in ("l", "g", "j1.phi"):
        for out in ("x2", "j2.phi"):
            assert _rel(A[out, name], S[out, name][[5, 10]]) < 1e-9
    assert _rel(S["x2", "l"], _fd_param(double, "l", 1e-4, "x2", 1.0, **kw)) < 1e-6
    assert _rel(S["j2.phi", "g"], _fd_param(double, "g", 1e-4, "j2.phi", 1.0, **kw)) < 1e-6


def test_adjoint_of_an_integral_objective(double):
    """d/dp of the integral of a signal over the run: the adjoint (a quadrature of the run's
    integrator) equals the forward sensitivity of the running integral at the end, and central
    differences of the integral."""
    J = "integral(potential_energy)"
    A = double.sensitivities(1.0, params=["l", "g", "m"], method="adjoint", integral="potential_energy", **TIGHT)
    F = double.sensitivities(1.0, params=["l", "g", "m"], integral=["potential_energy"], points=11, **TIGHT)
    assert A.outputs == (J,) and A.units[J, "l"] == "J.s/m"
    for n in ("l", "g", "m"):
        assert A[J, n] == pytest.approx(F[J, n][-1], rel=1e-9)
    h, v = 1e-5, double.parameters["g"]
    jp, jm = (double._with_real({"g": v + d}).sensitivities(1.0, params=["g"], integral="potential_energy",
                                                            method="adjoint", **TIGHT).values[J] for d in (h, -h))
    assert A[J, "g"] == pytest.approx((jp - jm) / (2 * h), rel=1e-6)


def test_the_one_call_adjoint_equals_the_function_reverse(double):
    """Seeds on the state and the integrals take one integrator call with adjoint directions
    (Trajectory._reverse_once); it equals the adjoint of the trajectory Function (CasADi's
    reverse of the whole graph, after a separate run for the values), and a seed on an
    output (which needs the values first) takes the latter."""
    from mechdsl.eom import parameter_vector
    from mechdsl.simulation.prepared import prepare

    problem = double.problem(t_end=1.0, points=11, compiled=False, **TIGHT)
    tr = prepare(problem).trajectory(integrals=("potential_energy",))
    pv = parameter_vector(problem.eom, problem.settings.p)
    x = tr.start(pv)[0]
    N, k = tr.times.size, len(tr.names)
    sy, sq = np.zeros((2, k, N)), np.zeros((2, 1, N))
    sy[0, tr.names.index("j2.phi"), -1] = 1.0
    sy[0, tr.names.index("der(j1.phi)"), 4] = 0.5
    sq[1, 0, -1] = 1.0
    assert tr._once(sy)
    once = tr.reverse(x, pv, sy, sq)
    graph = tr.reverse(x, pv, sy, sq, nominal=tr.evaluate(x, pv))
    for a, b in zip(once, graph):
        assert np.abs(a - b).max() <= 1e-9 * np.abs(b).max()
    sy[0, tr.names.index("x2"), -1] = 1.0
    assert not tr._once(sy)


def test_linear_pendulum_against_its_closed_form():
    """theta(t) = theta0 cos(w t) + v0/w sin(w t), w = sqrt(g/L): d theta/d theta0 = cos(w t),
    d theta/d v0 = sin(w t)/w, d theta/dL = t sin(w t) w theta0/(2L) + v0 (sin(w t) - w t cos(w t))/(2 w L);
    the start written as a parameter in degrees: d theta / d a = cos(w t) pi/180 per degree."""
    m = mechdsl.loads(LINEAR)
    S = m.sensitivities(2.0, params=["L", "a"], starts=["der(theta)"], points=41, **TIGHT)
    t = S.t
    th0, v0, L, g = math.radians(10), 0.3, 0.8, 9.81
    w = math.sqrt(g / L)
    assert _rel(S["theta", "der(theta)"], np.sin(w * t) / w) < 1e-8
    dL = t * np.sin(w * t) * w * th0 / (2 * L) + v0 * (np.sin(w * t) - w * t * np.cos(w * t)) / (2 * w * L)
    assert _rel(S["theta", "L"], dL) < 1e-8
    assert _rel(S["theta", "a"], np.cos(w * t) * math.pi / 180) < 1e-8
    assert S.units["theta", "a"] == "rad/deg" and S.units["der(theta)", "L"] == "rad/s/m"
    assert S.name_units == {"L": "m", "a": "deg", "der(theta)": "rad/s"}
    T = m.sensitivities(2.0, starts=["theta"], points=41, **TIGHT)       # the start itself: per radian
    assert _rel(T["theta", "theta"], np.cos(w * t)) < 1e-8


def test_small_angle_period_dT_dL():
    """The pendulum's quarter period t* (theta = 0) moves with L by dt*/dL = -(d theta/dL)/theta'
    at t*; the period T = 4 t* then has dT/dL = pi/sqrt(g L) (amplitude 1e-3 rad: the
    finite-amplitude correction theta0^2/16 is 6e-8)."""
    m = mechdsl.load(MODELS / "pendulum.mech", model="PendulumLagrange")
    L, g = 1.0, 9.81
    quarter = math.pi / 2 * math.sqrt(L / g) * (1 + 1e-6 / 16)
    S = m.sensitivities(quarter, params=["L"], method="adjoint", outputs=["theta", "der(theta)"], times=[quarter],
                        x0={"theta": 1e-3}, **TIGHT)
    dT_dL = -4 * S["theta", "L"][0] / S.values["der(theta)"][0]
    assert dT_dL == pytest.approx(math.pi / math.sqrt(g * L), rel=1e-6)


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
def test_constrained_four_bar_through_the_formulated_problem():
    """The four-bar (three coordinates, two loop constraints): derivatives of the rocker angle,
    a speed and a reaction output with respect to link lengths and the crank's start angle and
    speed (consistent initialization moves the other coordinates) against central differences
    of projection runs."""
    m = mechdsl.load(MODELS / "four_bar.mech", model="FourBar")
    kw = dict(points=6, rtol=1e-11, atol=1e-11)
    S = m.sensitivities(0.5, params=["a", "b"], starts=["crank_pivot.phi", "der(crank_pivot.phi)"], **kw)
    assert "index-1 ODE" in S.metadata["integration"]["why"]
    for n in ("a", "b"):
        for out in ("rocker_pivot.phi", "der(elbow.phi)", "F_close[1]"):
            assert _rel(S[out, n], _fd_param(m, n, 1e-5, out, 0.5, **kw)) < 1e-6, (out, n)
    fd = _fd_start(m, "crank_pivot.phi", 1e-5, "rocker_pivot.phi", 0.5, math.pi / 2, **kw)
    assert _rel(S["rocker_pivot.phi", "crank_pivot.phi"], fd) < 1e-6
    fd = _fd_start(m, "der(crank_pivot.phi)", 1e-5, "der(rocker_pivot.phi)", 0.5, 2.0, **kw)
    assert _rel(S["der(rocker_pivot.phi)", "der(crank_pivot.phi)"], fd) < 1e-6


@pytest.mark.slow_cases('callable')  # CPU budget: the cheaper tests of this file stay in the default run
@pytest.mark.parametrize("signal", ["zoh", "linear", "callable"])
def test_input_driven_runs(signal):
    """The cart-pole pushed by a zero-order-hold table (the run restarts at its samples: one
    integrator per piece, chained), a linear table and a Python function of time."""
    m = mechdsl.load(MODELS / "cart_pole.mech", model="CartPole")
    F = {"zoh": table([0, 0.3, 0.6, 0.8], [1.0, -2.0, 0.5, 0.5]), "linear": table([0, 0.3, 0.6, 0.8], [1.0, -2.0, 0.5, 0.5], "linear"),
         "callable": lambda t: math.sin(5 * t)}[signal]
    kw = dict(points=9, inputs={"F": F}, **TIGHT)
    S = m.sensitivities(0.8, params=["M", "l"], **kw)
    if signal == "zoh":
        assert S.metadata["integration"]["pieces"] == 3
    assert "F" in S.outputs
    for n in ("M", "l"):
        assert _rel(S["theta", n], _fd_param(m, n, 1e-5, "theta", 0.8, **kw)) < 1e-6
        assert _rel(S["tip_x", n], _fd_param(m, n, 1e-5, "tip_x", 0.8, **kw)) < 1e-6


def test_to_xarray_has_units():
    m = mechdsl.loads(LINEAR)
    ds = m.sensitivities(1.0, params=["L", "a"], points=5).to_xarray()
    assert ds["d(theta)/d(a)"].attrs["units"] == "rad/deg" and ds["theta"].attrs["units"] == "rad"
    assert ds["d(energy)/d(L)"].attrs["units"] == "J/m" and ds["time"].size == 5


def test_contacts_are_refused_at_the_contact():
    m = mechdsl.load(MODELS / "bouncing_ball.mech")
    with pytest.raises(MechError) as e:
        m.sensitivities(1.0, params=[m.parameter_names[0]])
    d = e.value.first
    assert d.code == "E770" and d.span.line > 0 and "saltation" in d.message and "sweep" in d.help


@pytest.mark.parametrize("kw, text", [
    (dict(params=["L2"]), "did you mean 'L'"),
    (dict(params=["theta"]), "is a coordinate"),
    (dict(starts=["phi"]), "not a coordinate"),
    (dict(params=["L"], method="backward"), "'forward' or 'adjoint'"),
    (dict(params=["L"], method="adjoint", times=[3.0]), "outside the run"),
    (dict(params=["L"], outputs=["z"]), "not a recorded signal"),
    (dict(params=["L"], times=[0.5]), "adjoint"),
    (dict(params=["L"], integrator="stormer-verlet"), "canonical"),
    (dict(params=["L"], integrator="scipy-dop853"), "no CasADi integrator"),
    (dict(), "at least one"),
])
def test_bad_requests_are_usage_errors(kw, text):
    m = mechdsl.load(MODELS / "pendulum.mech", model="Pendulum")
    with pytest.raises(UsageError, match=text):
        m.sensitivities(1.0, **kw)


def test_dependent_parameters_are_named_and_their_sources_differentiate_through_them():
    m = mechdsl.loads("""
model Bar
  parameter Real m(unit = "kg") = 2;
  parameter Real l(unit = "m") = 0.5;
  parameter Real J(unit = "kg.m2") = m*l^2/3;
  parameter Real g(unit = "m/s2") = 9.81;
  coordinate Real th(start = 1, unit = "rad");
equation
  kinetic = 1/2*J*der(th)^2;
  potential = -m*g*l/2*cos(th);
end Bar;
""")
    with pytest.raises(UsageError, match=r"dependent parameter.*J = "):
        m.sensitivities(1.0, params=["J"])
    S = m.sensitivities(1.0, params=["l"], points=5, **TIGHT)       # theta'' = -3 g/(2 l) sin(theta)
    assert _rel(S["th", "l"], _fd_param(m, "l", 1e-5, "th", 1.0, points=5, **TIGHT)) < 1e-6


def test_the_run_function_is_reused_only_for_the_same_run():
    """cached_trajectory: the same equations, settings and times give the same Trajectory (its
    derivative Functions built once); other parameters, tolerances or times another, and the
    values always those of a run at those parameters."""
    from mechdsl.simulation.prepared import prepare

    m = mechdsl.load(MODELS / "pendulum.mech", model="Pendulum")

    def traj(model, **kw):
        return prepare(model.problem(t_end=1.0, points=5, compiled=False, **kw)).trajectory()

    a = traj(m)
    assert traj(m) is a and traj(m, rtol=1e-9) is not a
    assert prepare(m.problem(t_end=1.0, points=5, compiled=False)).trajectory(times=[0.5, 1.0]) is not a
    for L in (1.0, 2.0, 1.0):
        mm = m.with_params(L=L)
        S = mm.sensitivities(1.0, params=["g"], points=5, rtol=1e-10, atol=1e-10)
        r = mm.simulate(1.0, points=5, rtol=1e-10, atol=1e-10, compiled=False)
        assert np.allclose(S.values["x"], r["x"], rtol=0, atol=1e-8), L
