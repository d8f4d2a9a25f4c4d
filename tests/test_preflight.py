"""The start check (mechdsl.eom.preflight, E740-E748, E754) and the degenerate component values
(semantic/physical.py, E510-E512): what `mech check` accepts, `mech simulate` can start.

Each case is a model that passed `check` (exit 0) before and failed or hung in `simulate`, or a
value the fuzzer found on a shipped model; each now gets a coded, located error from both."""
from __future__ import annotations

import re

import numpy as np
import pytest

import mechdsl
from mechdsl.cli import main
from mechdsl.diagnostics import MechError
from mechdsl.eom.preflight import _mass_problems, preflight

from conftest import MODELS

SPHERICAL = """model SphPend
  Gravity gravity(g = {0, -9.81, 0});
  PointMass bob(m = 1);
  Point pivot(body = world, r = {0, 0, 0});
  Spherical j(parent = pivot, child = bob, theta(start = 0.3));
end SphPend;
"""
COINCIDENT = """model SD
  Gravity gravity(g = {0, -9.81, 0});
  PointMass bob(m = 1);
  Planar j(parent = world, child = bob, axis = {0, 0, 1});
  SpringDamper sd(a = world, b = bob, k = 10, c = 1, l0 = 0.5);
end SD;
"""
NO_MASS = """model NoMass
  parameter Real m = 0;
  Gravity gravity(g = {0, -9.81, 0});
  PointMass bob(m = m);
  Revolute j(parent = world, child = bob, axis = {0, 0, 1});
end NoMass;
"""
NOT_QUADRATIC = """model NQ
  coordinate Real x(start = 1);
  coordinate Real y(start = 0);
equation
  kinetic = der(x)^4 + der(y)^2;
  potential = y;
  0 = x^2 + y^2 - 1;
end NQ;
"""
ZERO_OVER_ZERO = """model Z
  parameter Real r = 1;
  parameter Real a = 0/(r - r);
  PointMass p(m = 1);
  Prismatic j(parent = world, child = p, axis = {1, 0, 0}, s(start = a));
end Z;
"""


def _cli(args, capsys):
    rc = main(args)
    cap = capsys.readouterr()
    assert "Traceback" not in cap.err and "internal error" not in cap.err
    return rc, cap.err


def _located(err: str, code: str, path, line: int) -> None:
    """A coded error at path:line:col, with the source line, a caret and a hint."""
    m = re.search(rf"^(\S+):(\d+):(\d+): error\[{code}\]", err, re.M)
    assert m, err
    assert m.group(1).endswith(str(path.name)) and int(m.group(2)) == line, err
    assert "^" in err and "help:" in err


def _write(tmp_path, text, name="m.mech"):
    path = tmp_path / name
    path.write_text(text)
    return path


@pytest.mark.parametrize("text,code,line,words", [
    (SPHERICAL, "E730", 5, "a point mass on a Spherical joint has no inertia about the rod"),
    (COINCIDENT, "E745", 5, "ends of spring-damper 'sd' coincide"),
    (NO_MASS, "E730", 5, "joint 'j' moves no mass"),
    (NOT_QUADRATIC, "E754", 5, "not quadratic in the speeds"),
    (ZERO_OVER_ZERO, "E303", 3, "division by zero"),
], ids=["spherical-point-mass", "coincident-spring", "no-mass", "not-quadratic", "zero-over-zero"])
def test_check_and_simulate_refuse_the_same_start(tmp_path, capsys, text, code, line, words):
    path = _write(tmp_path, text)
    rc, err = _cli(["check", str(path)], capsys)
    assert rc == 1
    _located(err, code, path, line)
    assert words in err
    rc, err = _cli(["simulate", str(path), "--t-end", "0.1", "--no-progress", "-o", str(tmp_path / "o.csv")], capsys)
    assert rc == 1 and f"error[{code}]" in err
    assert not (tmp_path / "o.csv").exists()


def _edited(tmp_path, model: str, old: str, new: str):
    text = (MODELS / model).read_text()
    assert old in text
    return _write(tmp_path, text.replace(old, new, 1), model)


