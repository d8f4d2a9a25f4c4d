"""What the language offers by name, described for people: the members of the built-in component
classes (fields, named points, joint variables, kinematic attributes), the attributes of scalar
declarations, the built-in functions and the scene settings.

The tables the compiler works from stay where they are (components.CLASSES, attributes.py,
evaluate.ALL_FUNCS, SCENE_SETTINGS); this module adds words and units to their names for hover
and completion in an editor (mechdsl.lsp).  tests/test_catalog.py checks that it names exactly
what the compiler accepts.
"""
from __future__ import annotations

from dataclasses import dataclass

from ..model import units as U
from . import components as K
from .entries import COORD_ATTRS
from .scalar_decls import PARAM_ATTRS


@dataclass(frozen=True)
class Member:
    """One name after a dot (``rod.b``, ``j1.phi``, ``b.w_body``) or in a modification (``m = 2``)."""

    name: str
    kind: str           # field | point | joint variable | attribute | setting
    doc: str = ""
    unit: str = ""      # a unit for people ("kg", "m/s"); "" when none or unknown
    default: str = ""   # the default value as text ("" when required or none)
    required: bool = False


def unit_text(d: U.Dim | None) -> str:
    if d is None:
        return ""
    s = str(d)
    return "1" if s in ("", "1") else s


# ----------------------------------------------------------------------------- kinematic attributes

# name -> (meaning, unit), as docs/language.md's attribute table says
KINEMATIC: dict[str, tuple[str, str]] = {
    "r": ("position, world axes", "m"),
    "x": ("x component of the position r", "m"),
    "y": ("y component of the position r", "m"),
    "z": ("z component of the position r", "m"),
    "v": ("absolute velocity, world axes", "m/s"),
    "a": ("absolute acceleration, world axes (outputs only)", "m/s2"),
    "R": ("rotation matrix, body axes to world axes", "1"),
    "w": ("angular velocity, world axes", "1/s"),
    "w_body": ("angular velocity, body axes (transpose(b.R)*b.w)", "1/s"),
    "alpha": ("angular acceleration, world axes (outputs only)", "1/s2"),
}
POINT_ATTRIBUTES = ("r", "x", "y", "z", "v", "a")
FRAME_ATTRIBUTES = POINT_ATTRIBUTES + ("R", "w", "w_body", "alpha")


def _kinematic(names) -> list[Member]:
    return [Member(n, "attribute", *KINEMATIC[n]) for n in names]


def world_members() -> list[Member]:
    """``world.x`` ...: the fixed frame's attributes (all zero, R the identity)."""
    return _kinematic(FRAME_ATTRIBUTES)


def point_members() -> list[Member]:
    """The attributes of a point (``rod.b.x``)."""
    return _kinematic(POINT_ATTRIBUTES)


def _default_text(f: K.Field) -> str:
    if f.default is K.REQUIRED or f.default is None:
        return ""
    v = f.default
    if f.kind == "bool":
        return "true" if v else "false"
    if isinstance(v, tuple):
        return "{" + ", ".join(f"{x:g}" for x in v) + "}"
    if isinstance(v, str):
        return f'"{v}"' if f.kind == "string" else v
    return f"{v:g}"


def field_members(cls: K.ComponentClass) -> list[Member]:
    """What a component's modification may set (``Rod rod(m = 1, L = 2)``)."""
    out = []
    for f in cls.fields:
        doc = f.doc or f.kind
        if f.choices:
            doc += " (" + " or ".join(f'"{c}"' for c in f.choices) + ")"
        out.append(Member(f.name, "field", doc, unit_text(f.dim), _default_text(f), f.default is K.REQUIRED))
    return out


def role_members(cls: K.ComponentClass) -> list[Member]:
    """A joint's variables (``j1.phi``); quaternion joints add q0..q3."""
    roles = list(cls.roles)
    if cls.name in ("Spherical", "Free"):
        roles += list(K.QUATERNION_ROLES)
    return [Member(r, "joint variable", f"joint variable {r} of the {cls.name} joint"
                   + (" (parametrization = \"quaternion\")" if (r, d) in K.QUATERNION_ROLES else ""),
                   "rad" if d == U.ONE else unit_text(d)) for r, d in roles]


