"""The built-in component classes: their fields (with kinds, defaults and units) and how each
turns into IR objects (bodies, points, joints, forces, contacts).

A component class is data (:class:`ComponentClass`); building is one small function per
category.  Adding a class is adding an entry to ``CLASSES``.
"""
from __future__ import annotations

import math
from dataclasses import field

from ..model import exprs as X
from ..model import ir
from ..model import units as U
from .values import ANY, Arr, CompRef, Scalar, Str, ValError, Val, describe_shape, shape_of
from ..model.records import record

REQUIRED = object()


@record
class Field:
    name: str
    kind: str                   # scalar vec3 mat3 point body bodies coordinate string bool
    default: object = REQUIRED  # python value (float, tuple of floats, str) or None (optional)
    dim: U.Dim | None = None
    doc: str = ""
    choices: tuple[str, ...] = ()


@record
class ComponentClass:
    name: str
    category: str               # body point frame joint force contact
    fields: tuple[Field, ...]
    doc: str
    roles: tuple[tuple[str, U.Dim], ...] = ()    # joint variables (euler form)
    points: tuple[str, ...] = ()                 # named points a body class provides

    def field(self, name: str) -> Field | None:
        for f in self.fields:
            if f.name == name:
                return f
        return None

    @property
    def connect_fields(self) -> tuple[str, str] | None:
        if self.name == "RigidLink":
            return ("a", "b")
        if self.category == "joint":
            return ("parent", "child")
        if self.name in ("Spring", "Damper", "SpringDamper"):
            return ("a", "b")
        return None


_X, _Y, _Z = (1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0)
_ZERO3 = (0.0, 0.0, 0.0)
ROT, LEN = U.ONE, U.LENGTH


def _f(*a, **k) -> Field:
    return Field(*a, **k)


_JOINT_COMMON = (_f("parent", "point", doc="point on the parent body (or world)"),
                 _f("child", "point", None, doc="point on the child body (omitted: the joint's own massless frame, "
                                                "named after the joint)"))
_ORIENT_DOC = "orientation of the parent joint frame in the parent point's axes: roll, pitch, yaw (rad, URDF's rpy)"
_JOINT_COMMON += (_f("rpy", "vec3", None, U.ONE, _ORIENT_DOC),
                  _f("R", "mat3", None, U.ONE, "orientation of the parent joint frame as a rotation matrix (instead of rpy)"))
_SPATIAL = (_f("sequence", "string", "zyx", doc="Euler/Cardan sequence of the three angles (intrinsic)"),
            _f("parametrization", "string", "euler", choices=("euler", "quaternion"),
               doc="'euler' (three angles, singular at gimbal lock) or 'quaternion' (singularity-free)"))