@pytest.mark.parametrize("model,old,new,code,line", [
    ("slider_crank.mech", 'l(unit = "m") = 0.3', 'l(unit = "m") = 1e-320', "E740", 11),
    ("slider_crank.mech", 'l(unit = "m") = 0.3', 'l(unit = "m") = 0.05', "E741", 22),
    ("slider_crank.mech", 'l(unit = "m") = 0.3', 'l(unit = "m") = -0.5', "E511", 18),
    ("slider_crank.mech", 'l(unit = "m") = 0.3', 'l(unit = "m") = 1e308', "E510", 18),
    ("nfourbar.mech", "phi(start = zeros(N + 1)", "phi(start = fill(tan(pi/2), N + 1)", "E748", 27),
    ("particle_on_sphere.mech", 'R(unit = "m") = 1 ', 'R(unit = "m") = 1.7e308 ', "E746", 15),
    ("bouncing_ball.mech", "normal = {0, 1, 0}", "normal = {0, 0, 0}", "E512", 30),
    ("falling_rod.mech", 'L(unit = "m") = 1 ', 'L(unit = "m") = 0 ', "E743", 26),
    ("falling_rod.mech", 'm(unit = "kg") = 1 ', 'm(unit = "kg") = 1e308 ', "E746", 16),
], ids=["slider-tiny-length", "slider-rod-shorter-than-crank", "slider-negative-length", "slider-huge-length", "nfourbar-tan-pi-2",
        "sphere-huge-radius", "ball-zero-normal", "rod-zero-length", "rod-huge-mass"])
def test_fuzzer_values_on_shipped_models(tmp_path, capsys, model, old, new, code, line):
    """Each was a traceback (exit 3), a hang, or nan/inf results with exit 0."""
    path = _edited(tmp_path, model, old, new)
    rc, err = _cli(["check", str(path)], capsys)
    assert rc == 1
    _located(err, code, path, line)


@pytest.mark.parametrize("setting,code,line", [("L=0", "E743", 26), ("m=1e308", "E746", 16), ("L=-1", "E511", 25)])
def test_simulate_set_is_checked(tmp_path, capsys, setting, code, line):
    """`--set L=0` on falling_rod never returned; now it is refused before the first step
    (at the joint whose rotation has no inertia, the model, the rod)."""
    rc, err = _cli(["simulate", str(MODELS / "falling_rod.mech"), "--set", setting, "--t-end", "0.5",
                    "--no-progress", "-o", str(tmp_path / "o.csv")], capsys)
    assert rc == 1 and f"error[{code}]" in err
    _located(err, code, MODELS / "falling_rod.mech", line)
    assert not (tmp_path / "o.csv").exists()


def test_api_parameter_vector_is_checked_at_simulate():
    """simulate(eom, p=...) does not go through with_params: the start check sees the values."""
    from mechdsl.simulate import simulate

    m = mechdsl.load(MODELS / "falling_rod.mech", model="FallingRod")
    with pytest.raises(MechError) as e:
        simulate(m.eom, 0.1, p={"L": 0.0})
    assert e.value.first.code == "E743" and "fly.phi" in e.value.first.message
    with pytest.raises(MechError) as e:
        m.with_params(L=1e308).simulate(0.1)
    assert e.value.first.code == "E510"


def test_non_finite_parameter_vector_is_named():
    m = mechdsl.load(MODELS / "pendulum.mech", model="Pendulum")
    p = np.array(m.eom.param_values, float)
    p[0] = np.inf
    found = preflight(m.eom, p)
    assert [d.code for d in found] == ["E740"] and m.eom.params[0] in found[0].message
    assert found[0].span.line > 0


@pytest.mark.parametrize("value", [1e-320, -5e-324])
def test_subnormal_parameter_is_refused(value):
    """falling_rod with m = 1e-320 ran for minutes on subnormal arithmetic (and m g had 2 digits)."""
    m = mechdsl.load(MODELS / "falling_rod.mech", model="FallingRod")
    found = preflight(m.eom, {"m": value})
    assert [d.code for d in found] == ["E740"] and "'m'" in found[0].message and "too small" in found[0].message
    assert preflight(m.eom, {"m": 1e-300}) == []        # small, but a normal number


