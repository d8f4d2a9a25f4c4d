"""What is drawn and where it is: every drawn point of a model as ONE CasADi Function of
(t, q, p), evaluated mapped over all frames at once (``Function.map``).

A :class:`Geometry` lists drawables (``Item``), each owning a few columns of the (3, K) matrix
of world points the Function returns:

    rod       2 columns: its ends (centre -+ L/2 axis)              -> a thick bar
    solid     outline samples in body axes (disk, cylinder, box)   -> the filled outline (hull)
    ellipsoid 4 columns: the centre and the ends of the three semi-axes (the equivalent
              ellipsoid of a general body's inertia)               -> its exact projected ellipse
    sphere    1 column, its centre; ``radius``                      -> a circle
    point     1 column (a point mass, a body with no shape or inertia, a contact point with a radius)
    link      2 columns: a general body's frame origin and its centre of mass
    spring, damper   2 columns: the end points                      -> zig-zag / piston
    arm       2 columns: a joint's point on a shapeless body and the body (a massless string or rod)
    pin       1 column: a hinge's point (``ground`` when on the world)
    rail      1 column: a slider's moving point; its guide is drawn along its path
    hoop      a closed circle of samples fixed on a moving frame: the guide of a point mass
              hinged to that frame (the bead-on-hoop's hoop)
    plane     4 columns: a square patch of a contact plane          -> a line (2D) or patch (3D)
    ring      1 column + ``radius``: a spherical contact surface    -> a circle outline
    trace     1 column: a point whose path is drawn

The Function's second output places every body that carries a solid or a hoop (``posed``):
its frame origin and rotation matrix (12 rows a body), for the interactive 3-D view.  A body's
own shape sits at its centre of mass, oriented by ``ir.Body.axis``; ``Shape`` components
(``ir.Model.shapes``) sit where they are placed, on bodies, moving frames or the world
(:mod:`.shapes`, docs/animate.md); ``up`` is against gravity (:mod:`.camera`).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..model import ir
from ..diagnostics import UsageError, did_you_mean
from .camera import gravity_up
from .shapes import body_solids, circle_samples, circle_through, outline_samples, shape_solid

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
    function: object               # casadi Function (t, q, p) -> X (3, K), P (12, B)
    anchors: list[int]             # columns that move with the mechanism (plane detection)
    p: np.ndarray
    up: np.ndarray = field(default_factory=lambda: np.array([0.0, 1.0, 0.0]))
    posed: list[str] = field(default_factory=list)     # bodies whose pose is the second output

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
        X = np.array(f(t[None, :], np.asarray(Q, float).T, self.p)[0])   # (3, K n): frame blocks side by side
        return np.transpose(X.reshape(3, n, k), (1, 0, 2))

    def poses(self, t: np.ndarray, Q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Frame origins (N, B, 3) and rotation matrices (N, B, 3, 3) of the ``posed`` bodies."""
        t = np.asarray(t, float).ravel()
        n, b = len(t), len(self.posed)
        if n == 0 or b == 0:
            return np.zeros((n, b, 3)), np.zeros((n, b, 3, 3))
        out = np.array(self.function.map(n)(t[None, :], np.asarray(Q, float).T, self.p)[1])   # (12, B n)
        P = np.transpose(out.reshape(12, n, b), (1, 2, 0))                                # (N, B, 12)
        return P[:, :, :3], np.transpose(P[:, :, 3:].reshape(n, b, 3, 3), (0, 1, 3, 2))     # R stored by columns


def build(eom, p=None, traces=()) -> Geometry:
    """The drawables of ``eom.model`` and the one Function that places them."""
    p = np.asarray(eom.param_values if p is None else p, float).ravel()
    if eom.point_position is None or eom.model is None:
        return Geometry([], None, [], p)
    g = _Builder(eom, p)
    g.bodies()
    g.frames()
    g.springs()
    g.joints()
    for c in g.model.contacts:
        _contact_items(c, eom, g.env, g.num, g.add)
    g.traces(traces)
    return g.geometry()