CLASSES: dict[str, ComponentClass] = {c.name: c for c in [
    # ------------------------------------------------------------------ bodies
    ComponentClass("PointMass", "body", (_f("m", "scalar", dim=U.MASS, doc="mass"),),
                   "a point mass; its body frame sits at the mass"),
    ComponentClass("Body", "body", (
        _f("m", "scalar", dim=U.MASS, doc="mass"),
        _f("r_cm", "vec3", _ZERO3, U.LENGTH, "centre of mass in body coordinates"),
        _f("I", "mat3", None, U.INERTIA, "inertia tensor about the centre of mass, body axes"),
        _f("I_11", "scalar", 0.0, U.INERTIA), _f("I_22", "scalar", 0.0, U.INERTIA),
        _f("I_33", "scalar", 0.0, U.INERTIA), _f("I_21", "scalar", 0.0, U.INERTIA),
        _f("I_31", "scalar", 0.0, U.INERTIA), _f("I_32", "scalar", 0.0, U.INERTIA),
        _f("measured_inertia", "bool", 0.0, doc="the inertia is measured data: judged only to be positive "
                                                 "semidefinite, not by the triangle inequality"),
        _f("shape", "string", "", choices=("", "box", "cylinder", "sphere", "rod", "disk"),
           doc="a shape to draw the body with (drawing only: the inertia is I)"),
        _f("size", "vector", None, U.LENGTH, "the drawn shape's size: box {lx, ly, lz}, cylinder {R, L}, "
                                             "sphere, disk {R}, rod {L}"),
        _f("axis", "vec3", _X, U.ONE, "the drawn shape's axis (cylinder, disk, rod), body coordinates")),
        "a rigid body with mass, centre of mass and inertia tensor", points=("com",)),
    ComponentClass("Rod", "body", (
        _f("m", "scalar", dim=U.MASS), _f("L", "scalar", dim=U.LENGTH, doc="length"),
        _f("axis", "vec3", _X, U.ONE, "direction from end a to end b, body coordinates")),
        "a uniform slender rod; frame at its centre, ends a and b", points=("a", "b", "com")),
    ComponentClass("Disk", "body", (
        _f("m", "scalar", dim=U.MASS), _f("R", "scalar", dim=U.LENGTH, doc="radius"),
        _f("axis", "vec3", _Z, U.ONE, "normal of the disk")),
        "a uniform thin disk; frame at its centre", points=("com",)),
    ComponentClass("Cylinder", "body", (
        _f("m", "scalar", dim=U.MASS), _f("R", "scalar", dim=U.LENGTH), _f("L", "scalar", dim=U.LENGTH),
        _f("axis", "vec3", _Z, U.ONE, "symmetry axis")),
        "a uniform solid cylinder; frame at its centre, end centres a and b", points=("a", "b", "com")),
    ComponentClass("Sphere", "body", (_f("m", "scalar", dim=U.MASS), _f("R", "scalar", dim=U.LENGTH)),
                   "a uniform solid sphere; frame at its centre", points=("com",)),
    ComponentClass("Box", "body", (_f("m", "scalar", dim=U.MASS),
                                   _f("size", "vec3", dim=U.LENGTH, doc="edge lengths along body x, y, z")),
                   "a uniform box; frame at its centre", points=("com",)),
    # ------------------------------------------------------------------ points and frames
    ComponentClass("Point", "point", (_f("body", "body", doc="body the point is fixed on (or world)"),
                                      _f("r", "vec3", _ZERO3, U.LENGTH, "position in body coordinates"),
                                      _f("rpy", "vec3", None, U.ONE, "orientation of the point's axes in body "
                                                                     "axes: roll, pitch, yaw (rad, URDF's rpy)"),
                                      _f("R", "mat3", None, U.ONE, "orientation as a rotation matrix (instead of rpy)")),
                   "a named point fixed on a body (with an orientation: a frame fixed on the body)"),
    ComponentClass("Shape", "shape", (
        _f("body", "body", doc="the body it is drawn on (or world)"),
        _f("shape", "string", choices=("box", "cylinder", "sphere", "disk", "rod"), doc="what is drawn"),
        _f("size", "vector", dim=U.LENGTH, doc="box {lx, ly, lz}, cylinder {R, L}, sphere, disk {R}, rod {L}"),
        _f("r", "vec3", _ZERO3, U.LENGTH, "its centre in body coordinates"),
        _f("rpy", "vec3", None, U.ONE, "orientation of its axes in body axes: roll, pitch, yaw (rad, URDF's rpy)"),
        _f("R", "mat3", None, U.ONE, "orientation as a rotation matrix (instead of rpy)"),
        _f("axis", "vec3", _Z, U.ONE, "the symmetry axis of a cylinder, disk or rod, in its own axes")),
        "a shape drawn on a body, placed in its axes (drawing only: no mass); a body may have several"),
    ComponentClass("Frame", "frame", (
        _f("parent", "point", "world", doc="where the frame's motion is measured from"),
        _f("r", "vec3", _ZERO3, U.LENGTH, "origin relative to parent (may depend on time)"),
        _f("axis", "vec3", _Z, U.ONE, "rotation axis"), _f("angle", "scalar", 0.0, U.ONE, "rotation angle (of time)"),
        _f("R", "mat3", None, U.ONE, "rotation matrix (instead of axis and angle)"),
        _f("rpy", "vec3", None, U.ONE, "roll, pitch, yaw (rad, URDF's rpy; instead of axis and angle)")),
        "a reference frame moving as a prescribed function of time (massless)"),
    # ------------------------------------------------------------------ joints
    ComponentClass("Revolute", "joint", _JOINT_COMMON + (_f("axis", "vec3", _Z, U.ONE),),
                   "rotation about an axis", roles=(("phi", ROT),)),
    ComponentClass("Prismatic", "joint", _JOINT_COMMON + (_f("axis", "vec3", _X, U.ONE),),
                   "translation along an axis", roles=(("s", LEN),)),
    ComponentClass("Cylindrical", "joint", _JOINT_COMMON + (_f("axis", "vec3", _Z, U.ONE),),
                   "rotation about and translation along one axis", roles=(("phi", ROT), ("s", LEN))),
    ComponentClass("Planar", "joint", _JOINT_COMMON + (_f("axis", "vec3", _Z, U.ONE, "normal of the plane"),),
                   "translation in a plane and rotation about its normal",
                   roles=(("x", LEN), ("y", LEN), ("phi", ROT))),
    ComponentClass("Spherical", "joint", _JOINT_COMMON + _SPATIAL, "a ball joint (three rotations)",
                   roles=(("phi", ROT), ("theta", ROT), ("psi", ROT))),
    ComponentClass("Free", "joint", (_f("parent", "point", "world"),) + _JOINT_COMMON[1:] + _SPATIAL,
                   "six degrees of freedom (three for a point mass)",
                   roles=(("x", LEN), ("y", LEN), ("z", LEN), ("phi", ROT), ("theta", ROT), ("psi", ROT))),
    ComponentClass("Fixed", "joint", _JOINT_COMMON, "a rigid connection (no freedom)"),
    ComponentClass("RigidLink", "joint", (_f("a", "body", doc="the body (or joint frame, or world) the link starts on"),
                                          _f("b", "point", doc="the body or point it carries"),
                                          _f("r", "vec3", dim=U.LENGTH, doc="where b sits, in a's axes")),
                   "a massless rigid link: b is held at r from a's origin, with a's axes"),
    # ------------------------------------------------------------------ forces
    ComponentClass("Gravity", "force", (_f("g", "vec3", (0.0, -9.81, 0.0), U.ACCEL, "gravitational acceleration"),),
                   "uniform gravity on every body"),
    ComponentClass("Spring", "force", (_f("a", "point"), _f("b", "point"), _f("k", "scalar", dim=U.STIFFNESS),
                                       _f("l0", "scalar", 0.0, U.LENGTH, "rest length")),
                   "a linear spring between two points"),
    ComponentClass("Damper", "force", (_f("a", "point"), _f("b", "point"), _f("c", "scalar", dim=U.DAMPING)),
                   "a linear damper between two points (Rayleigh dissipation)"),
    ComponentClass("SpringDamper", "force", (_f("a", "point"), _f("b", "point"), _f("k", "scalar", dim=U.STIFFNESS),
                                             _f("c", "scalar", dim=U.DAMPING), _f("l0", "scalar", 0.0, U.LENGTH)),
                   "a spring and a damper in parallel"),
    ComponentClass("Force", "force", (_f("point", "point"), _f("F", "vec3", dim=U.FORCE),
                                      _f("frame", "body", "world", doc="axes F is given in (world or a body)")),
                   "a force applied at a point (function of time and state)"),
    ComponentClass("Torque", "force", (_f("body", "body"), _f("tau", "vec3", dim=U.TORQUE),
                                       _f("frame", "body", "world")),
                   "a torque applied to a body"),
    ComponentClass("GeneralizedForce", "force", (_f("coordinate", "coordinate"), _f("Q", "scalar")),
                   "a generalized force on one coordinate"),
    ComponentClass("Friction", "force", (
        _f("coordinate", "coordinate", doc="the joint variable or coordinate the friction acts on"),
        _f("F", "scalar", doc="Coulomb friction force or torque while sliding (mu N; may depend on the state)"),
        _f("v_eps", "scalar", 1e-3, doc="regularization speed (coordinate units per second): "
                                         "Q = -F tanh(der(q)/v_eps)")),
        "regularized Coulomb friction on one coordinate (joint friction, a block sliding on a guide)"),
    ComponentClass("Gravitation", "force", (_f("bodies", "bodies"), _f("G", "scalar", 6.6743e-11, U.GRAV_CONST)),
                   "mutual Newtonian gravitation between bodies (at their mass centres)"),
    ComponentClass("Potential", "force", (_f("V", "scalar", dim=U.ENERGY),),
                   "an extra potential energy"),
    # ------------------------------------------------------------------ contacts (issue 6)
    ComponentClass("Contact", "contact", (
        _f("point", "point", None, doc="the contacting point (centre of a sphere when radius > 0)"),
        _f("radius", "scalar", 0.0, U.LENGTH),
        _f("surface", "string", "plane", choices=("plane", "sphere", "point")),
        _f("normal", "vec3", _Y, U.ONE, "plane normal (world), pointing to the allowed side"),
        _f("offset", "scalar", 0.0, U.LENGTH, "plane: normal . x >= offset"),
        _f("center", "point", "world", doc="sphere centre, or the other point"),
        _f("surface_radius", "scalar", 0.0, U.LENGTH),
        _f("inside", "bool", 0.0, doc="sphere: the point stays inside"),
        _f("e", "scalar", 1.0, U.ONE, "coefficient of restitution"),
        _f("mu", "scalar", 0.0, U.ONE, "coefficient of sliding friction while the contact persists"),
        _f("v_eps", "scalar", 1e-3, U.VELOCITY, "regularization speed of the sliding friction"),
        _f("gap", "scalar", None, U.LENGTH, "the gap as an expression of coordinates and time (>= 0 allowed); "
                                            "instead of point and surface, e.g. in equation-layer models")),
        "a unilateral frictionless contact with restitution"),
    ComponentClass("Fixation", "contact", (
        _f("point", "point", doc="the point that is suddenly fixed"),
        _f("time", "scalar", dim=U.TIME, doc="when it is fixed (where it is at that time)")),
        "an impulsive constraint: at `time` the point is fixed in space for good"),
]}


