"""Control inputs (issue 13): `input` declarations, the (t, x, u, p) Functions, the API and
driving inputs in a simulation, each compared with a closed form."""
import math
from pathlib import Path

import casadi as ca
import numpy as np
import pytest

import mechdsl
from conftest import simulate_with_csv_input
from mechdsl.diagnostics import MechError, UsageError

from conftest import CHECKOUT, MODELS, TESTS  # noqa: E402

SLIDER = """
model Slider
  parameter Real m(unit = "kg") = 2;
  parameter Real k(unit = "N/m") = 8;
  parameter Real w(unit = "1/s") = sqrt(k / m);
  input Real F(unit = "N", min = -5, max = 5) "push";
  input Real G(unit = "N") = 1.5;
  coordinate Real x(start = 0, speed = 0, unit = "m");
equation
  kinetic = 0.5*m*der(x)^2;
  force(x) = F + G;
end Slider;
"""


@pytest.fixture(scope="module")
def slider():
    return mechdsl.loads(SLIDER, model="Slider")


def test_inputs_are_declared_with_unit_bounds_default(slider):
    info = {i.name: i for i in slider.inputs}
    assert list(info) == ["F", "G"]
    assert info["F"].unit == "N" and info["F"].min == -5 and info["F"].max == 5 and info["F"].default == 0.0
    assert info["F"].doc == "push"
    assert info["G"].min is None and info["G"].default == pytest.approx(1.5)
    assert slider.parameter_names == ("m", "k", "w")        # inputs are not parameters


def test_functions_take_t_x_u_p(slider):
    f = slider.casadi()
    for name in ("ode", "ode_jacobian", "bias", "energy", "outputs"):
        assert f[name].name_in() == ["t", "x", "u", "p"], name
    assert f["ode"].class_name() == "SXFunction"
    xd = np.array(f["ode"](0.0, [0.3, 0.1], [2.0, 1.0], slider.parameter_vector())).ravel()
    assert xd == pytest.approx([0.1, 3.0 / 2.0], rel=1e-14)


def test_functions_without_inputs_have_an_empty_u():
    m = mechdsl.load(str(MODELS / "pendulum.mech"))
    f = m.casadi()["ode"]
    assert f.name_in() == ["t", "x", "u", "p"] and f.numel_in(2) == 0
    assert m.inputs == ()


def test_parameter_vector_recomputes_dependent_parameters(slider):
    assert slider.parameter_vector(k=18.0) == pytest.approx([2.0, 18.0, 3.0], rel=1e-14)
    pf = slider.casadi()["parameters"]
    assert pf.name_in() == ["free"] and pf.numel_in(0) == 2        # m, k (w is computed)
    assert np.array(pf([8.0, 2.0])).ravel() == pytest.approx([8.0, 2.0, 0.5], rel=1e-14)
    # an optimizer can make a parameter a decision variable through it
    k = ca.MX.sym("k")
    p = pf(ca.vertcat(2.0, k))
    xd = slider.casadi()["ode"](0, ca.vertcat(0, 0), ca.vertcat(0, 0), p)
    assert float(ca.Function("g", [k], [ca.jacobian(p[2], k)])(8.0)) == pytest.approx(1 / (2 * math.sqrt(8 * 2)))
    assert xd.shape == (2, 1)
    with pytest.raises(UsageError, match="input"):
        slider.parameter_vector(F=1.0)
    with pytest.raises(UsageError, match="dependent"):
        slider.parameter_vector(w=1.0)


def test_constant_input_closed_form(slider):
    r = slider.simulate(2.0, inputs={"F": 3.0}, rtol=1e-10, atol=1e-12, points=21)
    a = (3.0 + 1.5) / 2.0                      # G keeps its default
    np.testing.assert_allclose(r.q[:, 0], 0.5 * a * r.t ** 2, rtol=1e-8, atol=1e-10)
    assert r["F"] == pytest.approx(np.full(21, 3.0)) and r["G"] == pytest.approx(np.full(21, 1.5))
    assert r.metadata["inputs"] == {"F": "constant 3.0", "G": "default 1.5"}


def test_linear_table_closed_form(slider):
    tab = mechdsl.table([0.0, 2.0], [0.0, 4.0], hold="linear")       # F = 2 t
    r = slider.simulate(2.0, inputs={"F": tab, "G": 0.0}, rtol=1e-10, atol=1e-12, points=11)
    np.testing.assert_allclose(r.q[:, 0], 2.0 * r.t ** 3 / 6 / 2.0, rtol=1e-7, atol=1e-10)