class _Builder:
    """The drawables as they are added: ``cols`` (the symbolic points, 3 each), ``items`` (each
    with its slice of the points), ``anchors`` (points that move with the mechanism: the view's
    framing), and the bodies whose pose (origin, rotation) the Function returns."""

    def __init__(self, eom, p):
        import casadi as ca

        self.eom, self.model, self.p = eom, eom.model, p
        self.cols: list = []
        self.items: list[Item] = []
        self.anchors: list[int] = []
        self.env = _env(eom)
        self.shapes = tuple(getattr(self.model, "shapes", ()))
        self.rot = eom.body_rotation or (lambda name: ca.SX.eye(3))
        self.posed: list[str] = []
        self.poses: list = []
        self.contact_radius = _contact_radii(self.model, self.num)
        self.up = gravity_up([[self.num(c) for c in f.g] for f in self.model.forces if isinstance(f, ir.Gravity)])

    def num(self, e) -> float:                    # a size: its value for these parameters
        import casadi as ca

        sx = self.env.translate(e) if isinstance(e, ir.Expr) else ca.SX(float(e))
        return float(ca.Function("v", [self.eom.p], [sx])(self.p))

    def add(self, kind, name, pts, anchor=True, **kw) -> Item:
        start = len(self.cols)
        self.cols.extend(pts)
        if anchor:
            self.anchors.extend(range(start, len(self.cols)))
        it = Item(kind, name, slice(start, len(self.cols)), **kw)
        self.items.append(it)
        return it

    def pose(self, body: str) -> None:
        import casadi as ca

        if body not in self.posed:
            self.posed.append(body)
            self.poses.append(ca.vertcat(ca.reshape(self.eom.point_position(body), 3, 1),
                                         ca.reshape(self.rot(body), 9, 1)))

    def to_world(self, body: str):
        """Body axes -> world of ``body``: r -> o + R r."""
        import casadi as ca

        o = ca.reshape(self.eom.point_position(body), 3, 1)
        R = self.rot(body)
        return lambda r, o=o, R=R: o + ca.mtimes(R, ca.DM(r))

    def add_solid(self, body: str, solid, world, moving: bool = True) -> None:
        """One drawable for a solid of ``body`` (body axes -> world by ``world``)."""
        add = self.add
        if solid.kind == "rod":
            h = 0.5 * solid.size[0] * solid.rot[:, 2]
            add("rod", body, [world(solid.center - h), world(solid.center + h)], anchor=moving, body=body,
                extra={"solid": solid})
        elif solid.kind == "sphere":
            add("sphere", body, [world(solid.center)], anchor=moving, radius=solid.size[0], body=body,
                extra={"solid": solid})
        elif solid.kind == "ellipsoid":
            tips = [solid.center + solid.rot[:, i] * solid.size[i] for i in range(3)]
            add("ellipsoid", body, [world(solid.center)] + [world(r) for r in tips], anchor=False, body=body,
                extra={"solid": solid})
            if moving:
                self.anchors.append(len(self.cols) - 4)          # the centre moves with the mechanism
        else:
            add("solid", body, [world(r) for r in outline_samples(solid)], anchor=False, body=body,
                extra={"solid": solid})

    def bodies(self) -> None:
        """Each moving body: its solids (or a point / contact sphere at its centre of mass), and
        the link from its frame to its centre for a general rigid body drawn by nothing else."""
        import casadi as ca

        add, shapes = self.add, self.shapes
        for b in self.model.bodies:
            if b.kind in ("world", "frame"):
                continue
            o = ca.reshape(self.eom.point_position(b.name), 3, 1)
            world = self.to_world(b.name)
            solids = body_solids(b, shapes, self.num)
            com = np.array([self.num(c) for c in b.com])
            if solids:
                self.pose(b.name)
            for solid in solids:
                self.add_solid(b.name, solid, world)
            if any(s.kind in ("box", "disk", "cylinder") for s in solids):   # (an outline is not an anchor)
                add("point", b.name + ".com", [world(com)], body=b.name, radius=0.0, extra={"hidden": True})
            if not solids:
                r = self.contact_radius.get(b.name, 0.0)
                add("sphere" if r > 0 else "point", b.name, [world(com)], radius=r, body=b.name)
            drawn = b.shape or any(sh.body == b.name for sh in shapes)
            if b.kind == "rigid" and not drawn and np.linalg.norm(com) > 0:   # a general body: its frame to its centre
                add("link", b.name + ".frame", [o, world(com)], body=b.name)

    def frames(self) -> None:
        """Shapes on the world (fixed) and on moving frames."""
        for name in ["world"] + [b.name for b in self.model.bodies if b.kind == "frame"]:
            placed = [s for s in (shape_solid(sh, self.num) for sh in self.shapes if sh.body == name) if s is not None]
            if not placed:
                continue
            self.pose(name)
            world = self.to_world(name)
            for solid in placed:
                self.add_solid(name, solid, world, moving=name != "world")

    def springs(self) -> None:
        pos = self.eom.point_position
        for f in self.model.forces:
            if isinstance(f, ir.SpringDamper):
                self.add("damper" if f.kind == "damper" else "spring", f.name, [pos(f.a), pos(f.b)])

    def joints(self) -> None:
        """Hoops (a bead's circle), massless arms to a body, pins and rails."""
        import casadi as ca

        model, eom, add, pos = self.model, self.eom, self.add, self.eom.point_position
        shaped = {b.name for b in model.bodies if b.shape} | {sh.body for sh in self.shapes}
        hoops = _hoops(model, eom, self.p)
        for j in model.joints:
            if j.name in hoops:
                centre, normal, radius = hoops[j.name]
                o = ca.reshape(pos(j.parent_body), 3, 1)
                R = self.rot(j.parent_body)
                self.pose(j.parent_body)
                add("hoop", j.name, [o + ca.mtimes(R, ca.DM(r)) for r in circle_samples(centre, normal, radius)],
                    anchor=False, body=j.parent_body, radius=radius, extra={"center": centre, "normal": normal})
            elif j.child != j.child_body and j.child_body not in shaped:     # a massless arm to the body
                add("arm", j.name, [pos(j.child), pos(j.child_body)])
            if j.kind in PINNED:
                add("pin", j.name, [pos(j.parent)], extra={"ground": j.parent_body == "world"})
            elif j.kind in ("prismatic", "cylindrical") and j.parent_body == "world":
                add("rail", j.name, [pos(j.child)])

    def traces(self, names) -> None:
        """The points whose paths are drawn (--trail)."""
        known = [pt.name for pt in self.model.points]
        for name in names:
            if name not in known:
                hint = did_you_mean(name, known)
                raise UsageError(f"--trail: no point named '{name}' in {self.model.name}"
                                 + (f"; {hint}" if hint else f" (points: {', '.join(known[:12])}"
                                                              + (", ..." if len(known) > 12 else "") + ")"))
            self.add("trace", name, [self.eom.point_position(name)])

    def geometry(self) -> Geometry:
        import casadi as ca

        if not self.cols:
            return Geometry([], None, [], self.p, self.up)
        eom = self.eom
        X = ca.horzcat(*[ca.reshape(c, 3, 1) for c in self.cols])
        P = ca.horzcat(*self.poses) if self.poses else ca.SX.zeros(12, 0)
        fn = ca.Function("draw", [eom.t, eom.q, eom.p], [X, P], ["t", "q", "p"], ["X", "P"])
        return Geometry(self.items, fn, self.anchors, self.p, self.up, self.posed)