QUATERNION_ROLES = (("q0", ROT), ("q1", ROT), ("q2", ROT), ("q3", ROT))


def joint_roles(cls: ComponentClass, parametrization: str, point_mass_child: bool) -> tuple[tuple[str, U.Dim], ...]:
    roles = cls.roles
    if cls.name in ("Spherical", "Free") and parametrization == "quaternion":
        roles = tuple(r for r in roles if r[1] == LEN) + QUATERNION_ROLES
    if point_mass_child and cls.name in ("Free", "Planar"):
        roles = tuple(r for r in roles if r[1] == LEN)
    return roles


# ----------------------------------------------------------------------------- conversions


def as_expr(v: Val, what: str) -> ir.Expr:
    if isinstance(v, Scalar):
        return v.expr
    raise ValError("E301", f"{what} must be a scalar, got {describe_shape(v)}", "give one number or expression")


def as_vec3(v: Val, what: str) -> ir.Vec3:
    if isinstance(v, Arr) and shape_of(v) == (3,):
        return tuple(as_expr(x, what) for x in v.items)  # type: ignore[return-value]
    raise ValError("E301", f"{what} must be a vector of 3, got {describe_shape(v)}", "write it as {x, y, z}")


def as_mat3(v: Val, what: str) -> ir.Mat3:
    if isinstance(v, Arr) and shape_of(v) == (3, 3):
        return tuple(as_vec3(r, what) for r in v.items)  # type: ignore[return-value]
    raise ValError("E301", f"{what} must be a 3x3 matrix, got {describe_shape(v)}",
                   "write it as {{a, b, c}, {d, e, f}, {g, h, i}} or use diagonal({a, b, c})")


