"""The resolved model ("model" IR): what ``analyze`` hands to ``derive``.

A flat, fully resolved description of one model: no `extends`, no arrays, no `for` loops,
no modifiers left.  Every name is a flat string (``link[2].b``, ``q[3]``, ``j1.phi``).
Vector and matrix quantities are tuples of scalar expressions (a vector is a 3-tuple, a
matrix a 3-tuple of 3-tuples), so every :class:`Expr` is a scalar.

Expressions are small frozen dataclasses (made by :func:`mechdsl.model.records.record`, which builds
them cheaply).  Leaves refer to the model's parameters
(:class:`Param`), generalized coordinates (:class:`Coord`), their speeds (:class:`Speed`,
i.e. ``der(q)``) and :class:`Time`.  Kinematic queries (:class:`PointPos`, ...) and
energies (:class:`EnergyRef`) are leaves that ``derive`` replaces by the expressions it
computes.  Translators to CasADi and sympy live in :mod:`mechdsl.model.exprs`.

Conventions (documented in docs/language.md):
- world frame: x right, y up, z out of the plane; gravity is whatever Gravity says.
- every body has a body frame; ``com`` is the centre of mass in body coordinates and
  ``inertia`` the inertia tensor about the centre of mass in body axes.
- a joint places a joint frame on the parent (at ``parent`` point, with the axes ``parent_R``
  in parent body coordinates, default the body's axes) and one on the child (at ``child``
  point, axes ``child_R`` in child body coordinates).  At zero joint variables the two joint
  frames coincide; the joint's motion is the child joint frame relative to the parent one.
  ``axis`` is a unit vector in those (coinciding) axes.
  With (R_j, p_j) the joint's relative rotation and translation, P = parent_R, C = child_R
  (identity when None), the child body's pose is
      R_child = R_parent P R_j C^T,   o_child = o_parent + R_parent (r_P + P p_j) - R_child r_C
  where r_P is the parent point in parent body coordinates and r_C the child point in
  child body coordinates.  Per kind:
      revolute     R_j = rot(axis, phi),            p_j = 0
      prismatic    R_j = I,                         p_j = s axis
      cylindrical  R_j = rot(axis, phi),            p_j = s axis
      planar       R_j = rot(axis, phi),            p_j = x e1 + y e2   (plane_axes = (e1, e2))
      spherical    R_j = Euler(sequence; phi, theta, psi), intrinsic: 'zyx' -> Rz(phi) Ry(theta) Rx(psi)
                   or a unit quaternion (option parametrization = 'quaternion', variables q0..q3)
      free         p_j = (x, y, z) in parent axes, R_j as spherical
      fixed        R_j = I, p_j = 0
      frame        R_j = frame_R(t), p_j = frame_r(t)     (a prescribed moving frame)
  A point-mass child has no rotational freedom: free keeps (x, y, z), planar keeps (x, y).
"""
from __future__ import annotations

from dataclasses import field
from typing import Iterator, Union

from ..diagnostics import Span
from .records import record

# --------------------------------------------------------------------------- expressions


@record
class Expr:
    pass


@record
class Const(Expr):
    value: float


@record
class Param(Expr):
    name: str


@record
class Coord(Expr):
    name: str


@record
class Speed(Expr):
    """der(coordinate)."""

    name: str


@record
class Time(Expr):
    pass


@record
class Op(Expr):
    """An operation on scalar arguments.

    op is one of: add sub mul div pow neg (arithmetic); lt le gt ge eq ne and or not
    (logic, 1.0/0.0); if (cond, a, b); and the math functions sin cos tan asin acos atan
    atan2 sinh cosh tanh exp log log10 sqrt abs sign min max floor ceil.
    """

    op: str
    args: tuple[Expr, ...]


@record
class TimeDer(Expr):
    """der(expr) of an expression in coordinates and time (not speeds): total derivative."""

    expr: Expr


@record
class PointPos(Expr):
    """Component i (0, 1, 2) of a point's position in world coordinates."""

    point: str
    i: int