def test_shipped_models_start_clean():
    """The check finds nothing on a shipped model with its own values (all are run by test_cli_check)."""
    m = mechdsl.load(MODELS / "slider_crank.mech")
    assert preflight(m.eom) == []


@pytest.mark.parametrize("seed", range(4))
def test_singular_direction_matches_a_constructed_null_vector(seed):
    """Against an independent construction: M = A diag(ev) A^T with one zero eigenvalue whose
    eigenvector involves known coordinates; the check names exactly those (and none for ev > 0)."""
    rng = np.random.default_rng(seed)
    n = 5
    eom = mechdsl.loads("model Chain\n" + "".join(f"  coordinate Real q{i};\n" for i in range(n))
                        + "equation\n  kinetic = " + " + ".join(f"der(q{i})^2" for i in range(n))
                        + ";\nend Chain;\n").eom
    k = sorted(rng.choice(n, size=2, replace=False))
    null = np.zeros(n)
    null[k] = rng.uniform(0.5, 1.0, size=2) * rng.choice([-1, 1], size=2)
    null /= np.linalg.norm(null)
    Q, _ = np.linalg.qr(np.column_stack([null, rng.normal(size=(n, n - 1))]))
    scales = 10.0 ** rng.uniform(-3, 3, size=n)
    ev = np.r_[0.0, rng.uniform(1.0, 5.0, size=n - 1)]
    M = Q @ np.diag(ev) @ Q.T
    M = scales[:, None] * M * scales[None, :]        # other units: the check must not care
    found = _mass_problems(eom, M, None)
    assert [d.code for d in found] == ["E743"]
    named = found[0].message.split(": ", 1)[1]
    assert all(eom.coords[i] in named for i in k)
    assert not any(eom.coords[i] in named for i in range(n) if i not in k)
    ev[0] = 1e-3
    assert _mass_problems(eom, scales[:, None] * (Q @ np.diag(ev) @ Q.T) * scales[None, :], None) == []


@pytest.mark.parametrize("value", [1e-320, 1e308])
def test_initialization_never_raises_a_numpy_error(value):
    """dae.init called directly (as analyses do) on a slider-crank whose rod length makes the
    start nan or inf: a located E826, not numpy's LinAlgError from lstsq."""
    from mechdsl.dae.init import initialize
    from mechdsl.eom import parameter_vector

    eom = mechdsl.load(MODELS / "slider_crank.mech").eom
    with pytest.raises(MechError) as e:
        initialize(eom, p=parameter_vector(eom, {"l": value}))
    assert e.value.first.code == "E826" and e.value.first.span.line > 0


@pytest.mark.parametrize("text,code", [(SPHERICAL, "E730"), (COINCIDENT, "E745"), (NO_MASS, "E730")],
                         ids=["spherical-point-mass", "coincident-spring", "no-mass"])
def test_api_simulate_refuses_at_the_start(text, code):
    with pytest.raises(MechError) as e:
        mechdsl.loads(text).simulate(0.1)
    assert e.value.first.code == code and e.value.first.span.line == 5


def test_api_with_params_zero_mass_is_named():
    """A pendulum bob of mass 0 (a parameter, so not caught while deriving): E743 names the joint."""
    m = mechdsl.load(MODELS / "pendulum.mech", model="Pendulum").with_params(m=0.0)
    with pytest.raises(MechError) as e:
        m.simulate(0.1)
    d = e.value.first
    assert d.code == "E743" and "theta (joint 'hinge') moves no inertia" in d.message and d.span.line > 0


