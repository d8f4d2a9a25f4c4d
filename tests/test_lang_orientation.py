"""Oriented points, joints and frames (issue 26): rpy = {r, p, y} in URDF's convention, R = ...,
the built-ins rpy() and axis_angle(); checked against scipy.spatial.transform (an independent
rotation construction) and against the same mechanism written with constant moving frames (the
older exact workaround, a different code path through the mechanics)."""
from __future__ import annotations

import casadi as ca
import numpy as np
import pytest
from scipy.spatial.transform import Rotation as Rot

import mechdsl
from mechdsl.diagnostics import MechError


def _fn(eom, *outs):
    return ca.Function("f", [eom.q, eom.qd, eom.t, eom.p], list(outs))


def _matrix_output(r, name, i=0):
    return np.array([[r[f"{name}[{a},{b}]"][i] for b in range(1, 4)] for a in range(1, 4)])


@pytest.mark.parametrize("seed", range(4))
def test_rpy_and_axis_angle_builtins_match_scipy(seed):
    rng = np.random.default_rng(seed)
    rpy = [float(x) for x in rng.uniform(-3, 3, 3)]
    axis = [float(x) for x in rng.normal(size=3)]
    angle = float(rng.uniform(-3, 3))
    rv = [float(x) for x in rng.normal(size=3)]
    text = f"""
model B
  parameter Real A[3, 3] = rpy({rpy[0]!r}, {rpy[1]!r}, {rpy[2]!r});
  parameter Real A2[3, 3] = rpy({{{rpy[0]!r}, {rpy[1]!r}, {rpy[2]!r}}});
  parameter Real B[3, 3] = axis_angle({{{axis[0]!r}, {axis[1]!r}, {axis[2]!r}}}, {angle!r});
  parameter Real C[3, 3] = axis_angle({{{rv[0]!r}, {rv[1]!r}, {rv[2]!r}}});
  coordinate Real q(start = 0);
equation
  kinetic = der(q)^2/2;
end B;
"""
    p = mechdsl.loads(text).parameters

    def mat(name):
        return np.array([[p[f"{name}[{i},{j}]"] for j in range(1, 4)] for i in range(1, 4)])

    # URDF: fixed-axis X-Y-Z, R = Rz(y) Ry(p) Rx(r) (scipy's extrinsic "xyz")
    expected = Rot.from_euler("xyz", rpy).as_matrix()
    hand = (Rot.from_rotvec([0, 0, rpy[2]]) * Rot.from_rotvec([0, rpy[1], 0]) * Rot.from_rotvec([rpy[0], 0, 0])).as_matrix()
    assert np.allclose(expected, hand, atol=1e-15)
    assert np.allclose(mat("A"), expected, atol=1e-14)
    assert np.allclose(mat("A2"), expected, atol=1e-14)
    assert np.allclose(mat("B"), Rot.from_rotvec(angle * np.array(axis) / np.linalg.norm(axis)).as_matrix(), atol=1e-14)
    assert np.allclose(mat("C"), Rot.from_rotvec(rv).as_matrix(), atol=1e-14)


BODIES = """  Gravity g(g = {0, 0, -9.81});
  Body a(m = 1.3, r_cm = {0.1, 0.02, -0.05}, I = {{0.02, 0.001, -0.002}, {0.001, 0.03, 0.0015}, {-0.002, 0.0015, 0.025}});
  Body b(m = 0.7, r_cm = {0.05, -0.1, 0.03}, I = {{0.01, 0.0005, 0}, {0.0005, 0.012, -0.001}, {0, -0.001, 0.008}});
  Body c(m = 0.4, r_cm = {0, 0, 0.1}, I = diagonal({0.004, 0.005, 0.003}));
"""

ORIENTED = """
model O
BODIES
  Point base(body = world, r = {0.1, -0.2, 0.3}, rpy = {0.3, -0.4, 0.5});
  Point pa(body = a, r = {0.2, 0.1, -0.1}, R = axis_angle({1, -2, 0.5}, 0.7));
  Point cb(body = b, r = {-0.05, 0.02, 0.1}, rpy = {-0.2, 0.1, 0.9});
  Revolute j1(parent = base, child = a, axis = {0, 1, 0}, rpy = {0.1, 0.2, -0.3}, phi(start = 0.3));
  Prismatic j2(parent = pa, child = cb, axis = {1, 0, 0}, s(start = 0.05));
  Revolute j3(parent = b, child = c, axis = {0, 0, 1}, rpy = {1.2, 0, 0.4}, phi(start = -0.2));
  output Real Ra[3, 3] = a.R;
  output Real Rb[3, 3] = b.R;
  output Real Rc[3, 3] = c.R;
  output Real ob[3] = b.r;
  output Real Rcb[3, 3] = cb.R;
end O;
""".replace("BODIES\n", BODIES)

