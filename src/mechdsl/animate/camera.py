"""Which way is up, and the screen axes of each view.

The up direction of a drawing is against gravity: ``-g / |g|`` for the model's ``Gravity``
(summed when there are several); y when the model has none (the language's convention: x right,
y up).  ``--up x|y|z|-x|-y|-z`` overrides it.

Views (orthographic):

    xy, xz, yz   a coordinate plane, seen from +z, -y, +x; the screen's vertical is ``up``
                 projected on the plane (the plane's second axis when up is normal to it)
    3d           seen from azimuth 35 deg and elevation 20 deg about ``up``: at azimuth 0 the
                 viewer looks along -a, where a is the horizontal direction nearest +z (for an up
                 along y) or -y (for an up along z); the angle turns from a towards up x a

With up = y this is the 3d view mechdsl always drew; with up = z (gravity along -z) it is the
view of MuJoCo and matplotlib: x towards the viewer on the left, y to the right.
"""
from __future__ import annotations

import math

import numpy as np

from ..diagnostics import UsageError

UPS = ("x", "y", "z", "-x", "-y", "-z")
AZIMUTH, ELEVATION = math.radians(35.0), math.radians(20.0)
DEFAULT_UP = np.array([0.0, 1.0, 0.0])
# coordinate planes: (screen right, screen up, towards the viewer) when up is not in the plane
_PLANES = {"xy": ((1, 0, 0), (0, 1, 0), (0, 0, 1)),
           "xz": ((1, 0, 0), (0, 0, 1), (0, -1, 0)),
           "yz": ((0, 1, 0), (0, 0, 1), (1, 0, 0))}


def parse_up(text) -> np.ndarray:
    """``x``, ``-z``, ``+y`` ... as a unit vector; a usage error names the choices."""
    s = str(text).strip().lower()
    sign = -1.0 if s.startswith("-") else 1.0
    axis = s.lstrip("+-")
    if axis not in ("x", "y", "z") or len(s) - len(axis) > 1:
        raise UsageError(f"--up: unknown direction '{text}' (choices: {', '.join(UPS)})")
    v = np.zeros(3)
    v["xyz".index(axis)] = sign
    return v


def up_label(up) -> str:
    """'z', '-y', or the vector when it is not along an axis."""
    up = np.asarray(up, float)
    for i, name in enumerate("xyz"):
        if abs(abs(up[i]) - 1.0) < 1e-12:
            return ("-" if up[i] < 0 else "") + name
    return "(" + ", ".join(f"{c:.2f}" for c in up) + ")"


def gravity_up(g_vectors) -> np.ndarray:
    """Up from the model's gravity vectors (evaluated): against their sum; y when there is none."""
    total = np.zeros(3)
    for g in g_vectors:
        total += np.asarray(g, float)
    n = float(np.linalg.norm(total))
    if not np.isfinite(n) or n < 1e-300:
        return DEFAULT_UP.copy()
    return -total / n


def _unit(v) -> np.ndarray:
    v = np.asarray(v, float)
    return v / np.linalg.norm(v)


def horizontal_front(up) -> np.ndarray:
    """The horizontal direction the viewer stands on at azimuth 0 (see the module text)."""
    up = _unit(up)
    hint = np.array([0.0, -1.0, 0.0]) if abs(up[2]) >= max(abs(up[0]), abs(up[1])) else np.array([0.0, 0.0, 1.0])
    a = hint - hint.dot(up) * up
    return _unit(a)


def view_direction(up, azimuth: float = AZIMUTH, elevation: float = ELEVATION) -> np.ndarray:
    """Unit vector from the scene towards the viewer of the 3d view."""
    up = _unit(up)
    a = horizontal_front(up)
    b = np.cross(up, a)
    return (math.cos(elevation) * (math.cos(azimuth) * a + math.sin(azimuth) * b) + math.sin(elevation) * up)


def screen_axes(view: str, up=DEFAULT_UP) -> np.ndarray:
    """(3, 3): rows screen right, screen up, towards the viewer (world axes) of a view."""
    up = _unit(up)
    if view in _PLANES:
        right, sup, toward = (np.array(v, float) for v in _PLANES[view])
        inplane = up - up.dot(toward) * toward
        if np.linalg.norm(inplane) > 1e-6:
            sup = _unit(inplane)
            right = np.cross(sup, toward)
        return np.array([right, sup, toward])
    d = view_direction(up)
    right = _unit(np.cross(up, d))
    return np.array([right, np.cross(d, right), d])