def test_negative_kinetic_energy_in_the_equation_layer():
    """A negative mass inside `kinetic = ...` is no component value (E508 cannot see it); the
    start check finds the negative eigenvalue of M and names the coordinate."""
    text = """model Neg
  parameter Real m = -1;
  coordinate Real x(start = 0);
  coordinate Real y(start = 0);
equation
  kinetic = 1/2*der(x)^2 + 1/2*m*der(y)^2;
  potential = x^2 + y^2;
end Neg;
"""
    found = preflight(mechdsl.loads(text).eom)
    assert [d.code for d in found] == ["E743"] and "negative kinetic energy" in found[0].message
    assert "y" in found[0].message.split(": ", 1)[1] and " x" not in found[0].message.split(": ", 1)[1]
    assert preflight(mechdsl.loads(text).with_params(m=2.0).eom) == []


def test_loop_too_large_for_the_drift_bound(tmp_path, capsys):
    """nfourbar with l = tan(pi/2) = 1.6e16 m: positions resolved to ~4 m cannot be held to 1e-9
    (the projection never converged: the run did not return)."""
    rc, err = _cli(["check", str(MODELS / "nfourbar.mech"), "--model", "NFourBar"], capsys)
    assert rc == 0
    m = mechdsl.load(MODELS / "nfourbar.mech", model="NFourBar")
    found = preflight(m.eom, {"l": 1.633123935319537e16})
    assert [d.code for d in found] == ["E749"] and found[0].span.line == 29
    assert preflight(m.eom, {"l": 1e3}) == []            # a large but resolvable mechanism is fine


def test_start_overrides_replace_the_model_values():
    """x0 given by the caller replaces a start value the model cannot compute (asin of 1e319):
    the run starts; without the override the start check names the coordinate."""
    from mechdsl.simulate import simulate

    eom = mechdsl.load(MODELS / "pendulum.mech", model="Pendulum").eom
    ok = preflight(eom, None, {"theta": 0.3})
    assert ok == []
    with_bad = eom.replace(q0=eom.q0 * float("nan"))
    assert [d.code for d in preflight(with_bad)] == ["E741"]
    assert preflight(with_bad, None, {"theta": 0.3, "der(theta)": 0.0}) == []
    r = simulate(with_bad, 0.05, x0={"theta": 0.3, "der(theta)": 0.0}, points=3)
    assert r.failure is None and r.q[0, 0] == pytest.approx(0.3) and np.all(np.isfinite(r.q))


@pytest.mark.parametrize("formula", ["0/(r - r)", "0*(1/(r - r))", "(r - r)*(1/(r - r))"])
def test_zero_times_undefined_is_not_folded_to_zero(formula):
    """The constant folder turned 0/x and 0*x into 0 for any x: 0/(r - r) was a silent 0."""
    text = ZERO_OVER_ZERO.replace("0/(r - r)", formula)
    with pytest.raises(MechError) as e:
        mechdsl.loads(text)
    assert [d.code for d in e.value.diagnostics] == ["E303"] and e.value.first.span.line == 3


def test_constraint_not_finite_at_the_start_is_named():
    text = """model C
  coordinate Real x(start = 1);
  coordinate Real y(start = 0, fixed = false);
equation
  kinetic = 1/2*der(x)^2 + 1/2*der(y)^2;
  potential = y;
  y = sqrt(x - 2) "guide";
end C;
"""
    found = preflight(mechdsl.loads(text).eom)
    assert [d.code for d in found] == ["E826"] and "guide" in found[0].message and found[0].span.line == 7


def test_mass_matrix_not_finite_at_the_start_is_named():
    text = """model K
  coordinate Real x(start = 1);
  coordinate Real y(start = 0);
equation
  kinetic = 1/2*der(x)^2/(x - 1) + 1/2*der(y)^2;
  potential = y;
end K;
"""
    found = preflight(mechdsl.loads(text).eom)
    assert [d.code for d in found] == ["E742"] and "equation of x" in found[0].message
    assert preflight(mechdsl.loads(text.replace("start = 1", "start = 2")).eom) == []