def _env(eom):
    """Translation of sizes, normals and offsets (parameters, positions of points) to CasADi.
    (Not impacts.gaps._env: importing the impacts package costs seconds of scipy.optimize.)"""
    from ..model import exprs as X

    def query(n):
        if isinstance(n, ir.PointPos):
            return eom.point_position(n.point)[n.i]
        raise ValueError(f"{X.to_text(n)} cannot size a drawing (positions only)")

    return X.CasadiEnv(tuple(eom.coords), tuple(eom.params), eom.q, eom.qd, eom.t, eom.p, query)


def _hoops(model, eom, p) -> dict[str, tuple]:
    """Hinges that hold a point mass on a circle carried by a moving frame (a bead on a hoop):
    joint name -> (centre, normal, radius) of the circle in the frame's axes.  Found from the
    mass's position in the frame at three values of the hinge's coordinate, so it needs no
    convention of the joint's axes; hinges on the world or on bodies keep their arm (a pendulum)."""
    import casadi as ca

    found: dict[str, tuple] = {}
    kinds = {b.name: b.kind for b in model.bodies}
    coords = list(eom.coords)
    for j in model.joints:
        if j.kind != "revolute" or kinds.get(j.parent_body) != "frame" or kinds.get(j.child_body) != "point":
            continue
        var = next((v.coordinate for v in j.variables if v.coordinate in coords), None)
        if var is None or eom.body_rotation is None:
            continue
        rel = ca.mtimes(eom.body_rotation(j.parent_body).T,
                        ca.reshape(eom.point_position(j.child_body) - eom.point_position(j.parent_body), 3, 1))
        f = ca.Function("rel", [eom.t, eom.q, eom.p], [rel])
        q0 = np.asarray(eom.start()[0], float)
        i = coords.index(var)
        pts = []
        for k in range(3):
            q = q0.copy()
            q[i] += 2 * np.pi * k / 3
            pts.append(np.array(f(0.0, q, p)).ravel())
        circle = circle_through(*pts)
        if circle is not None and circle[2] > 0:
            found[j.name] = circle
    return found


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
