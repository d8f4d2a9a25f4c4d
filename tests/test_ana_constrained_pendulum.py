"""The Cartesian pendulum (models/pendulum_cartesian.mech: x^2 + y^2 = L^2) and the same
pendulum with its constraint written twice (a redundant constraint), against closed forms:
equilibria at the bottom (stable) and the top (unstable), the rod force m g at rest, the
small-oscillation frequency sqrt(g/L) of the reduced linear model, and the frozen-time linear
model about a rest state off the equilibrium (theta'' = -(g/L) sin theta: w^2 = g cos(a)/L)."""
import json
import math

import numpy as np
import pytest

import mechdsl
from conftest import MODELS
from mechdsl.diagnostics import MechError

M_, L_, G_ = 3.0, 2.0, 9.81

TWICE = """
model PendulumTwice "the rod written twice: the second constraint is redundant"
  parameter Real m = 3;  parameter Real L = 2;  parameter Real g = 9.81;
  coordinate Real x(start = 0.5, fixed = false);
  coordinate Real y(start = -1.5, fixed = false);
equation
  kinetic = 1/2*m*(der(x)^2 + der(y)^2);
  potential = m*g*y;
  x^2 + y^2 = L^2 "rod";
  2*x^2 + 2*y^2 = 2*L^2 "rod again";
end PendulumTwice;
"""


@pytest.fixture(scope="module")
def pend():
    return mechdsl.load(MODELS / "pendulum_cartesian.mech", model="PendulumCartesian").with_params(m=M_, L=L_)


@pytest.fixture(scope="module")
def twice():
    return mechdsl.loads(TWICE)


def bottom_top(eqs, ix, iy):
    assert len(eqs) == 2
    bottom = min(eqs, key=lambda e: e.q[iy])
    top = max(eqs, key=lambda e: e.q[iy])
    assert bottom.q[ix] == pytest.approx(0, abs=1e-12) and bottom.q[iy] == pytest.approx(-L_, rel=1e-12)
    assert top.q[ix] == pytest.approx(0, abs=1e-12) and top.q[iy] == pytest.approx(L_, rel=1e-12)
    return bottom, top


def rod_force(model, e) -> np.ndarray:
    """G^T lambda: the force the rod exerts on the mass, in (x, y)."""
    import casadi as ca

    eom = model.eom
    G = np.array(ca.Function("G", [eom.q, eom.p], [ca.jacobian(eom.g, eom.q)])(e.q, eom.param_values))
    return -(G.T @ e.multipliers)        # M q'' = bias - G^T lambda


def test_equilibria_bottom_stable_top_unstable(pend):
    bottom, top = bottom_top(pend.equilibria(), 0, 1)
    assert bottom.stable is True and top.stable is False
    # the rod holds the weight: force (0, m g) on the mass at the bottom, (0, m g) pushing up at the top
    assert np.allclose(rod_force(pend, bottom), [0, M_ * G_], atol=1e-10)
    assert np.allclose(rod_force(pend, top), [0, M_ * G_], atol=1e-10)
    # the multiplier named after the description "rod" is reported as it is (issue 23): for
    # g = x^2 + y^2 - L^2 (G = 2 (x, y)) the rod tension m g over 2 L, in N/m; negative
    # (compression) at the top
    assert bottom.lambdas["rod"] == pytest.approx(M_ * G_ / (2 * L_), rel=1e-12)
    assert top.lambdas["rod"] == pytest.approx(-M_ * G_ / (2 * L_), rel=1e-12)
    assert bottom.lambda_units == {"rod": "N/m"}
    assert bottom.multipliers == pytest.approx([M_ * G_ / (2 * L_)], rel=1e-12)
    # reduced Hessian of V + lambda g on the tangent (unit vector along x): 2 lambda = +-m g / L
    assert bottom.hessian_eigenvalues == pytest.approx([M_ * G_ / L_], rel=1e-10)
    assert top.hessian_eigenvalues == pytest.approx([-M_ * G_ / L_], rel=1e-10)
    assert "lambda'g" in bottom.reason
    d = bottom.to_dict()
    assert d["multipliers"] == {"rod": pytest.approx(M_ * G_ / (2 * L_))}
    assert d["multiplier_units"] == {"rod": "N/m"}
    assert json.loads(json.dumps(d))["tangent_basis"] == [{"plane.x": 1.0, "plane.y": 0.0}]


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
def test_reduced_linear_model_frequency(pend):
    lin = pend.linearize()
    assert lin.kind == "equilibrium" and lin.constrained
    assert lin.reduced_coords == ("plane.x",)
    assert np.allclose(lin.basis, [[1.0], [0.0]])
    # x = L sin th: M_r = m, K_r = m g / L (all of it geometric stiffness: V = m g y is linear)
    assert lin.M == pytest.approx(np.array([[M_]]), rel=1e-12)
    assert lin.K == pytest.approx(np.array([[M_ * G_ / L_]]), rel=1e-10)
    assert lin.stiffness[0, 0] == pytest.approx(M_ * G_ / L_, rel=1e-10)     # 2 lambda
    md = lin.modes()
    assert md.frequencies == pytest.approx([math.sqrt(G_ / L_)], rel=1e-10)
    assert md.kinds == ("oscillatory",)
    assert np.allclose(md.shapes[:, 0], [1.0, 0.0])          # in (x, y)
    assert lin.A.shape == (2, 2)
    top = max(pend.equilibria(), key=lambda e: e.q[1])
    lt = pend.linearize(at=top)
    assert lt.modes().kinds == ("divergent",)
    assert lt.modes().frequencies == pytest.approx([math.sqrt(G_ / L_)], rel=1e-10)