# the same mechanism with constant Frames for the orientations (the pre-issue-26 workaround):
# a joint frame is a Frame on the parent point; an oriented child point becomes an inverse placement
FRAMES = """
model F
BODIES
  parameter Real P1[3, 3] = rotation({0, 0, 1}, 0.5)*rotation({0, 1, 0}, -0.4)*rotation({1, 0, 0}, 0.3)
                            *rotation({0, 0, 1}, -0.3)*rotation({0, 1, 0}, 0.2)*rotation({1, 0, 0}, 0.1);
  parameter Real P2[3, 3] = rotation({1, -2, 0.5}, 0.7);
  parameter Real Cb[3, 3] = rotation({0, 0, 1}, 0.9)*rotation({0, 1, 0}, 0.1)*rotation({1, 0, 0}, -0.2);
  parameter Real P3[3, 3] = rotation({0, 0, 1}, 0.4)*rotation({1, 0, 0}, 1.2);
  Frame f1(parent = world, r = {0.1, -0.2, 0.3}, R = P1);
  Revolute j1(parent = f1, child = a, axis = {0, 1, 0}, phi(start = 0.3));
  Point pa(body = a, r = {0.2, 0.1, -0.1});
  Frame f2(parent = pa, R = P2);
  Prismatic j2(parent = f2, axis = {1, 0, 0}, s(start = 0.05));
  Frame back(parent = j2, R = transpose(Cb), r = -(transpose(Cb)*{-0.05, 0.02, 0.1}));
  Fixed weld(parent = back, child = b);
  Frame f3(parent = b, R = P3);
  Revolute j3(parent = f3, child = c, axis = {0, 0, 1}, phi(start = -0.2));
end F;
""".replace("BODIES\n", BODIES)


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
def test_oriented_joints_place_bodies_as_scipy_composes_them():
    m = mechdsl.loads(ORIENTED)
    r = m.simulate(0.05, points=3)
    eu = lambda *a: Rot.from_euler("xyz", a).as_matrix()  # noqa: E731 - URDF rpy
    for i in range(3):
        phi1, s2, phi3 = (r[n][i] for n in ("j1.phi", "j2.s", "j3.phi"))
        R_base = eu(0.3, -0.4, 0.5)
        Ra = R_base @ eu(0.1, 0.2, -0.3) @ Rot.from_rotvec([0, phi1, 0]).as_matrix()
        oa = np.array([0.1, -0.2, 0.3])
        Pa = Rot.from_rotvec(0.7 * np.array([1, -2, 0.5]) / np.linalg.norm([1, -2, 0.5])).as_matrix()
        Ccb = eu(-0.2, 0.1, 0.9)
        R_cb = Ra @ Pa                       # the child point's axes = the parent joint frame's (prismatic)
        Rb = R_cb @ Ccb.T
        o_cb = oa + Ra @ np.array([0.2, 0.1, -0.1]) + R_cb @ np.array([s2, 0, 0])
        ob = o_cb - Rb @ np.array([-0.05, 0.02, 0.1])
        Rc = Rb @ eu(1.2, 0, 0.4) @ Rot.from_rotvec([0, 0, phi3]).as_matrix()
        assert np.allclose(_matrix_output(r, "Ra", i), Ra, atol=1e-12)
        assert np.allclose(_matrix_output(r, "Rb", i), Rb, atol=1e-12)
        assert np.allclose(_matrix_output(r, "Rc", i), Rc, atol=1e-12)
        assert np.allclose(_matrix_output(r, "Rcb", i), R_cb, atol=1e-12)
        assert np.allclose([r[f"ob[{k}]"][i] for k in (1, 2, 3)], ob, atol=1e-12)


