"""Imported visuals are drawn where the URDF puts them.  At random joint states every Shape of an
imported robot is compared with Pinocchio's placement of the same <visual>
(``pin.buildGeomFromUrdf`` with ``GeometryType.VISUAL``, ``updateGeometryPlacements``): boxes corner
by corner (a mesh: the corners of the box that bounds the vertices Pinocchio itself loaded, scale
applied, placed by its visual frame), cylinders by centre, axis, radius and length, spheres by
centre and radius; once in the drawing's Function (float64) and once in the 3-D page's data
(float32 poses).  Robots: a synthetic one (offset and turned visuals, two on a link, a merged
link's visuals, a scaled and mirrored STL) and the UR5 and Franka Panda of example-robot-data
with their COLLADA meshes."""
from __future__ import annotations

import struct

import numpy as np
import pytest

import mechdsl
from mechdsl.animate.geometry import build
from mechdsl.view import still

from draw_util import SIGNS, page_solids, quat_matrix
from urdf_util import Pair, robots_dir, share_dir

ROBOT = """<?xml version="1.0"?>
<robot name="shapes">
  <link name="base">
    <inertial><mass value="3"/><inertia ixx="0.1" ixy="0" ixz="0" iyy="0.1" iyz="0" izz="0.1"/></inertial>
    <visual><origin xyz="0.02 -0.01 0.05" rpy="0 0 0.3"/><geometry><box size="0.3 0.2 0.1"/></geometry></visual>
  </link>
  <link name="upper">
    <inertial><origin xyz="0 0 0.2"/><mass value="2"/>
      <inertia ixx="0.03" ixy="0" ixz="0" iyy="0.03" iyz="0" izz="0.004"/></inertial>
    <visual><origin xyz="0.01 0.02 0.2" rpy="0.1 -0.2 0.3"/><geometry><cylinder radius="0.04" length="0.4"/></geometry></visual>
    <visual><origin xyz="0.05 0 0.1" rpy="0.4 0.5 -0.6"/><geometry><mesh filename="part.stl" scale="2 1 -1"/></geometry></visual>
  </link>
  <link name="hand">
    <inertial><origin xyz="0 0.02 0.03"/><mass value="0.5"/>
      <inertia ixx="0.001" ixy="0" ixz="0" iyy="0.002" iyz="0" izz="0.002"/></inertial>
    <visual><origin xyz="0.03 0 0.04" rpy="0.7 0 -0.2"/><geometry><box size="0.08 0.05 0.03"/></geometry></visual>
    <visual><origin xyz="0 0.05 0.06"/><geometry><sphere radius="0.025"/></geometry></visual>
  </link>
  <link name="slider">
    <inertial><mass value="0.4"/><inertia ixx="0.001" ixy="0" ixz="0" iyy="0.001" iyz="0" izz="0.0005"/></inertial>
    <visual><geometry><box size="0.05 0.06 0.07"/></geometry></visual>
  </link>
  <joint name="shoulder" type="continuous">
    <parent link="base"/><child link="upper"/><origin xyz="0 0 0.1" rpy="0.2 -0.1 0.4"/><axis xyz="0 1 1"/>
  </joint>
  <joint name="weld" type="fixed">
    <parent link="upper"/><child link="hand"/><origin xyz="0.02 0 0.4" rpy="0.3 0.2 -0.5"/>
  </joint>
  <joint name="slide" type="prismatic">
    <parent link="hand"/><child link="slider"/><origin xyz="0.1 0 0.05" rpy="0 0.6 0"/><axis xyz="1 0 0"/>
    <limit lower="-0.2" upper="0.2" effort="10" velocity="1"/>
  </joint>
</robot>
"""

# a tetrahedron whose vertices are away from the mesh's origin (its box is not centred there)
TETRA = np.array([[0.1, 0.02, -0.03], [0.3, 0.02, -0.03], [0.1, 0.12, -0.03], [0.1, 0.02, 0.05]])


def binary_stl(vertices: np.ndarray) -> bytes:
    tris = [(0, 1, 2), (0, 1, 3), (0, 2, 3), (1, 2, 3)]
    out = bytearray(80) + struct.pack("<I", len(tris))
    for t in tris:
        out += struct.pack("<3f", 0, 0, 0) + b"".join(struct.pack("<3f", *vertices[i]) for i in t) + b"\0\0"
    return bytes(out)


@pytest.fixture(scope="module")
def synthetic(tmp_path_factory):
    d = tmp_path_factory.mktemp("visuals")
    (d / "part.stl").write_bytes(binary_stl(TETRA))
    (d / "shapes.urdf").write_text(ROBOT)
    return d / "shapes.urdf"




