"""Issue 17: constraint multipliers are named after the constraint's description.  Issue 23: they
are reported unscaled (the lambda of M q'' = f - G' lambda), in J / [g]; the force at the point is
constraint_force(rod, bob), the same whatever the scale of g."""
import numpy as np
import pytest

import mechdsl

SRC = """
model Pend "a point mass on a rod, Cartesian coordinates"
  parameter Real m(unit = "kg") = 1.7;
  parameter Real L(unit = "m") = 1.3;
  parameter Real g(unit = "m/s2") = 9.81;
  Gravity gravity(g = {0, -g, 0});
  PointMass bob(m = m);
  Planar plane(parent = world, child = bob, axis = {0, 0, 1},
               x(start = 0.6*L, speed = 0.72), y(start = -0.8*L, speed = 0.54));  // |v| = 0.9
  output Real F[3] = constraint_force(rod, bob);
equation
  ROD "rod";
end Pend;
"""
FORMS = {"squared": "bob.x^2 + bob.y^2 = L^2", "scaled": "3*bob.x^2 + 3*bob.y^2 = 3*L^2",
         "root": "sqrt(bob.x^2 + bob.y^2) = L"}
# lambda = T / |dg/dr| (dg/dr = 2 r, 6 r, r/|r|) and its unit J / [g]
SCALE = {"squared": (2 * 1.3, "N/m"), "scaled": (6 * 1.3, "N/m"), "root": (1.0, "N")}


def _model(form):
    return mechdsl.loads(SRC.replace("ROD", FORMS[form]), filename="pend.mech")


@pytest.mark.parametrize("form", list(FORMS))
def test_rod_tension_closed_form(form):
    """T = m (g cos th + L thd^2) with cos th = -y/L and L thd^2 = |v|^2 / L, along a swing."""
    r = _model(form).simulate(2.0, points=41, reactions=True, rtol=1e-10, atol=1e-10)
    assert r.success
    m, L, g = 1.7, 1.3, 9.81
    x, y, vx, vy = (r[k] for k in ("plane.x", "plane.y", "der(plane.x)", "der(plane.y)"))
    tension = m * (g * (-y / L) + (vx**2 + vy**2) / L)
    assert np.max(np.abs(tension)) > 10.0             # a real load, not a trivially small one
    scale, unit = SCALE[form]
    assert r["lambda[rod]"] == pytest.approx(tension / scale, rel=1e-6, abs=1e-6)
    assert r.metadata["units"]["lambda[rod]"] == unit
    # the force on the bob: the tension along the rod, towards the pivot, however g is scaled
    assert r["F[1]"] == pytest.approx(-tension * x / L, rel=1e-6, abs=1e-6)
    assert r["F[2]"] == pytest.approx(-tension * y / L, rel=1e-6, abs=1e-6)


def test_old_name_is_an_alias_in_outputs():
    r = _model("squared").simulate(0.5, points=6, outputs=["lambda[c1]"])
    assert "lambda[rod]" in r.signals
    assert r["lambda[rod]"][0] == pytest.approx(1.7 * (9.81 * 0.8 + 0.9**2 / 1.3) / (2 * 1.3), rel=1e-6)


def test_names_from_descriptions_loops_and_fallback():
    src = """
model Three
  coordinate Real x[3](start = {1, 1, 1});
equation
  kinetic = 1/2*(der(x[1])^2 + der(x[2])^2 + der(x[3])^2);
  for i in 1:2 loop
    x[i] = x[i + 1] "tie rod";
  end for;
  x[1] + x[2] + x[3] = 3;
end Three;
"""
    m = mechdsl.loads(src, filename="three.mech")
    assert [c.name for c in m.model.constraints] == ["tie_rod_1", "tie_rod_2", "c3"]
    assert [c.alias for c in m.model.constraints] == ["c1", "c2", "c3"]


def test_old_names_still_read_from_results():
    r = _model("squared").simulate(0.5, points=6, reactions=True)
    assert "lambda[c1]" in r and "residual(c1)" in r
    assert np.array_equal(r["lambda[c1]"], r["lambda[rod]"])
    assert np.array_equal(r["residual(c1)"], r["residual(rod)"])
    assert r.metadata["aliases"]["lambda[c1]"] == "lambda[rod]"
