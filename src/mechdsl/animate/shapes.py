"""What a body looks like: its declared shape, else the uniform ellipsoid with its mass and
inertia (so a general ``Body`` such as the heavy top shows its real proportions).

A :class:`Solid` is a shape in the body's axes: ``kind`` (rod, disk, cylinder, box, sphere,
ellipsoid), ``size`` (rod (L,), disk (R,), cylinder (R, L), box (lx, ly, lz), sphere (R,),
ellipsoid its semi-axes (a, b, c)), ``center`` (its centre, body axes, from the body origin)
and ``rot`` (3x3, its own axes as columns in body axes; the symmetry axis of rods, disks and
cylinders is the third column, a box's edges lie along the three).

A body is drawn with its own shape (``Body(shape = ...)``: at its centre of mass, the axis in
body axes, a box along the body's axes) and every ``Shape`` component placed on it (centre
``r``, axes ``R`` or ``rpy``, the axis in the shape's own axes); a rigid body with neither is
drawn as its equivalent ellipsoid.

The equivalent ellipsoid: a uniform solid ellipsoid of mass m and semi-axes a, b, c has the
principal moments m (b^2 + c^2)/5, m (a^2 + c^2)/5, m (a^2 + b^2)/5, so from the principal
moments I1, I2, I3 of the body (about its centre of mass)
    a^2 = 5 (I2 + I3 - I1) / (2 m),  and cyclically,
along the principal axes.  A semi-axis that the moments make zero or negative (a flat or
rounded-off tensor) is drawn thin: 5% of the largest.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

RIM = 24                      # samples on a disk's rim


@dataclass
class Solid:
    kind: str
    size: tuple
    center: np.ndarray
    rot: np.ndarray
    name: str = ""                # the Shape component it draws ("": the body's own shape)


def frame_from_axis(axis) -> np.ndarray:
    """A right-handed frame whose third column is ``axis`` (unit)."""
    a = np.asarray(axis, float)
    a = a / (np.linalg.norm(a) or 1.0)
    u = np.cross(a, [0.0, 0.0, 1.0]) if abs(a[2]) < 0.9 else np.cross(a, [1.0, 0.0, 0.0])
    u /= np.linalg.norm(u)
    return np.column_stack([u, np.cross(a, u), a])


def equivalent_ellipsoid(mass: float, inertia) -> tuple[np.ndarray, np.ndarray] | None:
    """(semi-axes (3,), principal axes as columns (3, 3)) of the uniform ellipsoid with this mass
    and inertia tensor about the centre of mass; None when there is nothing to draw."""
    I = np.asarray(inertia, float)
    I = 0.5 * (I + I.T)
    if not (mass > 0 and np.all(np.isfinite(I))) or np.abs(I).max() <= 0:
        return None
    moments, axes = np.linalg.eigh(I)
    s = moments.sum()
    sq = 5.0 * (s - 2.0 * moments) / (2.0 * mass)          # I2 + I3 - I1 = trace - 2 I1
    top = max(float(sq.max()), 0.0)
    if top <= 0:
        return None
    semi = np.sqrt(np.maximum(sq, (0.05 ** 2) * top))
    if np.linalg.det(axes) < 0:
        axes[:, 2] = -axes[:, 2]
    return semi, axes


def body_solids(b, shapes, num) -> list[Solid]:
    """The Solids of an ir.Body: its own shape and the ``Shape`` components placed on it
    (``shapes``: the model's ir.Shape records, those of other bodies ignored); a rigid body
    with neither is drawn as its equivalent ellipsoid."""
    own = [s for s in [_solid(b.shape, b.shape_size, np.array([num(c) for c in b.com]), np.eye(3), b.axis, num)]
           if s is not None]
    placed = [s for s in (shape_solid(sh, num) for sh in shapes if sh.body == b.name) if s is not None]
    if own or placed or any(sh.body == b.name for sh in shapes):
        return own + placed
    ellipsoid = body_solid(b, num)
    return [ellipsoid] if ellipsoid is not None else []


def shape_solid(sh, num) -> Solid | None:
    """The Solid of an ir.Shape: centred at ``r``, its axes ``R`` (body axes)."""
    R = np.eye(3) if sh.R is None else np.array([[num(x) for x in row] for row in sh.R])
    solid = _solid(sh.kind, sh.size, np.array([num(c) for c in sh.r]), R, sh.axis, num)
    if solid is not None:
        solid.name = sh.name
    return solid


def _solid(kind: str, size_exprs, center: np.ndarray, R: np.ndarray, axis, num) -> Solid | None:
    """A shape of a kind and size, centred at ``center``, in axes R (body axes); the symmetry axis
    of a rod, disk or cylinder is ``axis`` in those axes; a box's edges lie along them."""
    size = tuple(num(s) for s in size_exprs)
    if not kind or not size:
        return None
    if kind in ("rod", "disk", "cylinder"):
        if kind == "cylinder" and len(size) < 2:
            size = (size[0], size[0])
        return Solid(kind, size, center, R @ frame_from_axis(np.array([num(a) for a in axis])))
    if kind == "box":
        return Solid("box", (size + (size[-1],) * 3)[:3], center, R)
    if kind == "sphere":
        return Solid("sphere", size[:1], center, R)
    return None


def body_solid(b, num) -> Solid | None:
    """The Solid of an ir.Body: its declared shape, else its equivalent ellipsoid."""
    com = np.array([num(c) for c in b.com])
    solid = _solid(b.shape, b.shape_size, com, np.eye(3), b.axis, num)
    if solid is not None:
        return solid
    if b.kind == "rigid" and not b.shape:
        I = np.array([[num(x) for x in row] for row in b.inertia])
        found = equivalent_ellipsoid(num(b.mass), I)
        if found is not None:
            semi, axes = found
            return Solid("ellipsoid", tuple(float(v) for v in semi), com, axes)
    return None


def outline_samples(s: Solid) -> list[np.ndarray]:
    """Body-axes points whose projected convex hull outlines the solid (a disk's rim, a
    cylinder's two rims, a box's corners)."""
    if s.kind == "box":
        lx, ly, lz = s.size
        local = [np.array([sx * lx, sy * ly, sz * lz]) / 2 for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)]
    else:
        R = s.size[0]
        rim = [np.array([R * math.cos(a), R * math.sin(a), 0.0]) for a in (2 * math.pi * k / RIM for k in range(RIM))]
        if s.kind == "disk":
            local = rim
        else:
            h = np.array([0.0, 0.0, 0.5 * s.size[1]])
            local = [r - h for r in rim] + [r + h for r in rim]
    return [s.center + s.rot @ r for r in local]


def circle_through(p1, p2, p3) -> tuple[np.ndarray, np.ndarray, float] | None:
    """(centre, unit normal, radius) of the circle through three points; None if they are in a line."""
    a, b = p2 - p1, p3 - p1
    n = np.cross(a, b)
    nn = float(n.dot(n))
    if nn <= 1e-24 * max(float(a.dot(a) * b.dot(b)), 1e-300):
        return None
    c = p1 + (np.cross(n, a) * b.dot(b) + np.cross(b, n) * a.dot(a)) / (2.0 * nn)
    return c, n / math.sqrt(nn), float(np.linalg.norm(p1 - c))


def circle_samples(center, normal, radius, n: int = 48) -> list[np.ndarray]:
    """n + 1 points around a circle (closed: the first point repeated)."""
    F = frame_from_axis(normal)
    return [center + radius * (math.cos(a) * F[:, 0] + math.sin(a) * F[:, 1])
            for a in (2 * math.pi * k / n for k in range(n + 1))]