class Visuals:
    """Pinocchio's visual geometry of the same URDF beside the imported model's drawing."""

    def __init__(self, pair: Pair, package_dirs: list[str]):
        import pinocchio as pin

        self.pair = pair
        self.geom = pin.buildGeomFromUrdf(pair.pin, str(pair.path), pin.GeometryType.VISUAL, package_dirs=package_dirs)
        self.gdata = pin.GeometryData(self.geom)
        self.index = {o.name: i for i, o in enumerate(self.geom.geometryObjects)}
        self.draw = build(pair.eom)

    def pin_placements(self, q):
        import pinocchio as pin

        qp, _ = self.pair.to_pin(q, np.zeros_like(q))
        pin.forwardKinematics(self.pair.pin, self.pair.data, qp)
        pin.updateGeometryPlacements(self.pair.pin, self.pair.data, self.geom, self.gdata)
        return self.gdata.oMg

    def expected(self, shape: str, q) -> dict:
        """Pinocchio's world placement of the visual a Shape comes from."""
        link, k = self.pair.imp.shapes[shape]
        i = self.index[f"{link}_{k}"]
        obj, M = self.geom.geometryObjects[i], self.pin_placements(q)[i]
        R, p = np.array(M.rotation), np.array(M.translation)
        g = obj.geometry
        kind = type(g).__name__
        if kind == "Box":
            h = np.array(g.halfSide)
            return {"kind": "box", "corners": [p + R @ (h * s) for s in SIGNS]}
        if kind == "Cylinder":
            return {"kind": "cylinder", "center": p, "axis": R[:, 2], "size": (g.radius, 2 * g.halfLength)}
        if kind == "Sphere":
            return {"kind": "sphere", "center": p, "size": (g.radius,)}
        V = np.array(g.vertices())                      # a mesh, as Pinocchio loaded it (scale applied)
        lo, hi = V.min(axis=0), V.max(axis=0)
        return {"kind": "box", "corners": [p + R @ np.where(s < 0, lo, hi) for s in SIGNS]}


def check(expected: dict, kind: str, center, rot, size, corners, tol: float) -> None:
    assert kind == expected["kind"]
    if kind == "box":
        np.testing.assert_allclose(np.array(corners), np.array(expected["corners"]), rtol=0, atol=tol)
        return
    np.testing.assert_allclose(center, expected["center"], rtol=0, atol=tol)
    np.testing.assert_allclose(size, expected["size"], rtol=0, atol=tol)
    if kind == "cylinder":
        np.testing.assert_allclose(rot[:, 2], expected["axis"], rtol=0, atol=tol)


def compare_drawing(v: Visuals, q, tol: float) -> int:
    """Every Shape in the drawing's Function (float64) against Pinocchio; returns how many."""
    geo = v.draw
    X = geo.positions(np.zeros(1), q[None, :])[0]
    origins, rotations = geo.poses(np.zeros(1), q[None, :])
    seen = 0
    for it in geo.items:
        solid = it.extra.get("solid")
        if solid is None or not solid.name:
            continue
        b = geo.posed.index(it.body)
        o, R = origins[0, b], rotations[0, b]
        corners = X[:, it.cols].T if solid.kind == "box" else None
        check(v.expected(solid.name, q), solid.kind, o + R @ solid.center, R @ solid.rot, solid.size, corners, tol)
        seen += 1
    return seen


def compare_page(v: Visuals, q, tol: float) -> int:
    """Every Shape in the page's data (body poses and the solids in body axes) against Pinocchio."""
    seen = 0
    for _, o, R, s in page_solids(still(v.pair.model, q).data):
        if "name" not in s:
            continue
        Rs = quat_matrix(*s["quat"])
        c = o + R @ np.array(s["center"])
        corners = [c + R @ Rs @ (np.array(s["size"]) / 2 * sg) for sg in SIGNS] if s["kind"] == "box" else None
        check(v.expected(s["name"], q), s["kind"], c, R @ Rs, tuple(s["size"]), corners, tol)
        seen += 1
    return seen


def test_synthetic_visuals_against_pinocchio(synthetic):
    pair = Pair(str(synthetic))
    v = Visuals(pair, [str(synthetic.parent)])
    assert sorted(pair.imp.shapes.values()) == sorted((o.name.rsplit("_", 1)[0], int(o.name.rsplit("_", 1)[1]))
                                                      for o in v.geom.geometryObjects)
    rng = np.random.default_rng(11)
    for _ in range(3):
        q = rng.uniform(-np.pi, np.pi, len(pair.eom.coords))
        assert compare_drawing(v, q, 2e-6) == 6
        assert compare_page(v, q, 2e-5) == 6


def test_the_text_keeps_the_urdf_numbers(synthetic):
    text = mechdsl.urdf.convert(synthetic).text
    assert ('Shape upper_visual(body = upper, shape = "cylinder", size = {0.04, 0.4}, r = {0.01, 0.02, 0.2},\n'
            '                     rpy = {0.1, -0.2, 0.3});') in text
    assert 'Shape slider_visual(body = slider, shape = "box", size = {0.05, 0.06, 0.07});' in text
    m = mechdsl.loads(text).model
    assert [(s.name, s.body, s.kind) for s in m.shapes] == [
        ("base_visual", "base", "box"), ("upper_visual", "upper", "cylinder"), ("upper_visual_2", "upper", "box"),
        ("hand_visual", "upper", "box"), ("hand_visual_2", "upper", "sphere"), ("slider_visual", "slider", "box")]
    assert all(not b.shape for b in m.bodies)


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
@pytest.mark.parametrize("rel_path", ["ur_description/urdf/ur5_robot.urdf", "panda_description/urdf/panda.urdf"])
def test_arm_meshes_against_pinocchio(rel_path):
    pair = Pair(rel_path)
    v = Visuals(pair, [str(share_dir())])
    n = len(v.geom.geometryObjects)
    assert len(pair.imp.shapes) == n
    q = np.random.default_rng(4).uniform(-np.pi, np.pi, len(pair.eom.coords))
    assert compare_drawing(v, q, 1e-5) == n
    assert compare_page(v, q, 3e-5) == n
