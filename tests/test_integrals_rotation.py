"""Issue 17: Noether for rotations of Cartesian coordinates -- the angular momentum of a model
written in x, y (Kepler) is found as a first integral, and no rotation is claimed when the
potential, a force or a constraint breaks the symmetry."""
import numpy as np
import pytest

import mechdsl
from mechdsl.analysis.integrals import first_integrals

from conftest import MODELS


def _model(kinetic, potential, coords, extra=""):
    decl = "\n".join(f"  coordinate Real {c}(start = {0.3 + 0.2 * i}, speed = {0.5 - 0.3 * i});"
                     for i, c in enumerate(coords))
    return mechdsl.loads(f"""
model M
  parameter Real k = 2;
  parameter Real mu = 1.5;
  parameter Real m = 0.7;
  parameter Real g = 9.81;
{decl}
equation
  kinetic = {kinetic};
  potential = {potential};
{extra}
end M;
""", filename="m.mech")


T2 = "1/2*m*(der(x)^2 + der(y)^2)"
T3 = "1/2*m*(der(x)^2 + der(y)^2 + der(z)^2)"


def _names(model):
    return [fi.name for fi in first_integrals(model.eom)]


def _value(fi, eom, q, qd):
    import casadi as ca

    f = ca.Function("f", [eom.q, eom.qd, eom.t, eom.p], [fi.sx])
    return float(f(q, qd, 0.0, eom.param_values))


def test_kepler_in_xy_has_the_angular_momentum():
    model = _model(T2, "-mu*m/sqrt(x^2 + y^2)", ["x", "y"])
    fis = {fi.name: fi for fi in first_integrals(model.eom)}
    assert list(fis) == ["L_(x:y)", "energy"]
    L = fis["L_(x:y)"]
    assert L.kind == "angular_momentum" and L.rotation == pytest.approx({"x,y": 1.0}, abs=1e-12)
    rng = np.random.default_rng(3)
    for _ in range(5):                       # p . A q = m (x y' - y x'), the closed form
        q, qd = rng.normal(size=2), rng.normal(size=2)
        assert _value(L, model.eom, q, qd) == pytest.approx(0.7 * (q[0] * qd[1] - q[1] * qd[0]), rel=1e-12)
    # conserved along a simulated orbit (the simulator records every first integral)
    r = model.simulate(5.0, points=51, rtol=1e-10, atol=1e-12)
    Lz = 0.7 * (r["x"] * r["der(y)"] - r["y"] * r["der(x)"])
    assert np.ptp(Lz) < 1e-8 and abs(Lz[0]) > 0.1
    assert r["L_(x:y)"] == pytest.approx(Lz, abs=1e-12)
    assert r["L_(x,y)"] is not None          # the name before issue 23 still reads


@pytest.mark.parametrize("potential", [
    "1/2*k*(x^2 + 2*y^2)",                   # anisotropic oscillator
    "-mu*m/sqrt((x - 1)^2 + y^2)",          # attraction towards a point off the origin
    "m*g*y",                                 # uniform gravity
])
def test_no_rotation_when_the_potential_breaks_it(potential):
    assert not [n for n in _names(_model(T2, potential, ["x", "y"])) if n.startswith("L_")]


def test_no_rotation_when_the_masses_differ_or_a_force_acts():
    assert _names(_model("1/2*m*der(x)^2 + m*der(y)^2", "1/2*k*(x^2 + y^2)", ["x", "y"])) == ["energy"]
    forced = _model(T2, "1/2*k*(x^2 + y^2)", ["x", "y"], "  force(x) = k*y;")
    assert not [n for n in _names(forced) if n.startswith("L_")]


def test_axis_in_3d():
    """Axisymmetric field (gravity along z plus a radial spring): only the rotation about z;
    an isotropic field: all three components."""
    assert [n for n in _names(_model(T3, "m*g*z + 1/2*k*(x^2 + y^2)", ["x", "y", "z"])) if n.startswith("L_")] \
        == ["L_(x:y)"]
    assert [n for n in _names(_model(T3, "1/2*k*(x^2 + y^2 + z^2)", ["x", "y", "z"])) if n.startswith("L_")] \
        == ["L_(x:y)", "L_(x:z)", "L_(y:z)"]


def test_spherical_pendulum_in_cartesian_coordinates():
    """The rod x^2 + y^2 + z^2 = L^2 is invariant under every rotation, gravity only under the
    one about the vertical: L_z alone."""
    model = _model(T3, "m*g*z", ["x", "y", "z"], '  x^2 + y^2 + z^2 = 1 "rod";')
    assert [n for n in _names(model) if n.startswith("L_")] == ["L_(x:y)"]


def test_two_body_problem_total_angular_momentum():
    names = _names(mechdsl.load(MODELS / "kepler.mech", model="Kepler"))
    assert [n for n in names if n.startswith("L_")] == ["L_(fs.x:fs.y+fp.x:fp.y)", "L_(fs.x:fs.z+fp.x:fp.z)",
                                                        "L_(fs.y:fs.z+fp.y:fp.z)"]