@pytest.mark.parametrize("a", [0.4, -1.1])
def test_rest_state_off_equilibrium(pend, a):
    """Released at rest at angle a: the frozen-time linear model of th'' = -(g/L) sin th,
    expressed in the reduced coordinate (the mass-orthogonal correction maps tangent moves to
    angles linearly to second order: dth = |Z| dz / L)."""
    lin = pend.linearize(at={"plane.x": L_ * math.sin(a), "plane.y": -L_ * math.cos(a)})
    assert lin.kind == "state"
    c2 = float(lin.basis[:, 0] @ lin.basis[:, 0])
    assert lin.M[0, 0] == pytest.approx(M_ * c2, rel=1e-12)
    assert lin.K[0, 0] == pytest.approx(M_ * G_ * math.cos(a) / L_ * c2, rel=1e-9)
    assert lin.modes().frequencies[0] == pytest.approx(math.sqrt(G_ * math.cos(a) / L_), rel=1e-9)
    # reference acceleration: tangential, g sin a
    assert np.linalg.norm(lin.acceleration) == pytest.approx(G_ * abs(math.sin(a)), rel=1e-10)


def test_moving_states_are_refused(pend):
    with pytest.raises(MechError, match="E901.*at rest"):
        pend.linearize(at={"plane.x": 0.0, "plane.y": -L_, "der(plane.x)": 1.0})
    with pytest.raises(MechError, match="E901"):
        pend.linearize(at="t=1")
    with pytest.raises(MechError, match="E901.*symbolic"):
        pend.linearize().symbolic()


def test_redundant_constraint(twice):
    eqs = twice.equilibria()
    bottom, top = bottom_top(eqs, 0, 1)
    assert bottom.stable is True and top.stable is False
    assert bottom.active_constraints == ("rod",)
    assert bottom.lambdas["rod_again"] == 0.0                 # dropped: reported as 0
    assert bottom.lambdas["rod"] == pytest.approx(M_ * G_ / (2 * L_), rel=1e-12)
    assert np.allclose(rod_force(twice, bottom), [0, M_ * G_], atol=1e-10)
    assert any("redundant constraint(s) rod_again dropped" in n for n in bottom.notes)
    assert bottom.hessian_eigenvalues == pytest.approx([M_ * G_ / L_], rel=1e-10)
    lin = twice.linearize(at=bottom)
    assert lin.modes().frequencies == pytest.approx([math.sqrt(G_ / L_)], rel=1e-10)
    assert lin.K.shape == (1, 1)


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
def test_cli_prints_lambda(capsys):
    from mechdsl.cli import main

    assert main(["equilibrium", str(MODELS / "pendulum_cartesian.mech"), "--model", "PendulumCartesian",
                 "--set", "m=3,L=2"]) == 0
    out = capsys.readouterr().out
    assert "lambda[rod] [N/m]" in out and "7.3575" in out and "-7.3575" in out   # tension m g over 2 L
    assert "stable" in out and "unstable" in out
    assert main(["linearize", str(MODELS / "pendulum_cartesian.mech"), "--model", "PendulumCartesian",
                 "--set", "L=2"]) == 0
    out = capsys.readouterr().out
    assert "lambda[rod] = 2.4525 N/m" in out                                # m g / (2 L), m = 1
    assert f"{math.sqrt(G_ / L_):.6g}" in out                                   # 2.21472 rad/s
    assert main(["linearize", str(MODELS / "pendulum_cartesian.mech"), "--model", "PendulumCartesian",
                 "--at", "t=1"]) == 1
    err = capsys.readouterr().err
    assert "E901" in err and "Traceback" not in err