def class_members(name: str, joint_frame: bool = True) -> list[Member]:
    """Every name that may follow ``c.`` for a component ``c`` of the built-in class ``name``:
    its named points, joint variables, fields and kinematic attributes (a named point wins over an
    attribute of the same name: ``rod.a`` is an end point).  A joint has the attributes of its
    own frame only when it has no child (``joint_frame``)."""
    cls = K.CLASSES.get(name)
    if cls is None:
        return []
    out = [Member(p, "point", f"named point {p} of the {cls.name}"
                  + (" (its centre of mass)" if p == "com" else ""), "") for p in cls.points]
    if cls.category == "joint":
        out += role_members(cls)
    out += field_members(cls)
    if cls.category in ("body", "frame"):
        out += _kinematic(FRAME_ATTRIBUTES)
    elif cls.category == "point":
        out += _kinematic(POINT_ATTRIBUTES)
    elif cls.category == "joint" and cls.field("child") is not None and joint_frame:
        out += [Member(m.name, m.kind, m.doc + " of the joint's frame (a joint without a child)", m.unit)
                for m in _kinematic(FRAME_ATTRIBUTES)]
    seen: dict[str, Member] = {}
    for m in out:
        seen.setdefault(m.name, m)
    return list(seen.values())


def class_member(name: str, member: str) -> Member | None:
    for m in class_members(name):
        if m.name == member:
            return m
    return None


def modifier_members(name: str) -> list[Member]:
    """What a modification of a component of class ``name`` may name: its fields and, for a
    joint, its variables (``phi(start = 1)``)."""
    cls = K.CLASSES.get(name)
    if cls is None:
        return []
    return field_members(cls) + (role_members(cls) if cls.category == "joint" else [])


# ----------------------------------------------------------------------------- scalar declarations

SCALAR_ATTRIBUTES: dict[str, str] = {
    "unit": 'the unit, e.g. "m", "kg.m2", "N/m" (dimensions are checked)',
    "displayUnit": "the unit to show values in",
    "min": "lowest allowed value",
    "max": "highest allowed value",
    "start": "value at the start time",
    "speed": "start value of der(q)",
    "fixed": "whether the start value is fixed (else a guess for consistent initialization); default true",
    "speed_fixed": "whether the start speed is fixed (else a guess); default true",
}


def scalar_members(prefix: str | None) -> list[Member]:
    """The attributes a declaration's modification may set: ``parameter Real m(unit = "kg")``,
    ``coordinate Real q(start = 1, speed = 0)``; joint variables take the coordinate's."""
    names = COORD_ATTRS if prefix in ("coordinate", "joint variable") else PARAM_ATTRS
    return [Member(n, "attribute", SCALAR_ATTRIBUTES[n]) for n in SCALAR_ATTRIBUTES if n in names]


# ----------------------------------------------------------------------------- built-in functions