@record
class PointVel(Expr):
    """Component i of a point's absolute velocity in world coordinates."""

    point: str
    i: int


@record
class BodyRot(Expr):
    """Entry (i, j) of a body's rotation matrix (body axes -> world axes)."""

    body: str
    i: int
    j: int


@record
class BodyOmega(Expr):
    """Component i of a body's angular velocity in world coordinates (frame "world", the
    attribute ``b.w``) or in body coordinates (frame "body", ``b.w_body``)."""

    body: str
    i: int
    frame: str = "world"


@record
class PointAcc(Expr):
    """Component i of a point's absolute acceleration in world coordinates (``p.a``): it needs
    the forward dynamics, so it may appear in outputs only."""

    point: str
    i: int


@record
class BodyAlpha(Expr):
    """Component i of a body's angular acceleration in world coordinates (``b.alpha``; outputs
    only, like PointAcc)."""

    body: str
    i: int


@record
class EnergyRef(Expr):
    """kind: 'kinetic' | 'potential' | 'dissipation' | 'energy' (T + V)."""

    kind: str


@record
class ReactionRef(Expr):
    """Reaction of a joint on its child, in the child joint frame.

    what: 'force' | 'torque'; i: component.  Computed only when an output asks for it.
    """

    joint: str
    what: str
    i: int


@record
class ConstraintLoad(Expr):
    """Component i of the force ('force') or torque ('torque') that a constraint exerts on a
    body, in world axes, at the point where it acts (``constraint_force(c, body)``, issue 23).

    ``constraint``: an explicit constraint's name, or a loop-closing joint.  In the multipliers
    EOM.lam: computed only when an output asks for it (constrained runs record the multipliers)."""

    constraint: str
    body: str
    what: str
    i: int


Vec3 = tuple[Expr, Expr, Expr]
Mat3 = tuple[Vec3, Vec3, Vec3]

ZERO = Const(0.0)
ONE = Const(1.0)

# --------------------------------------------------------------------------- traversal


def children(e: Expr) -> tuple[Expr, ...]:
    if isinstance(e, Op):
        return e.args
    if isinstance(e, TimeDer):
        return (e.expr,)
    return ()


def walk(e: Expr) -> Iterator[Expr]:
    """Every node of e, pre-order (iterative: deep expressions are fine)."""
    stack = [e]
    while stack:
        n = stack.pop()
        yield n
        stack.extend(reversed(children(n)))


def depends_on_state(e: Expr) -> bool:
    """True when e depends on coordinates, speeds or kinematic queries (not only t, p)."""
    return any(isinstance(n, (Coord, Speed, PointPos, PointVel, BodyRot, BodyOmega, EnergyRef,
                              ReactionRef, TimeDer, PointAcc, BodyAlpha, ConstraintLoad)) for n in walk(e))


# --------------------------------------------------------------------------- declarations


@record
class Parameter:
    name: str
    value: float                     # numeric default (after evaluating the binding)
    binding: Expr | None = None      # expression in other Params (dependent parameter)
    unit: str | None = None
    doc: str = ""
    integer: bool = False            # Integer parameters are structural: already substituted
    span: Span = field(default_factory=Span)
    input: bool = False              # declared `input`: a control input u (value = its default)
    min: float | None = None         # declared bounds (inputs: checked on the driving signal)
    max: float | None = None


@record
class Coordinate:
    name: str
    start: Expr = ZERO               # in Params only
    speed: Expr = ZERO               # start value of der(name), in Params only
    fixed: bool = True               # start value fixed for consistent initialization
    speed_fixed: bool = True
    unit: str | None = None
    doc: str = ""
    owner: str | None = None         # joint that declared it, if any
    span: Span = field(default_factory=Span)