def test_zero_order_hold_table_closed_form(slider):
    rows = np.array([[0.0, 2.0], [1.0, -2.0], [2.0, -2.0]])          # F = 2 on [0, 1), -2 after
    r = slider.simulate(2.0, inputs={"F": rows, "G": 0.0}, rtol=1e-10, atol=1e-12, points=5)
    t = r.t
    v1 = 1.0                                               # speed at t = 1 (a = 1)
    want = np.where(t <= 1, 0.5 * t ** 2, 0.5 + v1 * (t - 1) - 0.5 * (t - 1) ** 2)
    np.testing.assert_allclose(r.q[:, 0], want, atol=1e-6)
    assert r["F"] == pytest.approx([2.0, 2.0, -2.0, -2.0, -2.0])


def test_callable_of_time_and_casadi_function(slider):
    w = 1.3
    want = lambda t: (2.0 / 2.0) * (t / w - np.sin(w * t) / w ** 2)     # noqa: E731  F = 2 sin(w t)
    r1 = slider.simulate(3.0, inputs={"F": lambda t: 2.0 * math.sin(w * t), "G": 0.0}, rtol=1e-10, atol=1e-12,
                         points=31)
    np.testing.assert_allclose(r1.q[:, 0], want(r1.t), atol=1e-7)
    t = ca.MX.sym("t")
    fn = ca.Function("u", [t], [2.0 * ca.sin(w * t)])
    r2 = slider.simulate(3.0, inputs={"F": fn, "G": 0.0}, rtol=1e-10, atol=1e-12, points=31)
    np.testing.assert_allclose(r2.q[:, 0], want(r2.t), atol=1e-7)


def test_state_feedback_gives_the_harmonic_oscillator(slider):
    """u(t, x) = -c x: m x'' = -c x, x = x0 cos(sqrt(c/m) t); as a Python callable and a Function."""
    c = 4.5
    r = slider.simulate(4.0, x0={"x": 0.2}, inputs={"F": lambda t, x: -c * x[0], "G": 0.0},
                        rtol=1e-10, atol=1e-12, points=41)
    np.testing.assert_allclose(r.q[:, 0], 0.2 * np.cos(math.sqrt(c / 2.0) * r.t), atol=1e-7)
    np.testing.assert_allclose(r["F"], -c * r.q[:, 0], rtol=1e-12, atol=1e-14)
    t, x = ca.MX.sym("t"), ca.MX.sym("x", 2)
    r2 = slider.simulate(4.0, x0={"x": 0.2}, inputs={"F": ca.Function("k", [t, x], [-c * x[0]]), "G": 0.0},
                         rtol=1e-10, atol=1e-12, points=41)
    np.testing.assert_allclose(r2.q[:, 0], 0.2 * np.cos(math.sqrt(c / 2.0) * r2.t), atol=1e-7)


@pytest.mark.parametrize("inputs, match", [
    ({"H": 1.0}, "not an input of Slider.*did you mean"),
    ({"F": mechdsl.table([0.0, 1.0], [0.0, 1.0])}, "covers t = 0 .. 1 s, not the run's 0 .. 2 s"),
    ({"F": lambda t: [1.0, 2.0]}, "one number per call"),
    ({"F": lambda t: "a"}, "one number per call"),
    ({"F": lambda t: 1 / 0}, "ZeroDivisionError"),
    ({"F": 6.0}, "outside its declared bounds"),
    ({"F": [[0.0, 0.0], [2.0, -7.0]]}, "outside its declared bounds"),
    ({"F": [1.0, 2.0, 3.0]}, "table"),
    ({"F": {"a": 1}}, "expected a number"),
    ({"F": ca.Function("f", [ca.MX.sym("a", 3)], [ca.MX(1)])}, "takes \\(t\\) or \\(t, x\\)"),
])
def test_bad_inputs_are_clear_usage_errors(slider, inputs, match):
    if "H" in inputs:
        inputs = {"G": 0.0, "Fx": 1.0}
        match = "'Fx' is not an input of Slider \\(its inputs are F, G\\); did you mean 'F'"
    with pytest.raises(UsageError, match=match):
        slider.simulate(2.0, inputs=inputs, points=3)


def test_table_times_must_increase():
    with pytest.raises(UsageError, match="strictly increasing"):
        mechdsl.table([0.0, 1.0, 1.0], [0, 1, 2])
    with pytest.raises(UsageError, match="hold"):
        mechdsl.table([0.0, 1.0], [0, 1], hold="cubic")


def test_run_time_signal_outside_bounds_warns(slider):
    r = slider.simulate(1.0, inputs={"F": lambda t: 10.0 * t}, points=11)
    assert r.success
    assert any("input 'F' went above its maximum 5" in w for w in r.metadata["warnings"])