def test_parametric_axis_of_zero_length_is_named_without_warnings():
    """axis = {0, 0, a} is stored normalized (a / sqrt(a^2)): a = 0 was nan everywhere; now E512
    for the joint and the rod, and no numpy RuntimeWarning on the way."""
    import warnings

    text = """model Ax
  parameter Real a = 1;
  Gravity gravity(g = {0, -9.81, 0});
  Rod rod(m = 1, L = 1, axis = {a, 0, 0});
  Revolute j(parent = world, child = rod.a, axis = {0, 0, a});
end Ax;
"""
    m = mechdsl.loads(text)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        with pytest.raises(MechError) as e:
            m.with_params(a=0.0)
    assert [(d.code, d.span.line) for d in e.value.diagnostics] == [("E512", 4), ("E512", 5)]
    m.with_params(a=-2.0)                           # any nonzero direction is fine


def test_crank_of_length_zero_in_a_loop(tmp_path, capsys):
    """four_bar with crank length a = 0: on the one motion the loop allows, the crank and the
    coupler turn against each other moving no inertia (M is singular on null(G), a 1x1 matrix
    that was compared with itself); the run failed inside the integrator at t = 0."""
    rc, err = _cli(["simulate", str(MODELS / "four_bar.mech"), "--set", "a=0", "--t-end", "0.2",
                    "--no-progress", "-o", str(tmp_path / "o.csv")], capsys)
    assert rc == 1 and "error[E743]" in err and "on the motions the constraints allow" in err
    assert "crank_pivot.phi" in err and "elbow.phi" in err
    assert preflight(mechdsl.load(MODELS / "four_bar.mech").eom, {"a": 0.05}) == []


@pytest.mark.parametrize("setting", ["a=0", "e=1"])
def test_dependent_parameter_that_cannot_be_evaluated(tmp_path, capsys, setting):
    """kepler's vp = sqrt(mu (1 + e) / (a (1 - e))): `--set a=0` was a ZeroDivisionError (exit 3)."""
    rc, err = _cli(["simulate", str(MODELS / "kepler.mech"), "--set", setting, "--t-end", "0.1",
                    "--no-progress", "-o", str(tmp_path / "o.csv")], capsys)
    assert rc == 1 and "error[E303]" in err and "parameter 'vp'" in err
    _located(err, "E303", MODELS / "kepler.mech", 26)


@pytest.mark.parametrize("model,setting,code,line", [
    ("newtons_cradle.mech", "r=1e308", "E756", 40),  # the balls' gaps: nan columns, exit 0
])
def test_gaps_not_finite_at_the_start(tmp_path, capsys, model, setting, code, line):
    rc, err = _cli(["simulate", str(MODELS / model), "--set", setting, "--t-end", "0.1",
                    "--no-progress", "-o", str(tmp_path / "o.csv")], capsys)
    assert rc == 1
    _located(err, code, MODELS / model, line)


@pytest.mark.parametrize("old,new,line,what", [
    ('m1(unit = "kg") = 0.04325', 'm1(unit = "kg") = -1', 15, "negative mass"),
    ('i3(unit = "kg.m2") = 5.255e-06', 'i3(unit = "kg.m2") = -1e-3', 31, "negative moment of inertia"),
], ids=["mass", "inertia"])
def test_negative_mass_in_the_equation_layer_of_andrews(tmp_path, capsys, old, new, line, what):
    """andrews.mech with m1 = -1 ran to the end (exit 0): the reduced mass matrix stays positive
    definite, so E743 cannot see it.  The parameter is a mass by its unit and because T grows
    linearly with it; `check`, `simulate` and `--set` refuse it at the parameter (E747)."""
    path = _edited(tmp_path, "andrews.mech", old, new)
    rc, err = _cli(["check", str(path)], capsys)
    assert rc == 1 and what in err
    _located(err, "E747", path, line)
    rc, err = _cli(["simulate", str(MODELS / "andrews.mech"), "--set", new.split("(")[0] + "=" + new.split("= ")[-1],
                    "--t-end", "0.001", "--no-progress", "-o", str(tmp_path / "o.csv")], capsys)
    assert rc == 1 and "error[E747]" in err and not (tmp_path / "o.csv").exists()