@record
class Body:
    name: str
    kind: str                        # 'point' | 'rigid' | 'frame' (massless) | 'world'
    mass: Expr = ZERO
    com: Vec3 = (ZERO, ZERO, ZERO)
    inertia: Mat3 = ((ZERO,) * 3,) * 3
    shape: str = ""                  # 'rod' | 'disk' | 'cylinder' | 'sphere' | 'box' | '' (for drawing)
    shape_size: tuple[Expr, ...] = ()  # rod: (L,), disk: (R,), cylinder: (R, L), sphere: (R,), box: (lx, ly, lz)
    axis: Vec3 = (ONE, ZERO, ZERO)   # symmetry axis of the shape, body coordinates
    span: Span = field(default_factory=Span)
    measured: bool = False           # `measured_inertia = true`: the triangle inequality is not judged


@record
class Shape:
    """A shape drawn on a body (the component ``Shape``; drawing only, no mass).

    kind: 'box' | 'cylinder' | 'sphere' | 'disk' | 'rod'; size as for ``Body.shape_size``.
    Centred at ``r`` (body coordinates); its own axes are ``R`` in body axes (None: the body's);
    ``axis`` is the symmetry axis of a cylinder, disk or rod in its own axes (a box's edges lie
    along its own x, y, z)."""

    name: str
    body: str
    kind: str
    size: tuple[Expr, ...] = ()
    r: Vec3 = (ZERO, ZERO, ZERO)
    R: Mat3 | None = None
    axis: Vec3 = (ZERO, ZERO, ONE)
    span: Span = field(default_factory=Span)


@record
class Point:
    """A point fixed on a body (or on 'world'), position r in body coordinates.

    R (None: the body's axes) orients the point's own axes: a point with R is a frame fixed on
    the body, R its axes in body coordinates (body <- point).  Joints at the point use them."""

    name: str
    body: str
    r: Vec3 = (ZERO, ZERO, ZERO)
    span: Span = field(default_factory=Span)
    R: Mat3 | None = None


@record
class JointVar:
    """One joint variable.

    role: the joint's name for it ('phi', 's', 'x', 'y', 'z', 'theta', 'psi', ...).
    motion: its value as an expression: ``Coord(c)`` when bound one-to-one to coordinate c
    (then ``coordinate == c``), a function of Time and Params when prescribed (rheonomic),
    or a general expression of coordinates and time.
    """

    role: str
    motion: Expr
    coordinate: str | None = None

    @property
    def prescribed(self) -> bool:
        return self.coordinate is None and not depends_on_state(self.motion)


def plane_basis(normal) -> tuple[tuple[float, float, float], tuple[float, float, float]]:
    """The in-plane axes (e1, e2) of a planar joint with the unit ``normal`` (numbers), e1 x e2 =
    normal.  For a coordinate axis +-e_k: e1 = the lowest-numbered other axis (normal z: x, y;
    normal x: y, z; normal y: x, -z).  Any other normal takes the basis of its nearest coordinate
    axis (largest |n_k|) turned by the smallest rotation that carries that axis onto it, so the
    basis moves continuously as the normal tilts (a normal {1e-3, 0, 1} keeps e1 ~ x, e2 ~ y)."""
    n = [float(x) for x in normal]
    k = max(range(3), key=lambda i: (abs(n[i]), -i))
    s = 1.0 if n[k] > 0 else -1.0
    n0 = [s if i == k else 0.0 for i in range(3)]
    b = [1.0 if i == (1 if k == 0 else 0) else 0.0 for i in range(3)]

    def cross(a, c):
        return [a[1] * c[2] - a[2] * c[1], a[2] * c[0] - a[0] * c[2], a[0] * c[1] - a[1] * c[0]]

    # R b with R = I + [v]x + [v]x^2 / (1 + c), v = n0 x n, c = n0 . n (> 0: n0 is the nearest axis)
    v, c = cross(n0, n), sum(x * y for x, y in zip(n0, n))
    vb = cross(v, b)
    e1 = [b[i] + vb[i] + cross(v, vb)[i] / (1.0 + c) for i in range(3)]
    d = sum(x * y for x, y in zip(e1, n))                 # remove round-off off the plane, unit length
    e1 = [x - d * y for x, y in zip(e1, n)]
    r = sum(x * x for x in e1) ** 0.5
    e1 = [x / r for x in e1]
    e2 = cross(n, e1)
    clean = lambda w: tuple(0.0 if abs(x) < 1e-15 else x for x in w)  # noqa: E731
    return clean(e1), clean(e2)  # type: ignore[return-value]