def _eom(name, coords, V, g, q0, q, qd):
    import casadi as ca

    from mechdsl import eom as E

    t, p = ca.SX.sym("t"), ca.SX.sym("p", 0)
    return E.from_lagrangian(name, coords, [], [], q, qd, t, p, 0.5 * ca.dot(qd, qd), V, g=g, q0=q0)


def test_no_degree_of_freedom_and_moving_constraints():
    """A mass on the unit circle with x held at 0.6 by a second constraint: statics give
    G' lambda = (0, -m g) with G = [[2x, 2y], [1, 0]] at (0.6, -0.8)."""
    import casadi as ca

    from mechdsl.analysis.equilibrium import equilibria
    from mechdsl.analysis.linearize import linearize

    q, qd = ca.SX.sym("q", 2), ca.SX.sym("qd", 2)
    e = _eom("Held", ["x", "y"], 9.81 * q[1], ca.vertcat(ca.dot(q, q) - 1, q[0] - 0.6), [0.6, -0.8], q, qd)
    (eq,) = equilibria(e)
    assert eq.q == pytest.approx([0.6, -0.8])
    lam1 = 9.81 / 1.6
    assert eq.multipliers == pytest.approx([lam1, -1.2 * lam1], rel=1e-12)
    # reported as they are (issue 23); a hand-built EOM has no units to say
    assert eq.lambdas == {"g1": pytest.approx(lam1, rel=1e-12), "g2": pytest.approx(-1.2 * lam1, rel=1e-12)}
    assert eq.lambda_units == {"g1": None, "g2": None}
    assert eq.stable is None and "no degree of freedom" in eq.reason
    lin = linearize(e)
    assert lin.M.shape == (0, 0) and len(lin.modes()) == 0
    t = ca.SX.sym("t")
    moving = _eom("Breathing", ["x", "y"], 9.81 * q[1], ca.dot(q, q) - (1 + 0.1 * ca.sin(t)), [0.6, -0.8], q, qd)
    moving = moving.replace(g=ca.substitute(moving.g, t, moving.t))
    with pytest.raises(MechError, match="E901.*depend on time"):
        equilibria(moving)


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
def test_free_dumbbell_falls_with_g():
    """Two unit masses joined by a rigid rod of length 1, free in the vertical plane: the
    translations are symmetry directions of the constrained equations, the reference motion
    falls with g, the rod carries no force, the orientation is neutral (zero eigenvalue)."""
    import casadi as ca

    from mechdsl.analysis.equilibrium import equilibria

    q, qd = ca.SX.sym("q", 4), ca.SX.sym("qd", 4)
    e = _eom("Dumbbell", ["x1", "y1", "x2", "y2"], 9.81 * (q[1] + q[3]),
             (q[0] - q[2]) ** 2 + (q[1] - q[3]) ** 2 - 1, [0, 0, 1, 0], q, qd)
    eqs = equilibria(e, max_guesses=8)
    assert eqs
    for eq in eqs:
        assert eq.kind == "accelerated-reference"
        assert eq.acceleration == pytest.approx([0, -9.81, 0, -9.81], abs=1e-9)
        assert eq.lambdas["g1"] == pytest.approx(0.0, abs=1e-9)
        assert (eq.q[0] - eq.q[2]) ** 2 + (eq.q[1] - eq.q[3]) ** 2 == pytest.approx(1.0, abs=1e-12)
        assert eq.stable is None and "zero eigenvalue" in eq.reason