@pytest.mark.parametrize("seed", range(3))
def test_oriented_joints_dynamics_equal_the_constant_frame_workaround(seed):
    """M and bias at random states: folded joint orientations (tree.py pre/post rotation) against
    constant Frames (an element 'T' per placement); and both routes of the oriented model."""
    a, f = mechdsl.loads(ORIENTED).eom, mechdsl.loads(FRAMES).eom
    assert a.coords == ("j1.phi", "j2.s", "j3.phi") and f.coords == a.coords
    rng = np.random.default_rng(seed)
    q, qd = rng.uniform(-1.5, 1.5, 3), rng.uniform(-2, 2, 3)
    Ma, ba = (np.array(x) for x in _fn(a, a.M, a.bias)(q, qd, 0.0, a.param_values))
    Mf, bf = (np.array(x) for x in _fn(f, f.M, f.bias)(q, qd, 0.0, f.param_values))
    assert np.allclose(Ma, Mf, rtol=1e-12, atol=1e-14) and np.allclose(ba, bf, rtol=1e-12, atol=1e-13)
    from mechdsl.mechanics import derive

    lg = derive(mechdsl.loads(ORIENTED).model, route="lagrange")
    Ml, bl = (np.array(x) for x in _fn(lg, lg.M, lg.bias)(q, qd, 0.0, lg.param_values))
    assert np.allclose(Ma, Ml, rtol=1e-11, atol=1e-13) and np.allclose(ba, bl, rtol=1e-11, atol=1e-12)
    qdd = np.array(_fn(a, a.qdd)(q, qd, 0.0, a.param_values)).ravel()
    assert np.allclose(qdd, np.linalg.solve(Mf, bf).ravel(), rtol=1e-10)


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
def test_printed_equations_see_the_orientations():
    """The sympy route (mech equations) composes the joint frames too: its kinetic and potential
    energies equal the numeric ones at a random state."""
    from mechdsl.mechanics.symbolic import symbolic_model
    import sympy as sp

    m = mechdsl.loads(ORIENTED)
    sm = symbolic_model(m.model)
    rng = np.random.default_rng(7)
    q, qd = rng.uniform(-1, 1, 3), rng.uniform(-1, 1, 3)
    subs = {}
    for c, x, v in zip(sm.coords, q, qd):
        subs[sp.diff(c, sm.t)] = v
    subs.update({c: x for c, x in zip(sm.coords, q)})
    T = float(sm.T.subs(subs).evalf())
    V = float(sm.V.subs(subs).evalf())
    e = m.eom
    Tn, Vn = (float(x) for x in _fn(e, e.T, e.V)(q, qd, 0.0, e.param_values))
    assert T == pytest.approx(Tn, rel=1e-10) and V == pytest.approx(Vn, rel=1e-10, abs=1e-12)


def test_reaction_is_given_in_the_oriented_child_joint_frame():
    """A body welded by an oriented child point hangs still: the reaction on it is m g turned into
    the child joint frame (C^T R^T (0, 0, m g)), independent of how the child point is oriented."""
    text = """
model W
  Gravity g(g = {0, 0, -9.81});
  Body b(m = 2, r_cm = {0.3, 0, 0}, I = diagonal({0.1, 0.2, 0.3}));
  Point c(body = b, rpy = {0.4, -0.3, 1.1});
  Revolute j(parent = world, child = c, axis = {0, 0, 1}, phi(start = 0.7));
  output Real F[3] = reaction_force(j);
end W;
"""
    r = mechdsl.loads(text).simulate(0.01, points=2)
    C = Rot.from_euler("xyz", [0.4, -0.3, 1.1]).as_matrix()
    R_jc = Rot.from_rotvec([0, 0, r["j.phi"][0]]).as_matrix()      # the child joint frame in world axes
    expected = R_jc.T @ np.array([0, 0, 2 * 9.81])
    assert np.allclose([r[f"F[{k}]"][0] for k in (1, 2, 3)], expected, atol=1e-10)
    assert C.shape == (3, 3)


