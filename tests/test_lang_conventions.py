"""Issue 17: the sign conventions of every joint, as tabulated in docs/language.md, checked on
the derived kinematics; and the cart-pole with hinge axis {0, 0, -1} (theta positive clockwise,
as in the textbook) against Florian's closed-form equations at random states."""
from __future__ import annotations

from pathlib import Path

import casadi as ca
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

import mechdsl
from reach_util import accelerations

from conftest import CHECKOUT, MODELS  # noqa: E402
MARKER = "  Body b(m = 1, I = diagonal({0.1, 0.1, 0.1}));\n  Point bx(body = b, r = {1, 0, 0});\n"


def pose(decl, values):
    """(origin, R) of the marker body with the joint variables set (others 0)."""
    e = mechdsl.loads(f"model M\n{MARKER}  {decl}\nend M;\n").eom
    f = ca.Function("p", [e.q, e.t, e.p], [e.point_position("b"), e.body_rotation("b")])
    q = np.zeros(len(e.coords))
    for k, v in values.items():
        q[e.coords.index(k)] = v
    o, R = f(q, 0.0, e.param_values)
    return np.array(o, float).ravel(), np.array(R, float)


def rot_z(a):
    return Rotation.from_euler("z", a).as_matrix()


@pytest.mark.parametrize("decl, values, origin, R", [
    ("Revolute j(parent = world, child = b, axis = {0, 0, 1});", {"j.phi": 0.6}, [0, 0, 0], rot_z(0.6)),
    ("Revolute j(parent = world, child = b, axis = {0, 0, -1});", {"j.phi": 0.6}, [0, 0, 0], rot_z(-0.6)),
    ("Prismatic j(parent = world, child = b, axis = {1, 0, 0});", {"j.s": 0.6}, [0.6, 0, 0], np.eye(3)),
    ("Cylindrical j(parent = world, child = b, axis = {0, 0, 1});", {"j.phi": 0.6, "j.s": 0.4}, [0, 0, 0.4],
     rot_z(0.6)),
    ("Planar j(parent = world, child = b, axis = {0, 0, 1});", {"j.x": 0.3, "j.y": -0.2, "j.phi": 0.6},
     [0.3, -0.2, 0], rot_z(0.6)),
    ("Spherical j(parent = world, child = b);", {"j.phi": 0.3, "j.theta": 0.5, "j.psi": -0.4}, [0, 0, 0],
     Rotation.from_euler("ZYX", [0.3, 0.5, -0.4]).as_matrix()),
    ('Spherical j(parent = world, child = b, sequence = "zxz");', {"j.phi": 0.3, "j.theta": 0.5, "j.psi": -0.4},
     [0, 0, 0], Rotation.from_euler("ZXZ", [0.3, 0.5, -0.4]).as_matrix()),
    ("Free j(child = b);", {"j.x": 1, "j.y": 2, "j.z": 3, "j.phi": 0.3, "j.theta": 0.5, "j.psi": -0.4},
     [1, 2, 3], Rotation.from_euler("ZYX", [0.3, 0.5, -0.4]).as_matrix()),
    ('Spherical j(parent = world, child = b, parametrization = "quaternion");',
     {"j.q0": np.cos(0.3), "j.q3": np.sin(0.3)}, [0, 0, 0], rot_z(0.6)),
])
def test_joint_sign_conventions(decl, values, origin, R):
    o, Rb = pose(decl, values)
    assert o == pytest.approx(origin, abs=1e-12)
    assert Rb == pytest.approx(R, abs=1e-12)


@pytest.mark.parametrize("normal", [(0, 0, 1), (1, 0, 0), (0, 1, 0), (0, 0, -1), (-1, 0, 0), (0, -1, 0)])
def test_planar_axes_of_the_coordinate_normals(normal):
    """The documented basis: e1 = the lowest-numbered other axis, e1 x e2 = the normal."""
    from mechdsl.model.ir import plane_basis

    e1, e2 = (np.array(e) for e in plane_basis(normal))
    k = int(np.argmax(np.abs(normal)))
    assert e1 == pytest.approx(np.eye(3)[1 if k == 0 else 0], abs=0)
    assert np.cross(e1, e2) == pytest.approx(normal, abs=1e-15)


def test_planar_axes_move_continuously_with_the_normal():
    """A slightly tilted normal moves the in-plane axes slightly (the old rule turned them by 90
    degrees for {1e-3, 0, 1}: the child jumped by the offsets' length); orthonormal, right-handed."""
    from mechdsl.model.ir import plane_basis

    rng = np.random.default_rng(7)
    for _ in range(200):
        n = rng.normal(size=3)
        n /= np.linalg.norm(n)
        e1, e2 = (np.array(e) for e in plane_basis(n))
        assert np.array([e1 @ e1, e2 @ e2, e1 @ e2, e1 @ n, e2 @ n]) == pytest.approx([1, 1, 0, 0, 0], abs=1e-14)
        assert np.cross(e1, e2) == pytest.approx(n, abs=1e-14)
        if np.max(np.abs(n)) > 0.6:          # away from where the nearest coordinate axis changes
            m = n + 1e-6 * rng.normal(size=3)
            f1, f2 = (np.array(e) for e in plane_basis(m / np.linalg.norm(m)))
            assert np.linalg.norm(f1 - e1) + np.linalg.norm(f2 - e2) < 1e-4
    values = {"j.x": 0.3, "j.y": -0.2}
    o_z, _ = pose("Planar j(parent = world, child = b, axis = {0, 0, 1});", values)
    o_t, _ = pose("Planar j(parent = world, child = b, axis = {1e-3, 0, 1});", values)
    assert np.linalg.norm(o_t - o_z) < 1e-3


def test_convention_figures_exist_and_are_referenced():
    doc = (CHECKOUT / "docs" / "language.md").read_text()
    for kind in ("revolute", "prismatic", "cylindrical", "planar", "spherical", "free", "cart_pole_axis"):
        name = f"figures/joint_{kind}.png"
        assert (CHECKOUT / "docs" / name).is_file() and name in doc


def test_cart_pole_with_clockwise_hinge_matches_florian():
    """Florian (2007), frictionless, theta from the upward vertical, clockwise positive,
    l = half the pole length:
    theta'' = (g sin - cos (F + m l w^2 sin)/(M + m)) / (l (4/3 - m cos^2/(M + m))),
    x'' = (F + m l (w^2 sin - theta'' cos)) / (M + m)."""
    text = (MODELS / "cart_pole.mech").read_text().replace(
        "axis = {0, 0, 1}, phi = theta", "axis = {0, 0, -1}, phi = theta")
    m = mechdsl.loads(text, model="CartPole")
    e = m.eom
    Mc, mp, L, g = 1.0, 0.1, 1.0, 9.81
    l = L / 2
    acc = accelerations(e)
    rng = np.random.default_rng(2)
    for _ in range(4):
        q = np.array([rng.uniform(-1, 1), rng.uniform(-np.pi, np.pi)])
        qd = rng.uniform(-2, 2, 2)
        th, w = q[1], qd[1]
        s, c = np.sin(th), np.cos(th)
        thdd = (g * s - c * (mp * l * w**2 * s) / (Mc + mp)) / (l * (4 / 3 - mp * c**2 / (Mc + mp)))
        xdd = mp * l * (w**2 * s - thdd * c) / (Mc + mp)
        got = acc(q, qd)
        assert got[e.coords.index("theta")] == pytest.approx(thdd, rel=1e-10)
        assert got[e.coords.index("x")] == pytest.approx(xdd, rel=1e-10, abs=1e-12)
