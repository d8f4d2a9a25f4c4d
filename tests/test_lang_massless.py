"""Issue 17: massless links and Cartesian point masses. A joint without a child is a massless
frame others attach to (a Prismatic on a Revolute: polar coordinates), `RigidLink` holds a body
at a fixed offset from a frame (a pendulum without an invented point), and a PointMass with
`r(start = ..)`/`v(start = ..)` has Cartesian coordinates named after it (no Free or Planar
joint). Each against its closed-form Lagrangian."""
from __future__ import annotations

import numpy as np
import pytest
from scipy.integrate import solve_ivp

import mechdsl
from mechdsl.diagnostics import MechError
from reach_util import accelerations

G = 9.81

POLAR = """
model Polar "a particle in polar coordinates: a slider on a turning massless arm"
  parameter Real m(unit = "kg") = 2;
  Gravity g(g = {0, -9.81, 0});
  PointMass bob(m = m);
  Revolute turn(parent = world, phi(start = 0.3, speed = 1));
  Prismatic slide(parent = turn, child = bob, axis = {1, 0, 0}, s(start = 1, speed = 0.3));
end Polar;
"""


def test_polar_particle_matches_its_lagrangian():
    """L = m/2 (s'^2 + s^2 phi'^2) - m g s sin(phi):
    s'' = s phi'^2 - g sin(phi), phi'' = -(2 s' phi' + g cos(phi)) / s."""
    m = mechdsl.loads(POLAR)
    assert m.coordinates == ("turn.phi", "slide.s")
    acc = accelerations(m.eom)
    rng = np.random.default_rng(5)
    for _ in range(4):
        phi, s = rng.uniform(-3, 3), rng.uniform(0.2, 2)
        dphi, ds = rng.uniform(-2, 2, 2)
        expect = [-(2 * ds * dphi + G * np.cos(phi)) / s, s * dphi**2 - G * np.sin(phi)]
        assert acc([phi, s], [dphi, ds]) == pytest.approx(expect, rel=1e-10, abs=1e-10)


PEND = """
model Pend "a point mass at distance L on a hinge, held by a massless rigid link"
  parameter Real L(unit = "m") = 1.7;
  Gravity g(g = {0, -9.81, 0});
  PointMass bob(m = 3);
  Revolute hinge(parent = world, phi(start = 0.5));
  RigidLink rod(a = hinge, b = bob, r = {0, -L, 0});
  output Real y(unit = "m") = bob.y;
end Pend;
"""


def test_pendulum_on_a_rigid_link_matches_its_lagrangian():
    m = mechdsl.loads(PEND)
    assert m.coordinates == ("hinge.phi",)
    acc = accelerations(m.eom)
    for phi, dphi in [(0.5, 0.0), (2.0, -1.0), (-1.2, 3.0)]:
        assert acc([phi], [dphi]) == pytest.approx([-G / 1.7 * np.sin(phi)], rel=1e-12)


CART = """
model CartPend "the pendulum in Cartesian coordinates: a point mass with x, y and the rod's constraint"
  parameter Real L(unit = "m") = 1.5;
  Gravity g(g = {0, -9.81, 0});
  PointMass bob(m = 1, r(start = {L*sin(0.8), -L*cos(0.8)}));
equation
  bob.x^2 + bob.y^2 = L^2 "rod";
end CartPend;
"""


def test_cartesian_pendulum_follows_the_pendulum_equation():
    m = mechdsl.loads(CART)
    assert m.coordinates == ("bob.x", "bob.y")
    r = m.simulate(2.0, points=21, rtol=1e-10, atol=1e-12)
    assert r.success
    ref = solve_ivp(lambda t, y: [y[1], -G / 1.5 * np.sin(y[0])], (0, 2.0), [0.8, 0.0], t_eval=r.t,
                    rtol=1e-12, atol=1e-12)
    th = np.arctan2(r.q[:, 0], -r.q[:, 1])
    assert th == pytest.approx(ref.y[0], abs=1e-6)


