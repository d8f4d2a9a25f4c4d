"""Forces, energies and the equation layer against hand derivations; the bead on a spinning
hoop against its analytic equation of motion."""
from __future__ import annotations

import dataclasses

import casadi as ca
import numpy as np
import pytest

from mech_models import coord_var, fn, point, rod_body, rot_z_expr, v3
from mechdsl.model import ir
from mechdsl.model.exprs import const, mul, neg
from mechdsl.mechanics import derive

Z, O = ir.ZERO, ir.ONE
P = ir.Param


def qdd_fn(e):
    if e.qdd is not None:
        return ca.Function("f", [e.q, e.qd, e.t, e.p], [e.qdd])
    mb = ca.Function("mb", [e.q, e.qd, e.t, e.p], [e.M, e.bias])

    class F:
        def __call__(self, q, qd, t, p):
            M, b = mb(q, qd, t, p)
            return np.linalg.solve(np.array(M), np.array(b).ravel())

    return F()


def val(f, *a):
    return np.array(f(*a), float).ravel()


# --------------------------------------------------------------------------- bead on a hoop

def hoop_model(how: str):
    """Hoop of radius R spinning at rate w about the vertical y axis; a bead (point mass)
    slides on it, theta measured from the bottom.  how: 'revolute' (prescribed angle) or
    'frame' (a moving frame)."""
    params = (ir.Parameter("R", 0.7), ir.Parameter("w", 5.0), ir.Parameter("g", 9.81), ir.Parameter("m", 0.2))
    spin = mul(P("w"), ir.Time())
    bodies = [ir.Body("H", "frame"), ir.Body("bead", "point", mass=P("m"))]
    points = [point("world", "world"), point("H", "H"), point("bead", "bead"),
              ir.Point("bead.r", "bead", (Z, P("R"), Z))]
    if how == "revolute":
        jh = ir.Joint("spin", "revolute", "world", "H", "world", "H", axis=v3(0, 1, 0),
                      variables=(ir.JointVar("phi", spin),))
    else:
        c, s = fn("cos", spin), fn("sin", spin)
        Ry = ((c, Z, s), (Z, O, Z), (neg(s), Z, c))
        jh = ir.Joint("spin", "frame", "world", "H", "world", "H", frame_R=Ry, frame_r=(Z, Z, Z))
    jb = ir.Joint("slide", "revolute", "H", "bead.r", "H", "bead", axis=v3(0, 0, 1),
                  variables=(coord_var("phi", "theta"),))
    return ir.Model("Hoop", parameters=params, coordinates=(ir.Coordinate("theta", start=const(0.5)),),
                    bodies=tuple(bodies), points=tuple(points), joints=(jh, jb),
                    forces=(ir.Gravity("gravity", (Z, neg(P("g")), Z)),),
                    outputs=(ir.Output("y", ir.PointPos("bead", 1)),))


@pytest.mark.parametrize("how", ["revolute", "frame"])
@pytest.mark.parametrize("route", ["auto", "lagrange"])
def test_bead_on_spinning_hoop(how, route):
    e = derive(hoop_model(how), route=route)
    f = qdd_fn(e)
    R, w, g, _ = e.param_values
    rng = np.random.default_rng(4)
    for _ in range(6):
        th, thd, t = rng.uniform(-3, 3), rng.uniform(-3, 3), rng.uniform(0, 5)
        exact = (w ** 2 * np.cos(th) - g / R) * np.sin(th)
        assert val(f, [th], [thd], t, e.param_values)[0] == pytest.approx(exact, rel=1e-12, abs=1e-12)
    y = ca.Function("y", [e.q, e.t, e.p], [e.outputs["y"]])
    assert float(y([0.3], 1.0, e.param_values)) == pytest.approx(-R * np.cos(0.3), rel=1e-14)


# --------------------------------------------------------------------------- springs, dampers, applied forces

