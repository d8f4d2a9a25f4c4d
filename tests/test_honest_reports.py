"""Issue 23, part 4: the smaller silent wrong answers, each against what it should say."""
import math
import warnings

import numpy as np
import pytest

import mechdsl
from conftest import MODELS

STIFF = """
model Stiff "a Cartesian pendulum beside a stiff spring on another coordinate"
  parameter Real m(unit = "kg") = 1;
  parameter Real L(unit = "m") = 1.6454;
  parameter Real k(unit = "N/m") = 1e12;
  Gravity gravity(g = {0, -9.81, 0});
  PointMass bob(m = m, r(start = {0.3, -1.6}));
  coordinate Real s(start = 0.001, unit = "m");
equation
  kinetic = 1/2*m*der(s)^2;
  potential = 1/2*k*s^2;
  bob.x^2 + bob.y^2 = L^2 "rod";
end Stiff;
"""


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
def test_a_positive_eigenvalue_beside_a_stiff_spring_is_not_zero():
    """The constrained equilibrium at the bottom has the reduced Hessian eigenvalue m g / L = 5.962
    (and k along s): stable.  Before, a tolerance of 1e-9 x max|K| (1e12) called 5.962 a zero
    eigenvalue ("undetermined"), and one force scale for all coordinates accepted a dozen points
    along the circle, where gravity still pulls with up to 9.81 N, as equilibria."""
    eqs = mechdsl.loads(STIFF).equilibria()
    assert len(eqs) == 1
    (e,) = eqs
    assert e.q == pytest.approx([0.0, -1.6454, 0.0], abs=1e-12)
    assert e.stable is True and "positive definite" in e.reason
    assert e.hessian_eigenvalues == pytest.approx([9.81 / 1.6454, 1e12], rel=1e-9)


WALL = """
model PendulumBesideWall "a pendulum beside a wall at x = wall"
  parameter Real wall(unit = "m") = 0.5;
  Gravity gravity(g = {0, -9.81, 0});
  PointMass bob(m = 1);
  Point top(body = bob, r = {0, 1, 0});
  Revolute hinge(parent = world, child = top, axis = {0, 0, 1}, phi(start = 0.2));
  Contact stop(point = bob, surface = "plane", normal = {-1, 0, 0}, offset = -wall, e = 0.5);
end PendulumBesideWall;
"""


def test_equilibria_of_a_model_with_contacts_say_so(tmp_path, capsys):
    """The contacts are not equilibrium conditions; `mech equilibrium` says so and checks every
    equilibrium against them (before: not a word)."""
    from mechdsl.cli import main

    m = mechdsl.loads(WALL)
    eqs = m.equilibria()
    assert [round(float(e.q[0]), 9) for e in eqs] == [0.0, round(math.pi, 9)]
    assert all(e.admissible for e in eqs)
    assert any("stop are unilateral" in n for n in eqs.notes)
    behind = m.with_params(wall=-0.2).equilibria()       # the wall stands where the pendulum hangs
    assert not any(e.admissible for e in behind)
    assert all(any("penetrates contact 'stop' (gap -0.2 m)" in n for n in e.notes) for e in behind)
    path = tmp_path / "wall.mech"
    path.write_text(WALL)
    assert main(["equilibrium", str(path), "--set", "wall=-0.2"]) == 0
    out = capsys.readouterr().out
    assert "penetrates contact 'stop'" in out and "not searched" in out


BALL = """
model Ball
  Gravity gravity(g = {0, -9.81, 0});
  PointMass ball(m = 1, r(start = {0, -0.05}));
  Contact floor(point = ball, radius = 0.1, surface = "plane", normal = {0, 1, 0}, offset = 0, e = 0.8);
end Ball;
"""


def test_check_refuses_a_start_that_penetrates_a_contact(tmp_path, capsys):
    """mech check used to say ok for a start that simulate then refused (E861): both refuse it now,
    with the same located error."""
    from mechdsl.cli import main

    path = tmp_path / "ball.mech"
    path.write_text(BALL)
    assert main(["check", str(path)]) == 1
    err = capsys.readouterr().err
    assert "ball.mech:5:3: error[E861]: the start state penetrates contact 'floor' (gap -0.15 m)" in err
    assert main(["simulate", str(path), "--t-end", "1", "--no-progress"]) == 1
    assert "error[E861]" in capsys.readouterr().err
    path.write_text(BALL.replace("{0, -0.05}", "{0, 0.5}"))
    assert main(["check", str(path)]) == 0