KEPLER = """
model TwoBody "two point masses with Cartesian coordinates named after them"
  parameter Real M(unit = "kg") = 1000;
  parameter Real m(unit = "kg") = 1;
  parameter Real a(unit = "m") = 10;
  parameter Real Gc(unit = "m3.kg-1.s-2") = 1;
  PointMass sun(m = M, r(start = {0, 0, 0}));
  PointMass planet(m = m, r(start = {a, 0, 0}), v(start = {0, sqrt(Gc*(M + m)/a), 0}));
  Gravitation grav(bodies = {sun, planet}, G = Gc);
  output Real d(unit = "m") = norm(planet.r - sun.r);
end TwoBody;
"""


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
def test_two_body_circular_orbit_from_vector_starts():
    """Relative circular orbit: the distance stays a and the relative position returns after
    the period 2 pi sqrt(a^3 / (G (M + m)))."""
    m = mechdsl.loads(KEPLER)
    assert m.coordinates == ("sun.x", "sun.y", "sun.z", "planet.x", "planet.y", "planet.z")
    period = 2 * np.pi * np.sqrt(10.0**3 / 1001.0)
    r = m.simulate(period, points=51, rtol=1e-11, atol=1e-12)
    assert r.signals["d"] == pytest.approx(np.full(51, 10.0), rel=1e-7)
    rel_end = r.q[-1, 3:] - r.q[-1, :3]
    assert rel_end == pytest.approx([10.0, 0.0, 0.0], abs=1e-5)


def test_free_joint_names_are_kept():
    text = """
model F
  PointMass jupiter(m = 1);
  Free f_jupiter(child = jupiter, r(start = {5, 0, 0}), v(start = {0, 2, 0}));
end F;
"""
    m = mechdsl.loads(text)
    assert m.coordinates == ("f_jupiter.x", "f_jupiter.y", "f_jupiter.z")


@pytest.mark.parametrize("text, code", [
    ("model B\n  PointMass bob(m = 1);\n  Revolute hinge(parent = world);\nend B;\n", "E210"),
    ("model B\n  PointMass bob(m = 1);\n  Revolute h(parent = world, child = bob);\n"
     "  Prismatic s(parent = h, child = bob);\nend B;\n", "E209"),
    ("model B\n  PointMass bob(m = 1, r(start = {1, 2}), v(start = {0, 0, 1}));\nend B;\n", "E301"),
    ("model B\n  PointMass bob(m = 1, r = {1, 2});\nend B;\n", "E220"),
    # an attribute a RigidLink does not have (it has no child field: was an internal AssertionError)
    (PEND.replace("bob.y;", "rod.x;"), "E219"),
    (PEND.replace("bob.y;", "rod.phi;"), "E219"),
])
def test_massless_and_cartesian_errors(text, code):
    with pytest.raises(MechError) as err:
        mechdsl.loads(text)
    assert code in str(err.value)


def test_cartesian_coordinates_take_element_overrides(tmp_path):
    """bob.x.start from a scene, with_params or --set wins over r's entry; z is refused in the plane."""
    m = mechdsl.loads(CART)
    starts = {c.name: (c.start, c.speed) for c in m.with_params(**{"bob.y.speed": 0.5}).model.coordinates}
    assert starts["bob.y"][1].value == 0.5 and starts["bob.x"][1].value == 0.0
    moved = m.with_params(**{"bob.x.start": 1.5, "bob.y.start": 0.0})
    assert [c.start.value for c in moved.model.coordinates] == [1.5, 0.0]
    with pytest.raises(MechError) as err:
        m.with_params(**{"bob.z.start": 1.0})
    assert "E204" in str(err.value)
    scene = CART + "scene S\n  model CartPend(bob(x(start = 1.5), y(start = 0)));\n  stop_time = 0.1;\nend S;\n"
    assert [c.start.value for c in mechdsl.loads(scene, scene="S").model.coordinates] == [1.5, 0.0]


def test_joint_variables_win_over_frame_attributes():
    """`f.x` of a Free or Planar joint is its variable, with or without a child; `turn.x` of a
    child-less Revolute is its frame's position."""
    text = """
model F
  PointMass jupiter(m = 1);
  Free f(child = jupiter, r(start = {5, 1, 0}));
  Body plate(m = 1, I = diagonal({1, 1, 2}));
  Planar pl(parent = world, child = plate, axis = {0, 0, 1}, x(start = 3));
  PointMass bob(m = 1);
  Prismatic p(parent = world, axis = {1, 0, 0}, s(start = 2));
  Revolute turn(parent = p, phi(start = 0.5));
  RigidLink arm(a = turn, b = bob, r = {1, 0, 0});
  output Real fx(unit = "m") = f.x;
  output Real px(unit = "m") = pl.x;
  output Real tx(unit = "m") = turn.x;
end F;
"""
    m = mechdsl.loads(text)
    outs = {o.name: o.expr for o in m.model.outputs}
    assert outs["fx"].name == "f.x" and outs["px"].name == "pl.x"
    from reach_util import output_values
    e = m.eom
    q = np.zeros(len(e.coords))
    q[e.coords.index("p.s")] = 2.0
    assert output_values(m, q, np.zeros(len(e.coords)), ["tx"])["tx"][0] == pytest.approx(2.0)