def two_masses():
    """Mass 1 slides along x through the origin, mass 2 along y through (3, 0, 0); a
    spring-damper joins them; a constant world force acts on mass 2; no gravity."""
    bodies = (ir.Body("m1", "point", mass=const(1.5)), ir.Body("m2", "point", mass=const(0.8)))
    points = (point("world", "world"), point("o2", "world", (3, 0, 0)), point("m1", "m1"), point("m2", "m2"))
    joints = (ir.Joint("j1", "prismatic", "world", "m1", "world", "m1", axis=v3(1, 0, 0), variables=(coord_var("s", "x1"),)),
              ir.Joint("j2", "prismatic", "o2", "m2", "world", "m2", axis=v3(0, 1, 0), variables=(coord_var("s", "y2"),)))
    forces = (ir.SpringDamper("sd", "spring-damper", "m1", "m2", k=const(40.0), c=const(1.3), l0=const(1.0)),
              ir.AppliedForce("F", "m2", v3(0.5, 2.0, 0.0)))
    return ir.Model("TwoMasses", coordinates=(ir.Coordinate("x1"), ir.Coordinate("y2")), bodies=bodies,
                    points=points, joints=joints, forces=forces)


@pytest.mark.parametrize("route", ["auto", "lagrange"])
def test_spring_damper_and_force_by_hand(route):
    e = derive(two_masses(), route=route)
    f = qdd_fn(e)
    energies = ca.Function("VD", [e.q, e.qd, e.p], [e.V, e.D])
    rng = np.random.default_rng(5)
    for _ in range(5):
        x1, y2 = rng.uniform(-1, 1, 2)
        v1, v2 = rng.uniform(-2, 2, 2)
        d = np.array([3 - x1, y2])
        l = np.linalg.norm(d)
        u = d / l
        ldot = u @ np.array([-v1, v2])
        T = 40.0 * (l - 1.0) + 1.3 * ldot          # tension
        exact = [T * u[0] / 1.5, (-T * u[1] + 2.0) / 0.8]
        assert np.allclose(val(f, [x1, y2], [v1, v2], 0.0, e.param_values), exact, rtol=1e-12, atol=1e-12)
        V, D = val(energies, [x1, y2], [v1, v2], e.param_values)
        assert V == pytest.approx(20.0 * (l - 1) ** 2) and D == pytest.approx(0.65 * ldot ** 2)


def rod_pendulum(*, follower=0.0, torque=0.0, gen=0.0, kappa=0.0, beta=0.0, J=0.0, ratio=None):
    """Uniform rod (m = 1.2, L = 0.9) on a revolute joint about z at its end, gravity -y, with a
    body-fixed follower force at the tip, a world torque, a generalized force, an
    equation-layer torsional spring (potential) and damper (dissipation) and rotor inertia
    (kinetic term); `ratio`: the joint angle is ratio * theta (a general expression)."""
    b, pts = rod_body("rod", const(1.2), const(0.9))
    th = ir.Coord("theta")
    var = coord_var("phi", "theta") if ratio is None else ir.JointVar("phi", mul(const(ratio), th))
    forces = [ir.Gravity("g", v3(0, -9.81, 0))]
    if follower:
        forces.append(ir.AppliedForce("follower", "rod.b", v3(follower, 0, 0), frame="rod"))
    if torque:
        forces.append(ir.AppliedTorque("tau", "rod", v3(0, 0, torque)))
    if gen:
        forces.append(ir.GeneralizedForce("Q", "theta", fn("sin", ir.Time())))
    terms = []
    if kappa:
        terms.append(ir.Term("potential", mul(const(kappa / 2), mul(th, th))))
    if beta:
        terms.append(ir.Term("dissipation", mul(const(beta / 2), mul(ir.Speed("theta"), ir.Speed("theta")))))
    if J:
        terms.append(ir.Term("kinetic", mul(const(J / 2), mul(ir.Speed("theta"), ir.Speed("theta")))))
    return ir.Model("Rod", coordinates=(ir.Coordinate("theta"),), bodies=(b,), points=(point("world", "world"),) + tuple(pts),
                    joints=(ir.Joint("j", "revolute", "world", "rod.a", "world", "rod", axis=v3(0, 0, 1), variables=(var,)),),
                    forces=tuple(forces), terms=tuple(terms),
                    outputs=(ir.Output("xdot", ir.TimeDer(ir.PointPos("rod.b", 0))), ir.Output("vx", ir.PointVel("rod.b", 0))))