def python_to_val(x) -> Val:
    if isinstance(x, str):
        return Str(x)
    if isinstance(x, tuple):
        return Arr(tuple(python_to_val(i) for i in x))
    return Scalar(ir.Const(float(x)), ANY)


# ----------------------------------------------------------------------------- geometry helpers


C = X.const


def normalized(v: ir.Vec3, what: str) -> ir.Vec3:
    if all(isinstance(c, ir.Const) for c in v):
        n = math.hypot(*(c.value for c in v))  # type: ignore[union-attr]  (no overflow for huge components)
        if n == 0:
            raise ValError("E310", f"{what} must not be the zero vector", "give a direction, e.g. {0, 0, 1}")
        return tuple(C(c.value / n) for c in v)  # type: ignore[union-attr,return-value]
    n = X.func("sqrt", X.vsum(X.mul(c, c) for c in v))
    return tuple(X.div(c, n) for c in v)  # type: ignore[return-value]


def scale(v: ir.Vec3, s: ir.Expr) -> ir.Vec3:
    return tuple(X.mul(s, c) for c in v)  # type: ignore[return-value]


def outer(a: ir.Vec3, b: ir.Vec3) -> ir.Mat3:
    return tuple(tuple(X.mul(x, y) for y in b) for x in a)  # type: ignore[return-value]