@record
class Joint:
    """kind: revolute prismatic cylindrical spherical planar free fixed frame.

    variables in the joint's canonical order:
      revolute (phi) | prismatic (s) | cylindrical (phi, s) | planar (x, y, phi)
      spherical: Euler angles (phi, theta, psi) in `sequence` (e.g. 'zyx', 'zxz')
      free: (x, y, z, phi, theta, psi); for a point-mass child only (x, y, z)
      fixed: () | frame: () with `frame_r` (Vec3 of t) and `frame_R` (Mat3 of t)
    For planar joints the plane is normal to ``axis``; its in-plane axes are ``plane_axes``.
    options: 'sequence' (Euler sequence), 'parametrization' ('euler' | 'quaternion').
    """

    name: str
    kind: str
    parent: str                      # point name
    child: str                       # point name
    parent_body: str
    child_body: str
    axis: Vec3 = (ZERO, ZERO, ONE)
    variables: tuple[JointVar, ...] = ()
    plane_axes: tuple[Vec3, Vec3] | None = None
    frame_r: Vec3 | None = None
    frame_R: Mat3 | None = None
    options: tuple[tuple[str, str], ...] = ()
    closes_loop: bool = False        # set by topology: a cut joint; its variables are then () and its
                                     # loop-closure constraint removes only the joint's free directions
    span: Span = field(default_factory=Span)
    parent_R: Mat3 | None = None     # axes of the parent joint frame in parent body axes (None: the same)
    child_R: Mat3 | None = None      # axes of the child joint frame in child body axes (None: the same)

    def option(self, key: str, default: str = "") -> str:
        return dict(self.options).get(key, default)


# --------------------------------------------------------------------------- forces and terms


@record
class Gravity:
    name: str
    g: Vec3
    span: Span = field(default_factory=Span)


@record
class SpringDamper:
    """A linear spring and/or damper between points a and b (force along the line).

    Spring potential k/2 (l - l0)^2; damper force -c dl/dt along the line (Rayleigh
    dissipation c/2 (dl/dt)^2).  kind: 'spring' | 'damper' | 'spring-damper'.
    """

    name: str
    kind: str
    a: str
    b: str
    k: Expr = ZERO
    c: Expr = ZERO
    l0: Expr = ZERO
    span: Span = field(default_factory=Span)


@record
class AppliedForce:
    """Force F applied at a point; F given in world axes or in the axes of body `frame`."""

    name: str
    point: str
    F: Vec3
    frame: str = "world"
    span: Span = field(default_factory=Span)


@record
class AppliedTorque:
    name: str
    body: str
    tau: Vec3
    frame: str = "world"
    span: Span = field(default_factory=Span)


@record
class GeneralizedForce:
    name: str
    coordinate: str
    Q: Expr
    span: Span = field(default_factory=Span)
    note: str = ""            # what it is when built from a component (Friction: the law)
    regularization: Expr | None = None   # Friction: v_eps (an expression in parameters)


@record
class Gravitation:
    """Mutual Newtonian gravitation between every pair of `bodies` (at their mass centres)."""

    name: str
    bodies: tuple[str, ...]
    G: Expr
    span: Span = field(default_factory=Span)


@record
class Term:
    """An equation-layer term.  kind: 'kinetic' | 'potential' | 'dissipation'.

    Also used for the component `Potential` (kind 'potential').
    """

    kind: str
    expr: Expr
    name: str = ""
    span: Span = field(default_factory=Span)


Force = Union[Gravity, SpringDamper, AppliedForce, AppliedTorque, GeneralizedForce, Gravitation]