# the same contract on a larger model (its symbolic simplification takes seconds): slow set
@pytest.mark.parametrize("file,model", [("pendulum_cartesian.mech", "PendulumCartesian"),
                                        pytest.param("four_bar.mech", "FourBar", marks=pytest.mark.slow)])
def test_equations_print_each_multipliers_terms(file, model, capsys):
    """`mech equations` on a constrained model printed the placeholder -(G^T lambda)[q]; now each
    equation carries -sum_c dg_c/dq_i lambda[c], checked against the derived G at random states."""
    import casadi as ca
    import sympy as sp

    from mechdsl.cli import main
    from mechdsl.mechanics.printing import lagrange_equations, multiplier_terms

    assert main(["equations", str(MODELS / file), "--model", model]) == 0
    out = capsys.readouterr().out
    assert "G^T lambda" not in out and "lambda[" in out
    if model == "PendulumCartesian":                   # each constraint says its multiplier's unit
        assert "(lambda[rod] in N/m)" in out             # g = x^2 + y^2 - L^2, in m2
    m = mechdsl.load(MODELS / file, model=model)
    sm = lagrange_equations(m.model)[0]
    terms, names = multiplier_terms(m.model, sm)
    eom = m.eom
    qs = list(sm.coords)
    from mechdsl.mechanics.symbolic import _Builder

    b = _Builder(m.model)
    lam_syms = [sp.Symbol(f"lambda[{c}]") for c in eom.constraint_names]
    f = sp.lambdify([qs, [b.p[p] for p in eom.params], lam_syms], terms, "numpy")
    G = ca.Function("G", [eom.q, eom.p], [ca.jacobian(eom.g, eom.q)])
    rng = np.random.default_rng(5)
    for _ in range(5):
        q, lam = rng.normal(size=eom.n), rng.normal(size=eom.m)
        want = -np.array(G(q, eom.param_values)).T @ lam
        got = np.array(f(q, eom.param_values, lam), float).ravel()
        np.testing.assert_allclose(got, want, rtol=1e-10, atol=1e-12)


def test_equations_in_python_carry_the_multipliers_and_write_dots():
    """m.equations() left the constraint forces out and wrote d/dt x(t) where `mech equations
    --latex` writes dots: both notations now, dots by default."""
    eqs = mechdsl.load(MODELS / "pendulum_cartesian.mech", model="PendulumCartesian").equations()
    assert "lambda[rod]" in str(eqs[0].rhs) and eqs.multipliers
    tex = eqs.latex()
    assert r"\ddot{x}_{plane}" in tex and r"\lambda_{\mathrm{rod}}" in tex and r"\frac{d" not in tex
    assert r"\frac{d^{2}}{d t^{2}}" in eqs.latex(dots=False)
    assert eqs._repr_latex_() == "$$" + tex + "$$"


def test_e751_is_located_at_the_output(tmp_path, capsys):
    from mechdsl.cli import main

    path = tmp_path / "held.mech"
    path.write_text("""model Held
  Gravity gravity(g = {0, -9.81, 0});
  Rod rod(m = 1, L = 1, axis = {0, -1, 0});
  Revolute hinge(parent = world, child = rod.a, axis = {0, 0, 1}, phi(start = 0.3));
  output Real F[3] = reaction_force(hinge);
equation
  rod.b.x = 0.2 "hold";
end Held;
""")
    for cmd in (["check", str(path)], ["simulate", str(path), "--t-end", "1", "--no-progress"]):
        assert main(cmd) == 1
        err = capsys.readouterr().err
        assert f"{path}:5:15: error[E751]" in err and "constraint_force(c, body)" in err and "<input>" not in err


KEPLER2 = """
model Orbit "a body around a fixed centre, Cartesian x, y"
  parameter Real mu(unit = "J.m") = 1;
  PointMass bob(m = 1, r(start = {1, 0}), v(start = {0, 1.1}));
  Potential centre(V = -mu*1/sqrt(bob.x^2 + bob.y^2));
end Orbit;
"""


