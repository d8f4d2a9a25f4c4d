"""What is drawn and where it is: every drawn point of a model as ONE CasADi Function of
(t, q, p), evaluated mapped over all frames at once (``Function.map``).

A :class:`Geometry` lists drawables (``Item``), each owning a few columns of the (3, K) matrix
of world points the Function returns:

    rod       2 columns: its ends (centre -+ L/2 axis)              -> a thick bar
    disk, cylinder, box   rim / corner samples in body axes         -> the filled outline (hull)
    sphere    1 column, its centre; ``radius``                      -> a circle
    point     1 column (a point mass, a body without a shape, a contact point with a radius)
    spring, damper   2 columns: the end points                      -> zig-zag / piston
    arm       2 columns: a joint's point on a shapeless body and the body (a massless string or rod)
    pin       1 column: a hinge's point (``ground`` when on the world)
    rail      1 column: a slider's moving point; its guide is drawn along its path
    plane     4 columns: a square patch of a contact plane          -> a line (2D) or patch (3D)
    ring      1 column + ``radius``: a spherical contact surface    -> a circle outline
    trace     1 column: a point whose path is drawn

Shapes sit at the body's centre of mass, oriented by ``ir.Body.axis`` (docs/animate.md).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from ..model import ir
from ..diagnostics import UsageError, did_you_mean

RIM = 24                      # samples on a disk's rim
PINNED = ("revolute", "spherical", "cylindrical", "universal")   # joints drawn as pins


@dataclass
class Item:
    kind: str
    name: str
    cols: slice
    radius: float = 0.0
    body: str = ""
    extra: dict = field(default_factory=dict)


@dataclass
class Geometry:
    items: list[Item]
    function: object               # casadi Function (t, q, p) -> X (3, K)
    anchors: list[int]             # columns that move with the mechanism (plane detection)
    p: np.ndarray

    @property
    def empty(self) -> bool:
        return not any(it.kind not in ("plane", "ring") for it in self.items)

    def positions(self, t: np.ndarray, Q: np.ndarray) -> np.ndarray:
        """World positions of every column at every sample: (N, 3, K), one mapped call."""
        t = np.asarray(t, float).ravel()
        n = len(t)
        k = self.function.size2_out(0)
        if n == 0:
            return np.zeros((0, 3, k))
        f = self.function.map(n)
        X = np.array(f(t[None, :], np.asarray(Q, float).T, self.p))      # (3, K n): frame blocks side by side
        return np.transpose(X.reshape(3, n, k), (1, 0, 2))


def build(eom, p=None, traces=()) -> Geometry:
    """The drawables of ``eom.model`` and the one Function that places them."""
    import casadi as ca

    from ..impacts.gaps import _env

    model: ir.Model = eom.model
    p = np.asarray(eom.param_values if p is None else p, float).ravel()
    cols: list = []
    items: list[Item] = []
    anchors: list[int] = []
    has_points = eom.point_position is not None and model is not None
    env = _env(eom) if has_points else None

    def num(e) -> float:                          # a size: its value for these parameters
        sx = env.translate(e) if isinstance(e, ir.Expr) else ca.SX(float(e))
        return float(ca.Function("v", [eom.p], [sx])(p))

    def add(kind, name, pts, anchor=True, **kw) -> Item:
        start = len(cols)
        cols.extend(pts)
        if anchor:
            anchors.extend(range(start, len(cols)))
        it = Item(kind, name, slice(start, len(cols)), **kw)
        items.append(it)
        return it

    if not has_points:
        return Geometry([], None, [], p)
    contact_radius = _contact_radii(model, num)
    rot = eom.body_rotation
    for b in model.bodies:
        if b.kind in ("world", "frame"):
            continue
        o = ca.reshape(eom.point_position(b.name), 3, 1)
        R = rot(b.name) if rot is not None else ca.SX.eye(3)
        com = ca.vertcat(*[env.translate(c) for c in b.com])
        axis = np.array([num(a) for a in b.axis])
        axis = axis / (np.linalg.norm(axis) or 1.0)
        size = [num(s) for s in b.shape_size]
        world = lambda r: o + ca.mtimes(R, com + ca.DM(r))  # noqa: E731
        if b.shape == "rod" and size:
            h = 0.5 * size[0] * axis
            add("rod", b.name, [world(-h), world(h)], body=b.name)
        elif b.shape in ("disk", "cylinder", "box") and size:
            local = _samples(b.shape, size, axis)
            add("solid", b.name, [world(r) for r in local], anchor=False, body=b.name)
            anchors.append(len(cols))
            add("point", b.name + ".com", [world(np.zeros(3))], body=b.name, radius=0.0,
                extra={"hidden": True})
        elif b.shape == "sphere" and size:
            add("sphere", b.name, [world(np.zeros(3))], radius=size[0], body=b.name)
        else:
            r = contact_radius.get(b.name, 0.0)
            kind = "sphere" if r > 0 else "point"
            add(kind, b.name, [world(np.zeros(3))], radius=r, body=b.name)
            if b.kind == "rigid" and not b.shape:          # a general body: its frame to its centre
                add("link", b.name + ".frame", [o, world(np.zeros(3))], body=b.name)
    for f in model.forces:
        if isinstance(f, ir.SpringDamper):
            add("damper" if f.kind == "damper" else "spring", f.name,
                [eom.point_position(f.a), eom.point_position(f.b)])
    shaped = {b.name for b in model.bodies if b.shape}
    for j in model.joints:
        if j.child != j.child_body and j.child_body not in shaped:     # a massless arm to the body
            add("arm", j.name, [eom.point_position(j.child), eom.point_position(j.child_body)])
        if j.kind in PINNED:
            add("pin", j.name, [eom.point_position(j.parent)], extra={"ground": j.parent_body == "world"})
        elif j.kind in ("prismatic", "cylindrical") and j.parent_body == "world":
            add("rail", j.name, [eom.point_position(j.child)])
    for c in model.contacts:
        _contact_items(c, eom, env, num, add)
    for name in traces:
        known = [pt.name for pt in model.points]
        if name not in known:
            hint = did_you_mean(name, known)
            raise UsageError(f"--trail: no point named '{name}' in {model.name}"
                             + (f"; {hint}" if hint else f" (points: {', '.join(known[:12])}"
                                                          + (", ..." if len(known) > 12 else "") + ")"))
        add("trace", name, [eom.point_position(name)])
    if not cols:
        return Geometry([], None, [], p)
    X = ca.horzcat(*[ca.reshape(c, 3, 1) for c in cols])
    fn = ca.Function("draw", [eom.t, eom.q, eom.p], [X], ["t", "q", "p"], ["X"])
    return Geometry(items, fn, anchors, p)


def _contact_radii(model, num) -> dict[str, float]:
    """Point masses that a contact gives a radius: drawn as balls of that radius."""
    out: dict[str, float] = {}
    for c in model.contacts:
        pt = c.get("point")
        if isinstance(pt, str) and c.get("radius") is not None:
            try:
                body = model.point(pt).body
            except KeyError:
                continue
            out[body] = max(out.get(body, 0.0), num(c.get("radius")))
        ctr = c.get("center")
        if c.get("surface") == "point" and isinstance(ctr, str) and c.get("surface_radius") is not None:
            try:
                body = model.point(ctr).body
            except KeyError:
                continue
            out[body] = max(out.get(body, 0.0), num(c.get("surface_radius")))
    return out


def _contact_items(c, eom, env, num, add) -> None:
    import casadi as ca

    surface = c.get("surface", c.kind)
    if c.get("gap") is not None or surface not in ("plane", "sphere"):
        return
    if surface == "plane":
        n = np.array([num(x) for x in (c.get("normal") or (ir.ZERO, ir.ONE, ir.ZERO))])
        n = n / (np.linalg.norm(n) or 1.0)
        off = num(c.get("offset") or 0.0)
        u = np.cross(n, [0.0, 0.0, 1.0])
        if np.linalg.norm(u) < 1e-9:
            u = np.cross(n, [1.0, 0.0, 0.0])
        u = u / np.linalg.norm(u)
        v = np.cross(n, u)
        base = n * off
        add("plane", c.name, [ca.DM(base + a * u + b * v) for a, b in ((-1, -1), (1, -1), (1, 1), (-1, 1))],
            anchor=False, extra={"normal": n, "u": u, "v": v, "base": base})
        return
    center = c.get("center") or "world"
    add("ring", c.name, [eom.point_position(center)], anchor=False, radius=num(c.get("surface_radius") or 0.0))


def _samples(shape: str, size: list[float], axis: np.ndarray) -> list[np.ndarray]:
    """Body-axes points whose projected hull outlines the shape (centred at the centre of mass)."""
    if shape == "box":
        lx, ly, lz = (size + [size[-1]] * 3)[:3]
        return [np.array([sx * lx, sy * ly, sz * lz]) / 2 for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)]
    u = np.cross(axis, [0.0, 0.0, 1.0]) if abs(axis[2]) < 0.9 else np.cross(axis, [1.0, 0.0, 0.0])
    u /= np.linalg.norm(u)
    v = np.cross(axis, u)
    R = size[0]
    angles = [2 * math.pi * k / RIM for k in range(RIM)]
    rim = [R * (math.cos(a) * u + math.sin(a) * v) for a in angles]
    if shape == "disk":
        return rim
    h = 0.5 * (size[1] if len(size) > 1 else R) * axis
    return [r - h for r in rim] + [r + h for r in rim]