# name -> (signature, what it gives)
FUNCTIONS: dict[str, tuple[str, str]] = {
    "sin": ("sin(x)", "sine (element-wise)"), "cos": ("cos(x)", "cosine (element-wise)"),
    "tan": ("tan(x)", "tangent (element-wise)"), "asin": ("asin(x)", "arc sine"),
    "acos": ("acos(x)", "arc cosine"), "atan": ("atan(x)", "arc tangent"),
    "atan2": ("atan2(y, x)", "the angle of the point (x, y), in (-pi, pi]"),
    "sinh": ("sinh(x)", "hyperbolic sine"), "cosh": ("cosh(x)", "hyperbolic cosine"),
    "tanh": ("tanh(x)", "hyperbolic tangent"), "exp": ("exp(x)", "e to the power x"),
    "log": ("log(x)", "natural logarithm"), "log10": ("log10(x)", "base-10 logarithm"),
    "sqrt": ("sqrt(x)", "square root"), "abs": ("abs(x)", "absolute value"),
    "sign": ("sign(x)", "-1, 0 or 1"), "floor": ("floor(x)", "largest integer not above x"),
    "ceil": ("ceil(x)", "smallest integer not below x"),
    "min": ("min(a, b)", "the smaller of a and b"), "max": ("max(a, b)", "the larger of a and b"),
    "cross": ("cross(a, b)", "cross product of two 3-vectors"), "dot": ("dot(a, b)", "dot product"),
    "norm": ("norm(v)", "Euclidean length of a vector"), "normalize": ("normalize(v)", "v / norm(v)"),
    "transpose": ("transpose(M)", "the transposed matrix"),
    "identity": ("identity(n)", "the n x n identity matrix"),
    "zeros": ("zeros(n, ...)", "an array of zeros of the given sizes"),
    "ones": ("ones(n, ...)", "an array of ones of the given sizes"),
    "fill": ("fill(value, n, ...)", "an array of the given sizes filled with value"),
    "sum": ("sum(a)", "the sum of all elements of an array"),
    "skew": ("skew(v)", "the skew-symmetric cross-product matrix of a 3-vector: skew(a)*b = cross(a, b)"),
    "diagonal": ("diagonal(v)", "the diagonal matrix with v on its diagonal"),
    "size": ("size(a) or size(a, k)", "the length of a vector, or of dimension k of an array"),
    "rotation": ("rotation(axis, angle)", "the rotation matrix about a unit axis by an angle (Rodrigues)"),
    "rpy": ("rpy(r, p, y) or rpy({r, p, y})", "the rotation matrix of roll, pitch, yaw in URDF's convention: "
                                               "Rz(y) Ry(p) Rx(r) (fixed axes x, y, z)"),
    "axis_angle": ("axis_angle(axis, angle) or axis_angle(v)", "the rotation matrix about an axis by an angle; "
                                                               "from one vector: about v by norm(v)"),
    "der": ("der(x)", "the speed of a coordinate, or the time derivative of an expression in coordinates "
                      "and time"),
    "position": ("position(p)", "the position of a point or body, the same as p.r (m)"),
    "velocity": ("velocity(p)", "the velocity of a point or body, the same as p.v (m/s)"),
    "kinetic_energy": ("kinetic_energy()", "the model's kinetic energy T (J)"),
    "potential_energy": ("potential_energy()", "the model's potential energy V (J)"),
    "energy": ("energy()", "the total energy T + V (J)"),
    "dissipation_function": ("dissipation_function()", "the Rayleigh dissipation function D (W)"),
    "reaction_force": ("reaction_force(joint)", "the joint's reaction force, in its child frame (N); "
                                                "outputs only"),
    "reaction_torque": ("reaction_torque(joint)", "the joint's reaction torque, in its child frame (N.m); "
                                                  "outputs only"),
}

BUILTIN_VALUES: dict[str, str] = {
    "time": "the time t (s)",
    "pi": "3.14159...",
    "world": "the fixed frame; its origin is the point world",
}

# ----------------------------------------------------------------------------- scene settings

SETTINGS: dict[str, str] = {
    "stop_time": "end of the run (s)", "start_time": "start of the run (s); default 0",
    "tolerance": "sets rtol and atol together", "rtol": "relative tolerance of the integrator",
    "atol": "absolute tolerance of the integrator", "method": "integration method, e.g. \"idas\"",
    "points": "number of output points", "outputs": "what to record: outputs, coordinates, der(q), energies",
    "formulation": "formulation of a constrained model, e.g. \"ggl\"", "dt": "step of fixed-step methods (s)",
    "reactions": "constrained models: record the reaction forces",
    "compiled": "false forbids compiling the right-hand side to C",
    "rest_speed": "contacts: rebounds slower than this end in persistent contact (m/s); default 1e-3",
    "impact_order": 'contacts: "simultaneous" (default) or "sequential"',
    "output_events": "contacts: also record a row just before and one just after every event",
}


def setting_members() -> list[Member]:
    return [Member(n, "setting", d) for n, d in SETTINGS.items()]


__all__ = ["Member", "KINEMATIC", "FUNCTIONS", "BUILTIN_VALUES", "SETTINGS", "SCALAR_ATTRIBUTES",
           "class_members", "class_member", "modifier_members", "scalar_members", "world_members",
           "point_members", "setting_members", "unit_text"]