def test_automatic_names_read_as_csv_and_integrals_print_in_the_models_names(tmp_path):
    """The angular momentum was named L_(bob.x,bob.y): a comma in a CSV header that ordinary
    readers (split on ',') take apart; its repr showed CasADi's p_0*qd_1*q_0."""
    import csv

    m = mechdsl.loads(KEPLER2)
    fis = {f.name: f for f in m.first_integrals()}
    assert "L_(bob.x:bob.y)" in fis
    text = repr(fis["L_(bob.x:bob.y)"])
    assert "bob.x" in text and "der(bob.y)" in text and "qd_" not in text and "p_0" not in text
    r = m.simulate(1.0, points=5)
    path = tmp_path / "orbit.csv"
    r.to_csv(path)
    header = path.read_text().splitlines()[0]
    assert header.split(",") == r.columns and all("," not in c for c in r.columns)
    with open(path, newline="") as fh:
        assert next(csv.reader(fh)) == r.columns
    L = r["L_(bob.x:bob.y)"]
    assert L == pytest.approx(np.full(5, 1.1), rel=1e-8)               # x v_y - y v_x at the start
    assert np.array_equal(r["L_(bob.x,bob.y)"], L)                     # the old name still reads


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
def test_projection_runs_are_not_told_to_use_projection():
    """The energy warning advised `formulation = "projection"` to a run that already used it."""
    m = mechdsl.load(MODELS / "pendulum_cartesian.mech", model="PendulumCartesian")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        r = m.simulate(100.0, rtol=1e-4, atol=1e-6, points=101)
        b = m.simulate(100.0, rtol=1e-4, atol=1e-6, points=101, formulation="baumgarte")
    assert r.metadata["run"]["formulation"] == "projection"
    assert r.stats["energy_ok"] is False                    # the case: its energy drifts beyond the limit
    said = " ".join(r.metadata["warnings"] + [r.metadata.get("energy_warning", "")])
    assert "energy" in said and "projection" not in said
    assert 'use formulation = "projection"' in b.metadata.get("energy_warning", "") + " ".join(b.metadata["warnings"])


def test_the_energy_warning_of_an_ode_run_is_printed_once(capsys):
    """It was printed twice: the energy is both an invariant and a first integral."""
    from mechdsl.cli import main

    assert main(["simulate", str(MODELS / "pendulum.mech"), "--model", "Pendulum", "--t-end", "2000",
                 "--rtol", "1e-5", "--no-progress"]) == 0
    out = capsys.readouterr().out
    assert out.count("energy should stay constant") == 1
    assert sum(line.startswith("warning:") for line in out.splitlines()) == 1


def test_docs_and_code_give_the_same_warning_thresholds():
    """The docs said 1000 rtol (ODE) and min(0.05, max(1e-6, 1e4 rtol)) (DAE), the code did a
    third thing; one rule now, stated where the code reads it."""
    from conftest import CHECKOUT as ROOT
    from mechdsl.simulation.accuracy import DRIFT_CAP, DRIFT_FACTOR, drift_limit
    from mechdsl.simulation.backends import dae
    from mechdsl.simulation.estimate import WARN_FACTOR

    rule = f"min({DRIFT_CAP:g}, {DRIFT_FACTOR:g} rtol)"
    assert drift_limit(1e-8) == pytest.approx(DRIFT_FACTOR * 1e-8) and drift_limit(1.0) == DRIFT_CAP
    assert dae.drift_limit is drift_limit                     # the DAE energy check reads the same
    for doc in ("docs/simulate.md", "docs/constraints.md", "docs/analysis.md", "docs/internals/dae.md",
                "docs/internals/simulation.md"):
        text = (ROOT / doc).read_text()
        assert rule in text, doc
        for history in ("was min(0.05, max(1e-6, 1e4 rtol)) here and 1000 rtol elsewhere",
                         "the ODE rule was 1000 rtol and the DAE one min(0.05, max(1e-6, 1e4 rtol))"):
            text = text.replace(history, "")         # what the rule was before, said as such
        old = text
        assert "1000 rtol" not in old and "1000 times `rtol`" not in old and "max(1e-6, 1e4 rtol)" not in old, doc
    sim = (ROOT / "docs/simulate.md").read_text()
    assert f"{WARN_FACTOR:g} times the tolerance class" in sim