def test_applied_forces_terms_by_hand():
    m, L, g = 1.2, 0.9, 9.81
    e = derive(rod_pendulum(follower=0.7, torque=0.3, gen=1.0, kappa=2.0, beta=0.4))
    assert e.route == "aba"
    el = derive(rod_pendulum(follower=0.7, torque=0.3, gen=1.0, kappa=2.0, beta=0.4), route="lagrange")
    rng = np.random.default_rng(6)
    for _ in range(5):
        th, thd, t = rng.uniform(-3, 3), rng.uniform(-2, 2), rng.uniform(0, 3)
        exact = (L * 0.7 + 0.3 + np.sin(t) - 2.0 * th - 0.4 * thd - m * g * L / 2 * np.sin(th)) / (m * L ** 2 / 3)
        for ee in (e, el):
            assert val(qdd_fn(ee), [th], [thd], t, ee.param_values)[0] == pytest.approx(exact, rel=1e-12)
    # EOM.Q holds the non-conservative forces by virtual work: follower, torque, generalized force
    Q = ca.Function("Q", [e.q, e.qd, e.t, e.p], [e.Q])
    assert float(Q([0.4], [0.0], 1.0, e.param_values)) == pytest.approx(L * 0.7 + 0.3 + np.sin(1.0))
    # der() of a position equals the point velocity
    o = ca.Function("o", [e.q, e.qd, e.p], [e.outputs["xdot"], e.outputs["vx"]])
    a, b = val(o, [0.4], [1.3], e.param_values)
    assert a == pytest.approx(b) and a == pytest.approx(L * np.cos(0.4) * 1.3)


def test_kinetic_term_and_general_joint_expression_use_crba():
    m, L, g = 1.2, 0.9, 9.81
    e = derive(rod_pendulum(follower=0.7, J=0.25))
    assert e.route == "crba" and e.qdd is None
    e2 = derive(rod_pendulum(follower=0.7, ratio=2.0))
    assert e2.route == "crba"
    for th, thd in [(0.3, 1.0), (-2.0, 0.4)]:
        exact = (L * 0.7 - m * g * L / 2 * np.sin(th)) / (m * L ** 2 / 3 + 0.25)
        assert val(qdd_fn(e), [th], [thd], 0.0, e.param_values)[0] == pytest.approx(exact, rel=1e-12)
        exact2 = (2 * L * 0.7 - m * g * L * np.sin(2 * th)) / (4 * m * L ** 2 / 3)
        assert val(qdd_fn(e2), [th], [thd], 0.0, e2.param_values)[0] == pytest.approx(exact2, rel=1e-12)
        el = derive(rod_pendulum(follower=0.7, ratio=2.0), route="lagrange")
        assert val(qdd_fn(el), [th], [thd], 0.0, el.param_values)[0] == pytest.approx(exact2, rel=1e-12)


def test_gravitation_between_point_masses():
    bodies = (ir.Body("a", "point", mass=const(2.0)), ir.Body("b", "point", mass=const(3.0)))
    pts = (point("world", "world"), point("a", "a"), point("b", "b"))
    roles = ("x", "y", "z")
    joints = tuple(ir.Joint(f"f{n}", "free", "world", n, "world", n, variables=tuple(coord_var(r, f"{n}.{r}") for r in roles))
                   for n in ("a", "b"))
    coords = tuple(ir.Coordinate(f"{n}.{r}") for n in ("a", "b") for r in roles)
    model = ir.Model("Grav", coordinates=coords, bodies=bodies, points=pts, joints=joints,
                     forces=(ir.Gravitation("G", ("a", "b"), const(1.5)),))
    e = derive(model)
    q = np.array([0.1, 0.2, -0.3, 1.1, -0.7, 0.4])
    a = val(qdd_fn(e), q, np.zeros(6), 0.0, e.param_values)
    d = q[3:] - q[:3]
    r = np.linalg.norm(d)
    assert np.allclose(a[:3], 1.5 * 3.0 * d / r ** 3, rtol=1e-13)
    assert np.allclose(a[3:], -1.5 * 2.0 * d / r ** 3, rtol=1e-13)
    V = ca.Function("V", [e.q, e.p], [e.V])
    assert float(V(q, e.param_values)) == pytest.approx(-1.5 * 6.0 / r)