@record
class Constraint:
    """An explicit holonomic constraint residual(q, t) = 0 (residual = lhs - rhs).

    `name` comes from the description ("rod") when it is a word, else c<k>; `alias` is always
    c<k> (k in declaration order), the name before issue 17, still accepted in `outputs`."""

    name: str
    residual: Expr
    doc: str = ""
    span: Span = field(default_factory=Span)
    alias: str = ""
    dim: object = None               # units.Dim of the residual (lhs - rhs), None when unknown


@record
class Loop:
    """A kinematic loop closed by the cut joint `joint` (bodies along the loop, in order)."""

    name: str
    joint: str
    bodies: tuple[str, ...]
    span: Span = field(default_factory=Span)


@record
class Output:
    name: str
    expr: Expr
    unit: str | None = None
    doc: str = ""
    span: Span = field(default_factory=Span)


@record
class Contact:
    """A unilateral contact (issue 6).  Fields are kept generic until impacts land."""

    name: str
    kind: str
    fields: tuple[tuple[str, object], ...] = ()
    span: Span = field(default_factory=Span)

    def get(self, key: str, default=None):
        return dict(self.fields).get(key, default)


@record
class Model:
    name: str
    doc: str = ""
    parameters: tuple[Parameter, ...] = ()
    coordinates: tuple[Coordinate, ...] = ()
    bodies: tuple[Body, ...] = ()        # excludes the world
    points: tuple[Point, ...] = ()       # includes every body origin (named as the body) and 'world'
    joints: tuple[Joint, ...] = ()
    forces: tuple[Force, ...] = ()
    terms: tuple[Term, ...] = ()
    constraints: tuple[Constraint, ...] = ()
    loops: tuple[Loop, ...] = ()
    outputs: tuple[Output, ...] = ()
    contacts: tuple[Contact, ...] = ()
    span: Span = field(default_factory=Span)
    shapes: tuple[Shape, ...] = ()       # drawn shapes placed on bodies (the component Shape)

    # -- lookups -------------------------------------------------------------------
    def parameter(self, name: str) -> Parameter:
        return _find(self.parameters, name)

    def coordinate(self, name: str) -> Coordinate:
        return _find(self.coordinates, name)

    def body(self, name: str) -> Body:
        return _find(self.bodies, name)

    def point(self, name: str) -> Point:
        return _find(self.points, name)

    def joint(self, name: str) -> Joint:
        return _find(self.joints, name)

    def constraint_bodies(self, c: Constraint) -> list[str]:
        """The bodies whose points (or orientations) the residual of ``c`` names, in order of appearance."""
        points = {p.name: p.body for p in self.points}
        out: list[str] = []
        for n in walk(c.residual):
            b = points.get(n.point) if isinstance(n, PointPos) else (n.body if isinstance(n, BodyRot) else None)
            if b is not None and b not in out:
                out.append(b)
        return out

    @property
    def coordinate_names(self) -> tuple[str, ...]:
        return tuple(c.name for c in self.coordinates)

    @property
    def real_parameters(self) -> tuple[Parameter, ...]:
        """The entries of the parameter vector p, in order (inputs are not parameters)."""
        return tuple(p for p in self.parameters if not p.integer and not p.input)

    @property
    def inputs(self) -> tuple[Parameter, ...]:
        """The control inputs (``input Real F``), the entries of u in order."""
        return tuple(p for p in self.parameters if p.input)

    @property
    def tree_joints(self) -> tuple[Joint, ...]:
        return tuple(j for j in self.joints if not j.closes_loop)

    @property
    def is_tree(self) -> bool:
        return not self.loops and not self.constraints

    @property
    def has_components(self) -> bool:
        return bool(self.bodies)


def _find(items, name):
    for it in items:
        if it.name == name:
            return it
    raise KeyError(name)


@record
class Scene:
    """A named experiment: the model (with overrides already applied) and settings.

    settings keys (all optional): stop_time, start_time, rtol, atol, method, points,
    outputs (tuple of names), formulation, dt, and any later issue's own keys.
    """

    name: str
    model: Model
    doc: str = ""
    settings: tuple[tuple[str, object], ...] = ()
    span: Span = field(default_factory=Span)

    def get(self, key: str, default=None):
        return dict(self.settings).get(key, default)
