"""Joint kinds as small hooks (one class per kind).

Every joint is compiled into a short chain of elementary *elements* placed between the
parent joint frame and the child joint frame (see docs/internals/mechanics.md):

    'R'  revolute about a unit axis a, one variable:  E = rot(a, x),  r = 0,     S = [a; 0]
    'P'  prismatic along a unit axis a, one variable: E = 1,          r = x a,   S = [0; a]
    'Q'  ball joint in a unit quaternion (4 variables q0..q3, 3 speeds = the relative angular
         velocity in child axes):                     E = R(q/|q|),   r = 0,     S = [1; 0]
    'T'  a prescribed transform (moving frame):       E = R(t),       r = r(t)

Composite joints are chains of these with massless frames in between (a planar joint is
P e1, P e2, R a; Euler angles 'zyx' are R z, R y, R x), so every element has a constant
motion subspace in its own frame and the recursive algorithms need no joint bias term c_J.

A kind's hooks: ``roles`` (variable names in canonical order), ``elements`` (the chain)
and ``closure`` (which relative directions a loop-closing cut joint locks).
"""
from __future__ import annotations


from ..model import ir
from ..diagnostics import Diagnostic, MechError
from .rotations import euler_sequence
from ..model.records import record

E_X = (ir.ONE, ir.ZERO, ir.ZERO)
E_Y = (ir.ZERO, ir.ONE, ir.ZERO)
E_Z = (ir.ZERO, ir.ZERO, ir.ONE)
UNIT = (E_X, E_Y, E_Z)
QUAT_ROLES = ("q0", "q1", "q2", "q3")


@record
class Element:
    kind: str                                   # 'R' | 'P' | 'Q' | 'T'
    vars: tuple[ir.JointVar, ...] = ()
    axis: ir.Vec3 | None = None                 # R, P
    R: ir.Mat3 | None = None                    # T
    r: ir.Vec3 | None = None                    # T


@record
class Closure:
    """What a cut joint locks: translation along `lock_dirs` (None: all three parent axes),
    rotation: 'full' (3), 'axis' (keep `axis` aligned: 2), 'none'."""

    translation: str          # 'all' | 'perp' (perpendicular to axis) | 'normal' (along axis) | 'none'
    rotation: str             # 'full' | 'axis' | 'none'


def _err(joint: ir.Joint, code: str, msg: str, help: str | None = None) -> MechError:
    return MechError(Diagnostic(code, msg, joint.span, help))


class JointKind:
    """Template: subclasses set ``kind`` and override ``roles``/``chain``/``closure``."""

    kind = ""
    closure = Closure("all", "full")

    def roles(self, joint: ir.Joint, point_child: bool) -> tuple[str, ...]:
        return ()

    def chain(self, joint: ir.Joint, v: dict[str, ir.JointVar], point_child: bool) -> list[Element]:
        return []

    # -- template method -------------------------------------------------------------
    def elements(self, joint: ir.Joint, point_child: bool) -> list[Element]:
        roles = self.roles(joint, point_child)
        byrole = {jv.role: jv for jv in joint.variables}
        if len(joint.variables) != len(roles) or set(byrole) != set(roles):
            have = ", ".join(jv.role for jv in joint.variables) or "none"
            raise _err(joint, "E701",
                       f"{joint.kind} joint '{joint.name}' needs the variables ({', '.join(roles)}), has ({have})")
        return self.chain(joint, byrole, point_child)


class Revolute(JointKind):
    kind = "revolute"
    closure = Closure("all", "axis")

    def roles(self, joint, point_child):
        return ("phi",)

    def chain(self, joint, v, point_child):
        return [Element("R", (v["phi"],), axis=joint.axis)]


class Prismatic(JointKind):
    kind = "prismatic"
    closure = Closure("perp", "full")

    def roles(self, joint, point_child):
        return ("s",)

    def chain(self, joint, v, point_child):
        return [Element("P", (v["s"],), axis=joint.axis)]


class Cylindrical(JointKind):
    kind = "cylindrical"
    closure = Closure("perp", "axis")

    def roles(self, joint, point_child):
        return ("phi", "s")

    def chain(self, joint, v, point_child):
        return [Element("P", (v["s"],), axis=joint.axis), Element("R", (v["phi"],), axis=joint.axis)]