EQUATION_LAYER = """model Rotor
  parameter Real A(unit = "kg.m2") = 2;
  parameter Real B(unit = "kg.m2") = 3;
  parameter Real C(unit = "kg.m2") = -0.5;
  parameter Real dm(unit = "kg", min = -0.5) = -0.25;
  parameter Real m(unit = "kg") = 1;
  coordinate Real a(start = 0);
  coordinate Real b(start = 0);
  coordinate Real x(start = 0);
equation
  kinetic = 1/2*(A*der(a)^2 + B*der(b)^2) + C*der(a)*der(b) + 1/2*(m + dm)*der(x)^2;
  potential = a^2 + b^2 + x^2;
end Rotor;
"""


def test_negative_mass_check_spares_products_of_inertia_and_declared_ranges():
    """C is a product of inertia (dT/dC = a'b' is indefinite) and dm declares its range: neither
    is a negative mass.  Made negative, the moment A is (dT/dA = a'^2/2 >= 0)."""
    model = mechdsl.loads(EQUATION_LAYER)
    assert preflight(model.eom) == []
    found = preflight(model.eom, {"A": -1.0})
    assert [d.code for d in found] == ["E747"] and "'A'" in found[0].message
    assert found[0].span.line == 2


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
def test_a_loop_smaller_than_the_constraint_tolerance(tmp_path, capsys):
    """Fuzz mutant (issue 18): nfourbar.mech with rods of 1e-12 m and 1e-12 kg.  The constraints
    are held to max(10 atol, 1e-10) = 1e-9 m, a thousand times the mechanism: the run ran away
    (speeds of 1e12 rad/s after 2e-6 s) and did not return in 300 s.  Refused at the start (E755)
    at the joint that closes the first loop; a mechanism of 1e-6 m (1000 x the bound) passes."""
    text = (MODELS / "nfourbar.mech").read_text()
    for old in ('m(unit = "kg") = 1 ', 'l(unit = "m") = 1 '):
        assert old in text
    tiny = text.replace('m(unit = "kg") = 1 ', 'm(unit = "kg") = 1e-12 ').replace('l(unit = "m") = 1 ', 'l(unit = "m") = 1e-12 ')
    path = _write(tmp_path, tiny, "nfourbar.mech")
    rc, err = _cli(["check", str(path)], capsys)
    assert rc == 1 and "measures only 2.27e-12 across" in err
    _located(err, "E755", path, 29)
    found = preflight(mechdsl.loads(text, model="NFourBar").eom, {"l": 1e-6})
    assert found == []


def test_a_contact_model_smaller_than_the_contact_tolerance(tmp_path, capsys):
    """pendulum_wall with L = 1e-12 m: its wall is located to the contact tolerance (1e-8 m at the
    scene's tolerance), ten thousand times the model; it started with the contact closed and
    failed at t = 0 on a step budget.  Refused at the start (E758) at the contact, by check and
    simulate alike; L = 1e-5 m (1000 x the tolerance) passes and runs, and so does the falling
    rod (1.6 m) and the cradle (0.45 m) at atol 1e-3, whose contact tolerance is 0.1 m (a loose
    tolerance is the user's choice)."""
    old = 'L(unit = "m") = 1 '
    path = _edited(tmp_path, "pendulum_wall.mech", old, 'L(unit = "m") = 1e-12 ')
    for cmd in (["check", str(path)], ["simulate", str(path), "--no-progress", "-o", str(tmp_path / "o.csv")]):
        rc, err = _cli(cmd, capsys)
        assert rc == 1 and "measures only 1.14e-12 m across" in err
        _located(err, "E758", path, 28)
    assert not (tmp_path / "o.csv").exists()
    m = mechdsl.load(MODELS / "pendulum_wall.mech")
    assert preflight(m.eom, {"L": 1e-5}) == []
    r = m.with_params(L=1e-5).simulate(0.01, error_estimate="off")
    assert r.failure is None and len(r.events) >= 1          # it swings into the wall and bounces
    for name in ("falling_rod.mech", "newtons_cradle.mech"):
        assert preflight(mechdsl.load(MODELS / name).eom, drift_bound=1e-2) == []