def test_linearization_has_one_column_per_input(slider):
    lin = slider.linearize(at="start")
    assert lin.inputs == ("F", "G")
    assert lin.B == pytest.approx(np.array([[0.0, 0.0], [0.5, 0.5]]), rel=1e-14)


def test_problem_lists_inputs_and_fixed_step_takes_time_varying_inputs(slider):
    pr = slider.problem(t_end=1.0, inputs={"F": lambda t: 0.0})
    assert pr.inputs == ("F", "G") and dict(pr.input_signals)["F"] == "callable u(t)"
    from mechdsl.simulation import dump

    assert "inputs: F (callable u(t)), G (default 1.5)" in dump(pr)
    # time-varying inputs on the fixed-step back end (before: refused, "ODE problems only"):
    # x'' = (t + 0) / 2 from rest, so x = t^3 / 12 (closed forms per back end: test_inputs_backends.py)
    r = slider.simulate(1.0, method="rk4", dt=0.01, inputs={"F": lambda t: t, "G": 0.0}, points=3)
    assert r.q[-1, 0] == pytest.approx(1.0 / 12.0, rel=1e-9)
    r = slider.simulate(1.0, method="rk4", dt=0.01, inputs={"F": 1.0, "G": 0.0}, points=3)  # constant
    assert r.q[-1, 0] == pytest.approx(0.25, rel=1e-9)


def test_constant_input_on_a_constrained_model():
    src = """
model Bead
  parameter Real m = 1;
  input Real F = 2;
  coordinate Real x(start = 0);
  coordinate Real y(start = 0);
equation
  kinetic = 0.5*m*(der(x)^2 + der(y)^2);
  force(x) = F;
  y = x "line";
end Bead;
"""
    m = mechdsl.loads(src, model="Bead")
    assert m.problem(t_end=1.0).kind == "dae"
    r = m.simulate(1.0, rtol=1e-10, atol=1e-12, points=3)
    assert r.q[-1, 0] == pytest.approx(0.5 * (2.0 / 2.0) * 1.0 ** 2, rel=1e-6)     # a = F / (2 m), F = 2 (default)


def test_cli_input_constant_and_csv(tmp_path):
    from mechdsl.cli import main

    rc, head, rows = simulate_with_csv_input(tmp_path, SLIDER, "time,F\n0,1\n0.5,-1\n1,-1\n", "--t-end", "1",
                                             "--points", "3", "--input", "F={csv}", "--input", "G=0")
    assert rc == 0
    assert "F" in head and "G" in head
    col = [row[head.index("F")] for row in rows]
    assert col == pytest.approx([1.0, -1.0, -1.0])
    x = [row[head.index("x")] for row in rows]
    assert x[1] == pytest.approx(0.5 * 0.5 * 0.25, rel=1e-6)       # a = 1/2 for 0.5 s
    src, csv_in = tmp_path / "model.mech", tmp_path / "f.csv"
    assert main(["simulate", str(src), "--t-end", "2", "--input", f"F={csv_in}", "--no-progress"]) == 2
    assert main(["simulate", str(src), "--t-end", "1", "--input", "F", "--no-progress"]) == 2
    assert main(["simulate", str(src), "--t-end", "1", "--input", f"F={tmp_path / 'none.csv'}",
                 "--no-progress"]) == 2


@pytest.mark.parametrize("rows, hold, message", [
    ("1,1\n0,2\n", "", "--input F: {csv}: a table's times must be strictly increasing"),
    ("0,nan\n1,2\n", "", "--input F: {csv}: a table's times and values must be finite numbers"),
    ("0,1\n5,2\n", ":cubic", "--input F: unknown hold ':cubic' after {csv} (use :zoh or :linear)"),
], ids=["unsorted", "nan", "unknown-hold"])
def test_cli_bad_input_tables_name_the_input_and_the_file(tmp_path, capsys, rows, hold, message):
    """A bad table file or a misspelt hold says which --input and which file (usage error, 2)."""
    from mechdsl.cli import main

    src, csv_in = tmp_path / "model.mech", tmp_path / "f.csv"
    src.write_text(SLIDER)
    csv_in.write_text(rows)
    assert main(["simulate", str(src), "--t-end", "1", "--input", f"F={csv_in}{hold}", "--no-progress"]) == 2
    assert message.format(csv=csv_in) in capsys.readouterr().err


@pytest.mark.parametrize("body, code", [
    ("parameter Real a = 1;\n  input Real F = a;", "E230"),
    ("input Real F = 0;\n  parameter Real a = 2*F;", "E231"),
    ("input Real F(min = 0) = -1;", "E313"),
])
def test_input_declaration_errors(body, code):
    src = f"""model Bad
  {body}
  coordinate Real x(start = 0);
equation
  kinetic = 0.5*der(x)^2;
  force(x) = F;
end Bad;
"""
    with pytest.raises(MechError) as ei:
        mechdsl.loads(src, model="Bad")
    assert code in str(ei.value)