def eye_minus_outer(a: ir.Vec3, k: ir.Expr, k_axis: ir.Expr) -> ir.Mat3:
    """k (E - a a^T) + k_axis a a^T."""
    rows = []
    for i in range(3):
        row = []
        for j in range(3):
            aij = X.mul(a[i], a[j])
            base = X.sub(C(1.0), aij) if i == j else X.neg(aij)
            row.append(X.add(X.mul(k, base), X.mul(k_axis, aij)))
        rows.append(tuple(row))
    return tuple(rows)  # type: ignore[return-value]


def diag(a: ir.Expr, b: ir.Expr, c: ir.Expr) -> ir.Mat3:
    z = C(0.0)
    return ((a, z, z), (z, b, z), (z, z, c))


def rodrigues(axis: ir.Vec3, angle: ir.Expr) -> ir.Mat3:
    """R = cos E + sin [a]x + (1 - cos) a a^T for a unit axis."""
    c, s = X.func("cos", angle), X.func("sin", angle)
    if isinstance(angle, ir.Const):
        c, s = C(math.cos(angle.value)), C(math.sin(angle.value))
    one_c = X.sub(C(1.0), c)
    ax, ay, az = axis
    skew = ((C(0.0), X.neg(az), ay), (az, C(0.0), X.neg(ax)), (X.neg(ay), ax, C(0.0)))
    return tuple(tuple(X.add(X.add(c if i == j else C(0.0), X.mul(s, skew[i][j])), X.mul(one_c, X.mul(axis[i], axis[j])))
                       for j in range(3)) for i in range(3))  # type: ignore[return-value]


def plane_axes(normal: ir.Vec3) -> tuple[ir.Vec3, ir.Vec3]:
    if not all(isinstance(c, ir.Const) for c in normal):
        raise ValError("E311", "the normal of a planar joint must be a constant vector",
                       "write it with numbers, e.g. axis = {0, 0, 1}")
    e1, e2 = ir.plane_basis([c.value for c in normal])  # type: ignore[union-attr]
    return tuple(C(x) for x in e1), tuple(C(x) for x in e2)  # type: ignore[return-value]


def check_sequence(seq: str) -> None:
    if len(seq) != 3 or any(c not in "xyz" for c in seq) or seq[0] == seq[1] or seq[1] == seq[2]:
        raise ValError("E312", f"'{seq}' is not an Euler/Cardan sequence",
                       "use three axes with no two neighbours equal, e.g. \"zyx\" or \"zxz\"")


# ----------------------------------------------------------------------------- bodies


_SHAPE_SIZES = {"box": 3, "cylinder": 2, "sphere": 1, "disk": 1, "rod": 1}


def drawn_shape(f: dict[str, Val]) -> tuple[str, tuple[ir.Expr, ...], ir.Vec3]:
    """A Body's or a Shape's `shape`, `size` and `axis`: what it is drawn with (a Body's inertia stays I)."""
    shape = f["shape"].value if isinstance(f.get("shape"), Str) else ""
    size_val = f.get("size")
    size = tuple(as_expr(x, "size") for x in size_val.items) if isinstance(size_val, Arr) else ()
    if shape and len(size) != _SHAPE_SIZES[shape]:
        raise ValError("E301", f"a {shape} is drawn with {_SHAPE_SIZES[shape]} size value(s), got {len(size)}",
                       "box: size = {lx, ly, lz}; cylinder: {R, L}; sphere, disk: {R}; rod: {L}")
    if size and not shape:
        raise ValError("E210", "size is given without a shape", 'add shape = "box" (or cylinder, sphere, disk, rod)')
    return shape, size, normalized(as_vec3(f["axis"], "axis"), "axis")