class Planar(JointKind):
    kind = "planar"
    closure = Closure("normal", "axis")

    def roles(self, joint, point_child):
        return ("x", "y") if point_child else ("x", "y", "phi")

    def chain(self, joint, v, point_child):
        e1, e2 = plane_axes(joint)
        out = [Element("P", (v["x"],), axis=e1), Element("P", (v["y"],), axis=e2)]
        if not point_child:
            out.append(Element("R", (v["phi"],), axis=joint.axis))
        return out


def plane_axes(joint: ir.Joint) -> tuple[ir.Vec3, ir.Vec3]:
    if joint.plane_axes is not None:
        return joint.plane_axes
    if not all(isinstance(c, ir.Const) for c in joint.axis):
        raise _err(joint, "E702", f"planar joint '{joint.name}' with a parametric normal needs plane axes")
    import numpy as np

    a = np.array([c.value for c in joint.axis], float)
    e1, e2 = ir.plane_basis(a / np.linalg.norm(a))
    return tuple(ir.Const(x) for x in e1), tuple(ir.Const(x) for x in e2)


class _Rotational(JointKind):
    """Spherical rotation: Euler angles in `sequence` or a unit quaternion."""

    def quaternion(self, joint) -> bool:
        par = joint.option("parametrization", "euler").lower()
        if par not in ("euler", "quaternion"):
            raise _err(joint, "E703", f"unknown parametrization '{par}' of joint '{joint.name}'",
                       "use parametrization = \"euler\" or \"quaternion\"")
        return par == "quaternion"

    def sequence(self, joint) -> tuple[int, int, int]:
        seq = joint.option("sequence", "zyx")
        try:
            return euler_sequence(seq)
        except ValueError:
            raise _err(joint, "E704", f"invalid Euler sequence '{seq}' of joint '{joint.name}'",
                       "three axes from x, y, z with no axis twice in a row, e.g. \"zyx\" or \"zxz\"") from None

    def rot_roles(self, joint):
        return QUAT_ROLES if self.quaternion(joint) else ("phi", "theta", "psi")

    def rot_chain(self, joint, v):
        if self.quaternion(joint):
            return [Element("Q", tuple(v[r] for r in QUAT_ROLES))]
        a, b, c = self.sequence(joint)
        return [Element("R", (v["phi"],), axis=UNIT[a]), Element("R", (v["theta"],), axis=UNIT[b]),
                Element("R", (v["psi"],), axis=UNIT[c])]


class Spherical(_Rotational):
    kind = "spherical"
    closure = Closure("all", "none")

    def roles(self, joint, point_child):
        return self.rot_roles(joint)

    def chain(self, joint, v, point_child):
        return self.rot_chain(joint, v)


class Free(_Rotational):
    kind = "free"
    closure = Closure("none", "none")

    def roles(self, joint, point_child):
        return ("x", "y", "z") + (() if point_child else self.rot_roles(joint))

    def chain(self, joint, v, point_child):
        out = [Element("P", (v[r],), axis=e) for r, e in zip(("x", "y", "z"), UNIT)]
        return out if point_child else out + self.rot_chain(joint, v)


class Fixed(JointKind):
    kind = "fixed"
    closure = Closure("all", "full")


class MovingFrame(JointKind):
    kind = "frame"
    closure = Closure("all", "full")

    def chain(self, joint, v, point_child):
        if joint.frame_r is None and joint.frame_R is None:
            return []
        R = joint.frame_R if joint.frame_R is not None else UNIT
        r = joint.frame_r if joint.frame_r is not None else (ir.ZERO, ir.ZERO, ir.ZERO)
        return [Element("T", (), R=R, r=r)]


KINDS: dict[str, JointKind] = {k.kind: k for k in (Revolute(), Prismatic(), Cylindrical(), Planar(),
                                                    Spherical(), Free(), Fixed(), MovingFrame())}


def kind_of(joint: ir.Joint) -> JointKind:
    try:
        return KINDS[joint.kind]
    except KeyError:
        raise _err(joint, "E700", f"unknown joint kind '{joint.kind}' of joint '{joint.name}'") from None