def test_input_in_a_prescribed_motion_is_refused():
    """phi = a (an input) in a joint: the velocities would miss da/dt (before: a silent wrong
    answer, the body turned without angular velocity); now E760 at the input."""
    src = """model PM
  input Real a = 0;
  Gravity gravity(g = {0, -9.81, 0});
  Body b(m = 1, I = identity(3));
  Body c(m = 1, I = identity(3));
  Revolute hinge(parent = world, child = b, axis = {0, 0, 1}, phi = a);
  Prismatic s(parent = b, child = c, axis = {1, 0, 0}, s(start = 0.1));
end PM;
"""
    m = mechdsl.loads(src, model="PM")
    with pytest.raises(MechError) as ei:
        m.eom
    assert "E760" in str(ei.value) and "input 'a' moves part of the mechanism" in str(ei.value)
    assert ":2:14:" in str(ei.value)


def test_an_array_of_inputs_defaults_to_zero_and_is_driven_entrywise():
    src = """model Arr
  input Real tau[2](unit = "N") "pushes";
  coordinate Real x(start = 0);
  coordinate Real y(start = 0);
equation
  kinetic = 0.5*(der(x)^2 + der(y)^2);
  force(x) = tau[1];
  force(y) = tau[2];
end Arr;
"""
    m = mechdsl.loads(src, model="Arr")
    assert [(i.name, i.default) for i in m.inputs] == [("tau[1]", 0.0), ("tau[2]", 0.0)]
    r = m.simulate(1.0, inputs={"tau[1]": 1.0, "tau[2]": lambda t: 2.0 * t}, points=3, rtol=1e-10, atol=1e-12)
    assert r.q[-1] == pytest.approx([0.5, 1.0 / 3.0], rel=1e-7)         # x = t^2/2, y = t^3/3
    assert r["tau[2]"] == pytest.approx([0.0, 1.0, 2.0])


def test_public_ode_is_sx_for_a_model_solved_numerically():
    """models/andrews.mech was an MX Function (numeric QR solve), which broke SX glue;
    Model.casadi() now gives SX.  Andrews' squeezer is constrained: its public ode is the
    problem's index-1 ODE (issue 22), an SX Function through the Cholesky + Schur route, equal
    to the numeric sparse QR of the same augmented system (the route above SCHUR_MAX_N)."""
    from mechdsl.dae.constrained_system import ConstrainedSystem

    m = mechdsl.load(str(MODELS / "andrews.mech"))
    fs = m.casadi()
    ode = fs["ode"]
    assert ode.class_name() == "SXFunction"
    system = fs.system()
    numeric = ConstrainedSystem._build(system.eom, system.p, system.active, "mx")
    assert numeric.fn["accel"].class_name() == "MXFunction"
    rng = np.random.default_rng(7)
    p = m.parameter_vector()
    n = m.eom.n
    for _ in range(5):
        x = rng.uniform(-1, 1, 2 * n)
        a = np.array(ode(0.0, x, [], p)).ravel()
        b = np.array(numeric.fn["accel"](x[:n], x[n:], 0.0, p, 0, 0)[0]).ravel()
        np.testing.assert_allclose(a[n:], b, rtol=1e-9, atol=1e-9 * np.abs(b).max())
        np.testing.assert_array_equal(a[:n], x[n:])
    xs = ca.SX.sym("x", 2 * n)                             # SX glue: substitute into an SX graph
    assert ode(0, xs, ca.SX(0, 1), ca.DM(p)).shape == (2 * n, 1)


def test_an_output_may_use_an_input():
    src = SLIDER.replace("equation", '  output Real push(unit = "N") = F + G;\nequation')
    m = mechdsl.loads(src, model="Slider")
    r = m.simulate(1.0, inputs={"F": lambda t: 2.0 * t}, points=3)
    assert r["push"] == pytest.approx([1.5, 2.5, 3.5])
    assert r["push"] == pytest.approx(r["F"] + r["G"])


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
def test_hamilton_equations_of_a_model_with_an_input(capsys):
    """The cart-pole's force F is an input: Hamilton's equations show it as the generalized
    force on the cart, dp_x/dt = F (exactly: x is cyclic in T and V) - was an internal error."""
    from conftest import MODELS
    from mechdsl.cli import main

    assert main(["equations", "--hamiltonian", str(MODELS / "cart_pole.mech")]) == 0
    out = capsys.readouterr().out
    assert any(" ".join(ln.split()) == "der(p_x) = F" for ln in out.splitlines())