@record(frozen=False)
class Built:
    """What one component instance contributes to the IR."""

    bodies: list = field(default_factory=list)
    points: list = field(default_factory=list)
    joints: list = field(default_factory=list)
    forces: list = field(default_factory=list)
    terms: list = field(default_factory=list)
    contacts: list = field(default_factory=list)
    shapes: list = field(default_factory=list)


def build_body(cls: ComponentClass, name: str, f: dict[str, Val], span) -> Built:
    m = as_expr(f["m"], "m")
    z = C(0.0)
    zero3 = (z, z, z)
    out = Built()
    com: ir.Vec3 = zero3
    axis: ir.Vec3 = (C(1.0), z, z)
    size: tuple[ir.Expr, ...] = ()
    shape = ""
    if cls.name == "PointMass":
        inertia = diag(z, z, z)
        kind = "point"
    elif cls.name == "Body":
        kind = "rigid"
        com = as_vec3(f["r_cm"], "r_cm")
        if f.get("I") is not None:
            inertia = as_mat3(f["I"], "I")
        else:
            g = {k: as_expr(f[k], k) for k in ("I_11", "I_22", "I_33", "I_21", "I_31", "I_32")}
            inertia = ((g["I_11"], g["I_21"], g["I_31"]), (g["I_21"], g["I_22"], g["I_32"]),
                       (g["I_31"], g["I_32"], g["I_33"]))
        shape, size, axis = drawn_shape(f)
    else:
        kind = "rigid"
        shape = cls.name.lower()
        if cls.name == "Rod":
            L = as_expr(f["L"], "L")
            axis = normalized(as_vec3(f["axis"], "axis"), "axis")
            inertia = eye_minus_outer(axis, X.div(X.mul(m, X.mul(L, L)), C(12.0)), z)
            size = (L,)
            half = X.div(L, C(2.0))
            out.points += [ir.Point(f"{name}.a", name, scale(axis, X.neg(half)), span),
                           ir.Point(f"{name}.b", name, scale(axis, half), span)]
        elif cls.name == "Disk":
            R = as_expr(f["R"], "R")
            axis = normalized(as_vec3(f["axis"], "axis"), "axis")
            mr2 = X.mul(m, X.mul(R, R))
            inertia = eye_minus_outer(axis, X.div(mr2, C(4.0)), X.div(mr2, C(2.0)))
            size = (R,)
        elif cls.name == "Cylinder":
            R, L = as_expr(f["R"], "R"), as_expr(f["L"], "L")
            axis = normalized(as_vec3(f["axis"], "axis"), "axis")
            trans = X.div(X.mul(m, X.add(X.mul(C(3.0), X.mul(R, R)), X.mul(L, L))), C(12.0))
            inertia = eye_minus_outer(axis, trans, X.div(X.mul(m, X.mul(R, R)), C(2.0)))
            size = (R, L)
            half = X.div(L, C(2.0))
            out.points += [ir.Point(f"{name}.a", name, scale(axis, X.neg(half)), span),
                           ir.Point(f"{name}.b", name, scale(axis, half), span)]
        elif cls.name == "Sphere":
            R = as_expr(f["R"], "R")
            k = X.div(X.mul(C(2.0), X.mul(m, X.mul(R, R))), C(5.0))
            inertia = diag(k, k, k)
            size = (R,)
        elif cls.name == "Box":
            lx, ly, lz = as_vec3(f["size"], "size")
            sq = lambda a, b: X.div(X.mul(m, X.add(X.mul(a, a), X.mul(b, b))), C(12.0))  # noqa: E731
            inertia = diag(sq(ly, lz), sq(lx, lz), sq(lx, ly))
            size = (lx, ly, lz)
        else:  # pragma: no cover - registry and builder out of sync
            raise ValError("E203", f"no builder for {cls.name}", "this is a bug in mechdsl")
    measured = cls.name == "Body" and bool(X.is_const(as_expr(f["measured_inertia"], "measured_inertia"), 1.0))
    out.bodies.append(ir.Body(name, kind, m, com, inertia, shape, size, axis, span, measured))
    out.points.insert(0, ir.Point(name, name, zero3, span))
    out.points.append(ir.Point(f"{name}.com", name, com, span))
    return out