@pytest.mark.parametrize("model,old,new,code,line", [
    ("particle_on_sphere.mech", 'R(unit = "m") = 1 ', 'R(unit = "m") = 1.8e308 ', "E303", 17),
    ("pendulum_wall.mech", "tolerance = 1e-10;", "tolerance = 1e-300;", "E604", 37),
], ids=["sphere-radius-beyond-double", "wall-tolerance-1e-300"])
def test_issue_18_examples_refused_where_written(tmp_path, capsys, model, old, new, code, line):
    """Issue 18: particle_on_sphere with 1.8e308 wrote inf with exit 0; a contact scene with
    tolerance = 1e-300 exited 3 without a CSV.  Both are model errors at the value now."""
    path = _edited(tmp_path, model, old, new)
    for cmd in (["check", str(path)], ["simulate", str(path), "--t-end", "0.05", "--no-progress",
                                        "-o", str(tmp_path / "o.csv")]):
        rc, err = _cli(cmd, capsys)
        assert rc == 1
        _located(err, code, path, line)


def test_falling_rod_from_1e32_m_finishes_with_finite_results(tmp_path, capsys):
    """Issue 18: falling_rod.mech with a number 1e32 (the start height) spun in the event search;
    it now runs 0.05 s and writes finite numbers (exit 0)."""
    path = _edited(tmp_path, "falling_rod.mech", 'h(unit = "m") = 1 ', 'h(unit = "m") = 1e32 ')
    out = tmp_path / "o.csv"
    rc, err = _cli(["simulate", str(path), "--t-end", "0.05", "--points", "5", "--no-progress", "-o", str(out)], capsys)
    assert rc == 0, err
    rows = [line.split(",") for line in out.read_text().splitlines()[1:]]
    assert len(rows) == 5 and all(np.isfinite(float(x)) for row in rows for x in row)


def test_a_subnormal_stop_time_is_a_run_not_an_internal_error(tmp_path, capsys):
    """Fuzzer class 'exit 3': a scene stop_time of 1e-320 overflowed the auto-compile work
    estimate (span * time scale) into an OverflowError.  The run now goes on without an
    estimate: exit 0, finite results, the span as asked."""
    src = (MODELS / "double_pendulum.mech").read_text()
    src = re.sub(r"stop_time = [0-9.e+-]+", "stop_time = 1e-320", src, count=1)
    path = tmp_path / "tiny.mech"
    path.write_text(src)
    out = tmp_path / "tiny.csv"
    rc = main(["simulate", str(path), "-o", str(out), "--no-progress", "--points", "3"])
    text = capsys.readouterr()
    assert rc == 0, text.err
    data = np.loadtxt(out, delimiter=",", skiprows=1, ndmin=2)
    assert np.isfinite(data).all() and data.shape[0] == 3
    assert 0.0 < data[-1, 0] <= 1.0e-319                  # the time column reaches the stop time


def test_a_singular_mass_matrix_on_the_crba_route_is_a_coded_error(tmp_path, capsys):
    """A coordinate that drives two joints (the crba route, M solved by QR) and moves no mass: the
    start check reports E743 instead of failing inside CasADi (found importing romeo.urdf, whose
    hand joints move only massless fingers)."""
    from mechdsl.cli import main

    f = tmp_path / "s.mech"
    f.write_text("""model S
  Gravity g;
  Body a(m = 1, r_cm = {0.5, 0, 0}, I = diagonal({0.1, 0.1, 0.1}));
  Body b(m = 0);
  Body c(m = 0);
  Revolute j1(parent = world, child = a, axis = {0, 0, 1}, phi(start = 0.1));
  Revolute j2(parent = a, child = b, axis = {0, 1, 0}, phi(start = 0.2));
  Revolute j3(parent = b, child = c, axis = {0, 1, 0}, phi = 2*j2.phi);
end S;
""")
    assert main(["check", str(f)]) == 1
    err = capsys.readouterr().err
    assert "error[E743]" in err and "internal error" not in err
