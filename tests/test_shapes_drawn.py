"""Shapes placed on bodies (the component ``Shape``: an offset ``r`` and an orientation ``rpy`` or
``R`` in body axes) are drawn where they are: a box's corners, computed here by turning them by
hand (elementary rotations, Rz Ry Rx for rpy; Rodrigues' formula for axis_angle), against the
2-D drawing (the outline the xy and xz views fill) and against the 3-D page's data (body pose
times the solid's centre, quaternion and size); several shapes on one body, a shape on the
world, a cylinder's axis; the language's checks."""
from __future__ import annotations

import numpy as np
import pytest
from matplotlib.colors import to_rgba
from matplotlib.patches import Polygon
from scipy.spatial import ConvexHull

import mechdsl
from mechdsl.animate import draw
from mechdsl.animate.geometry import build
from mechdsl.animate.stage import body_colours
from mechdsl.diagnostics import MechError
from mechdsl.view import still

from draw_util import SIGNS, page_solids, quat_matrix

MODEL = """
model Placed
  parameter Real a = 0.3;
  Body b(m = 1, I_11 = 0.01, I_22 = 0.01, I_33 = 0.01);
  Shape plate(body = b, shape = "box", size = {a, 0.1, 0.05}, r = {0.4, 0.1, 0.02}, rpy = {0.3, -0.5, 1.1});
  Shape fin(body = b, shape = "box", size = {0.05, 0.2, 0.08}, r = {-0.1, 0.05, 0.3},
            R = axis_angle({1, 2, 3}, 0.8));
  Shape shaft(body = b, shape = "cylinder", size = {0.02, 0.5}, r = {0.2, 0, 0}, rpy = {0, 0, 0.4},
              axis = {1, 0, 0});
  Shape post(body = world, shape = "box", size = {0.1, 0.1, 0.4}, r = {0, 0, -0.2});
  Revolute j(parent = world, child = b, axis = {0, 0, 1}, phi(start = 0.7));
end Placed;
"""
PHI = 0.7


def rx(a):
    return np.array([[1, 0, 0], [0, np.cos(a), -np.sin(a)], [0, np.sin(a), np.cos(a)]])


def ry(a):
    return np.array([[np.cos(a), 0, np.sin(a)], [0, 1, 0], [-np.sin(a), 0, np.cos(a)]])


def rz(a):
    return np.array([[np.cos(a), -np.sin(a), 0], [np.sin(a), np.cos(a), 0], [0, 0, 1]])


def rodrigues(axis, angle):
    k = np.asarray(axis, float) / np.linalg.norm(axis)
    K = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + np.sin(angle) * K + (1 - np.cos(angle)) * K @ K


# each shape by hand: (body rotation, centre in body axes, its axes in body axes, size)
BODY = rz(PHI)
HAND = {
    "plate": (BODY, np.array([0.4, 0.1, 0.02]), rz(1.1) @ ry(-0.5) @ rx(0.3), np.array([0.3, 0.1, 0.05])),
    "fin": (BODY, np.array([-0.1, 0.05, 0.3]), rodrigues([1, 2, 3], 0.8), np.array([0.05, 0.2, 0.08])),
    "post": (np.eye(3), np.array([0, 0, -0.2]), np.eye(3), np.array([0.1, 0.1, 0.4])),
}


def corners(name) -> np.ndarray:
    R, c, S, size = HAND[name]
    return np.array([R @ (c + S @ (size / 2 * s)) for s in SIGNS])


@pytest.fixture(scope="module")
def model():
    return mechdsl.loads(MODEL)


def outlines(m, view: str) -> list[np.ndarray]:
    """The vertices of the filled outlines of the drawing (the solids' polygons), in drawing order."""
    colours = body_colours(build(m.eom))
    fig = draw(m, view=view)
    wanted = {to_rgba(colours["b"]), to_rgba(colours["world"])}
    polys = [p for p in fig.axes[0].patches if isinstance(p, Polygon) and to_rgba(p.get_facecolor()) in wanted]
    return [np.unique(np.round(p.get_xy(), 12), axis=0) for p in polys]