def test_pure_equation_layer():
    th, thd = ir.Coord("theta"), ir.Speed("theta")
    m, L, g = P("m"), P("L"), P("g")
    T = mul(mul(const(0.5), mul(m, mul(L, L))), mul(thd, thd))
    V = neg(mul(mul(m, mul(g, L)), fn("cos", th)))
    model = ir.Model("Pend", parameters=(ir.Parameter("m", 1.0), ir.Parameter("L", 2.0), ir.Parameter("g", 9.81)),
                     coordinates=(ir.Coordinate("theta", start=P("L")),),
                     points=(point("world", "world"),),
                     forces=(ir.GeneralizedForce("Q", "theta", fn("sin", ir.Time())),),
                     terms=(ir.Term("kinetic", T), ir.Term("potential", V),
                            ir.Term("dissipation", mul(const(0.15), mul(thd, thd)))),
                     outputs=(ir.Output("E", ir.EnergyRef("energy")),
                              ir.Output("xd", ir.TimeDer(mul(L, fn("sin", th))))))
    e = derive(model)
    assert e.route == "lagrange"
    for x, xd, t in [(0.3, 1.0, 0.5), (2.5, -0.4, 2.0)]:
        exact = (-9.81 * 2 * np.sin(x) - 0.3 * xd + np.sin(t)) / 4.0
        assert val(qdd_fn(e), [x], [xd], t, e.param_values)[0] == pytest.approx(exact, rel=1e-13)
    q0, _ = e.start()
    assert q0[0] == pytest.approx(2.0, rel=1e-15)
    o = ca.Function("o", [e.q, e.qd, e.p], [e.outputs["E"], e.outputs["xd"]])
    E, xdot = val(o, [0.3], [1.0], e.param_values)
    assert E == pytest.approx(0.5 * 4 - 9.81 * 2 * np.cos(0.3))
    assert xdot == pytest.approx(2 * np.cos(0.3))


def test_components_mixed_with_an_equation_layer_coordinate():
    """A rod pendulum (coordinate theta) and an equation-layer mass x (T = M/2 x'^2) coupled by
    the potential k/2 (x - rod.b.x)^2 written with a point position."""
    m, L, g, Mx, k = 1.2, 0.9, 9.81, 0.5, 7.0
    base = rod_pendulum()
    x, xd = ir.Coord("x"), ir.Speed("x")
    gap = ir.Op("sub", (x, ir.PointPos("rod.b", 0)))
    model = dataclasses.replace(
        base, coordinates=base.coordinates + (ir.Coordinate("x"),),
        terms=(ir.Term("kinetic", mul(const(Mx / 2), mul(xd, xd))), ir.Term("potential", mul(const(k / 2), mul(gap, gap)))))
    e = derive(model)
    assert e.route == "crba"
    f = qdd_fn(e)
    for th, X in [(0.3, 0.1), (-1.2, 0.8)]:
        s = X - L * np.sin(th)
        exact = [(-m * g * L / 2 * np.sin(th) + k * s * L * np.cos(th)) / (m * L ** 2 / 3), -k * s / Mx]
        assert np.allclose(val(f, [th, X], [0.4, -0.3], 0.0, e.param_values), exact, rtol=1e-12)


def test_one_coordinate_driving_two_joints():
    """Two equal rods on separate pivots, both turned by the same coordinate (a gear): the
    pair moves like one rod, and a follower force on one of them counts once."""
    b1, p1 = rod_body("r1", const(1.2), const(0.9))
    b2, p2 = rod_body("r2", const(1.2), const(0.9))
    model = ir.Model("Gear", coordinates=(ir.Coordinate("theta"),), bodies=(b1, b2),
                     points=(point("world", "world"), point("o2", "world", (2, 0, 0))) + tuple(p1 + p2),
                     joints=(ir.Joint("j1", "revolute", "world", "r1.a", "world", "r1", axis=v3(0, 0, 1),
                                      variables=(coord_var("phi", "theta"),)),
                             ir.Joint("j2", "revolute", "o2", "r2.a", "world", "r2", axis=v3(0, 0, 1),
                                      variables=(coord_var("phi", "theta"),))),
                     forces=(ir.Gravity("g", v3(0, -9.81, 0)), ir.AppliedForce("f", "r2.b", v3(0.7, 0, 0), frame="r2")))
    e = derive(model)
    assert e.route == "crba"
    m, L, g = 1.2, 0.9, 9.81
    for th in (0.3, -2.0):
        exact = (L * 0.7 - 2 * m * g * L / 2 * np.sin(th)) / (2 * m * L ** 2 / 3)
        assert val(qdd_fn(e), [th], [1.1], 0.0, e.param_values)[0] == pytest.approx(exact, rel=1e-12)