def test_a_loop_closed_by_an_oriented_joint_holds_at_a_consistent_start():
    """A parallelogram in a tilted plane, every hinge axis rpy-oriented: the loop closure of the cut
    joint (its frames composed with the orientations) vanishes where the geometry closes."""
    R = Rot.from_euler("xyz", [0.3, 0.2, 0.1]).as_matrix()
    bx = ", ".join(repr(float(x)) for x in R[:, 0])        # one length along the tilted x axis
    text = """
model Loop
  parameter Real L = 1;
  Body l1(m = 1, r_cm = {0, 0, 0.5}, I = diagonal({0.1, 0.1, 0.01}));
  Body l2(m = 1, r_cm = {0, 0, 0.5}, I = diagonal({0.1, 0.1, 0.01}));
  Body cp(m = 1, r_cm = {0.5, 0, 0}, I = diagonal({0.01, 0.1, 0.1}));
  Point a(body = world, rpy = {0.3, 0.2, 0.1});
  Point b(body = world, r = {BX}, rpy = {0.3, 0.2, 0.1});
  Point e1(body = l1, r = {0, 0, L});
  Point e2(body = l2, r = {0, 0, L});
  Point k(body = cp, r = {1, 0, 0}, rpy = {0, 0, 0});
  Revolute h1(parent = a, child = l1, axis = {0, 1, 0}, phi(start = 0.4));
  Revolute h2(parent = b, child = l2, axis = {0, 1, 0}, phi(start = 0.4, fixed = false));
  Revolute h3(parent = e1, child = cp, axis = {0, 1, 0}, phi(start = -0.4, fixed = false));
  Revolute h4(parent = e2, child = k, axis = {0, 1, 0});
end Loop;
""".replace("BX", bx)
    m = mechdsl.loads(text)
    e = m.eom
    assert len(m.model.loops) == 1
    g = ca.Function("g", [e.q, e.t, e.p], [e.g])
    names = list(e.coords)
    q = np.zeros(len(names))
    q[names.index("h1.phi")], q[names.index("h2.phi")], q[names.index("h3.phi")] = 0.4, 0.4, -0.4
    assert np.max(np.abs(np.array(g(q, 0.0, e.param_values)))) < 1e-12
    q[names.index("h2.phi")] = 0.5                       # and not where it does not
    assert np.max(np.abs(np.array(g(q, 0.0, e.param_values)))) > 1e-3


def test_constant_frames_are_not_counted_moving_ones_are():
    text = """
model K
  Gravity g;
  Body b(m = 1, r_cm = {0.5, 0, 0}, I = diagonal({0.1, 0.1, 0.1}));
  parameter Real w = 2;
  Frame fixed(r = {0, 1, 0}, rpy = {0, 0, 0.3});
  Frame spin(parent = fixed, axis = {0, 1, 0}, angle = w*time);
  Revolute j(parent = spin, child = b, phi(start = 0.2));
end K;
"""
    m = mechdsl.loads(text)
    assert "2 bodies, 2 joints" in m.summary()     # b and its joint, the spinning frame and its motion
    from mechdsl.semantic.topology import counts

    c = counts(m.model)
    assert c["bodies"] == 2 and c["joints"] == 2 and len(m.model.bodies) == 3 and len(m.model.joints) == 3


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
def test_oriented_spherical_start_velocity_is_in_the_child_body_axes():
    """omega(start, frame = "body") on a Spherical joint whose child point is oriented is the child
    body's angular velocity in its own axes; frame = "world" is in world axes through the joint's rpy."""
    text = """
model S
  Body b(m = 1, r_cm = {0, 0, -0.5}, I = diagonal({0.1, 0.2, 0.3}));
  Point c(body = b, rpy = {0.3, 0.5, -0.2});
  Spherical j(parent = world, child = c, rpy = {0.2, -0.1, 0.4}, phi(start = 0.3), theta(start = -0.2),
              psi(start = 0.1), omega(start = {0.1, -0.4, 0.7}, frame = "FRAME"));
  output Real wb[3] = b.w_body;
  output Real w[3] = b.w;
end S;
"""
    for frame, out in (("body", "wb"), ("world", "w")):
        r = mechdsl.loads(text.replace("FRAME", frame)).simulate(0.01, points=2)
        assert np.allclose([r[f"{out}[{k}]"][0] for k in (1, 2, 3)], [0.1, -0.4, 0.7], atol=1e-12)


def test_orientation_errors_are_located():
    bad = """
model E
  Body b(m = 1, I = diagonal({1, 1, 1}));
  Point p(body = world, R = {{1, 0, 0}, {0, 1, 0}, {0, 0, 2}});
  Revolute j(parent = p, child = b, phi(start = 0.1));
end E;
"""
    with pytest.raises(MechError) as e:
        mechdsl.loads(bad)
    assert [d.code for d in e.value.diagnostics] == ["E318"]
    assert e.value.diagnostics[0].span.line == 4
    with pytest.raises(MechError) as e:
        mechdsl.loads(bad.replace("R = {{1, 0, 0}, {0, 1, 0}, {0, 0, 2}}", "rpy = {1, 2}"))
    assert e.value.diagnostics[0].code == "E301"