def hull(points2d: np.ndarray) -> np.ndarray:
    return np.unique(np.round(points2d[ConvexHull(points2d).vertices], 12), axis=0)


@pytest.mark.parametrize("view, axes", [("xy", [0, 1]), ("xz", [0, 2])])
def test_boxes_in_the_2d_views_are_where_hand_rotation_puts_them(model, view, axes):
    drawn = outlines(model, view)
    for name in ("plate", "fin", "post"):
        expected = hull(corners(name)[:, axes])
        assert any(d.shape == expected.shape and np.allclose(d, expected, atol=1e-12) for d in drawn), (name, drawn)


def test_the_drawing_function_puts_the_corners_there(model):
    geo = build(model.eom)
    X = geo.positions(np.zeros(1), np.array([[PHI]]))[0]
    solids = {it.extra["solid"].name: it for it in geo.items if it.extra.get("solid") is not None}
    assert sorted(solids) == ["fin", "plate", "post", "shaft"]
    for name in ("plate", "fin", "post"):
        np.testing.assert_allclose(X[:, solids[name].cols].T, corners(name), rtol=0, atol=1e-14)
    assert solids["post"].body == "world" and {solids[n].body for n in ("plate", "fin", "shaft")} == {"b"}


def test_the_page_data_puts_the_corners_there(model):
    found = {s["name"]: (body, o, R, s) for body, o, R, s in page_solids(still(model, [PHI]).data)}
    assert sorted(found) == ["fin", "plate", "post", "shaft"]
    for name in ("plate", "fin", "post"):
        body, o, R, s = found[name]
        S, c, size = quat_matrix(*s["quat"]), np.array(s["center"]), np.array(s["size"])
        got = np.array([o + R @ (c + S @ (size / 2 * sg)) for sg in SIGNS])
        np.testing.assert_allclose(got, corners(name), rtol=0, atol=1e-6)      # (poses are float32)
    body, o, R, s = found["shaft"]                     # the cylinder's axis: its own x turned by yaw 0.4
    S = quat_matrix(*s["quat"])
    np.testing.assert_allclose(o + R @ np.array(s["center"]), BODY @ np.array([0.2, 0, 0]), atol=1e-6)
    np.testing.assert_allclose(R @ S[:, 2], BODY @ rz(0.4) @ np.array([1, 0, 0]), atol=1e-6)
    assert s["size"] == [0.02, 0.5] and body == "b"


def test_a_body_with_shapes_is_not_drawn_as_its_inertia(model):
    kinds = [it.kind for it in build(model.eom).items]
    assert "ellipsoid" not in kinds and "link" not in kinds


@pytest.mark.parametrize("shape, code", [
    ('Shape s(body = b, shape = "box", size = {0.1, 0.2});', "E301"),
    ('Shape s(body = b, shape = "cone", size = {0.1});', "E217"),
    ('Shape s(body = b, shape = "box", size = {0.1, 0.2, 0.3}, rpy = {0, 0, 1}, R = rpy(0, 0, 1));', "E211"),
    ('Shape s(body = b, shape = "box", size = {0.1, 0.2, 0.3}, rpy = {0, 0, j.phi});', "E306"),
    ('Shape s(body = b, shape = "box", size = {0.1, -0.2, 0.3});', "E511"),
    ('Shape s(body = b, shape = "box", size = {0.1, 0.2, 0.3}, R = {{1, 0, 0}, {0, 1, 0}, {0, 0, 2}});', "E318"),
    ('Shape s(body = j.phi, shape = "sphere", size = {0.1});', "E209"),
])
def test_bad_shapes_are_located_errors(shape, code):
    text = f"""model M
  Body b(m = 1, I_11 = 0.01, I_22 = 0.01, I_33 = 0.01);
  Revolute j(parent = world, child = b, axis = {{0, 0, 1}});
  {shape}
end M;
"""
    with pytest.raises(MechError) as e:
        mechdsl.loads(text)
    d = e.value.diagnostics[0]
    assert d.code == code and d.span.line == 4, e.value.diagnostics
