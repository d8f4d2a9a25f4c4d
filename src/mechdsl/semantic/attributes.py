"""`value.name` on component references: world's, a point's or body's kinematic quantities
(r, v, a, x, y, z, R, w, w_body, alpha as IR queries), named points (rod.a), joint variables
(j1.phi) and fields. A mixin of :class:`~mechdsl.semantic.flatten.Flattener`."""
from __future__ import annotations

from ..model import ir
from ..model import units as U
from ..diagnostics import Span, did_you_mean
from . import components as K
from . import values as V
from .evaluate import fail
from .values import Arr, CompRef, Scalar, Val


class Attributes:
    def attribute(self, value: Val, name: str, span: Span) -> Val:
        if isinstance(value, Arr):
            return Arr(tuple(self.attribute(v, name, span) for v in value.items))
        if not isinstance(value, CompRef):
            fail("E219", f"{V.describe_shape(value)} has no attribute '{name}'", span,
                 "attributes (.x, .r, .R, .phi, ...) belong to components")
        if value.kind == "world":
            zero = V.const(0.0)
            table = {"r": Arr((zero,) * 3), "v": Arr((zero,) * 3), "a": Arr((zero,) * 3), "x": zero, "y": zero,
                     "z": zero, "w": Arr((zero,) * 3), "w_body": Arr((zero,) * 3), "alpha": Arr((zero,) * 3), "R": Arr(tuple(Arr(tuple(V.const(float(i == j)) for j in range(3)))
                                                        for i in range(3)))}
            if name in table:
                return table[name]
            fail("E219", f"world has no attribute '{name}'", span, "world has r, v, a, x, y, z, R, w, w_body, alpha")
        if value.kind == "joint" and name in ("r", "v", "a", "x", "y", "z", "R", "w", "w_body", "alpha"):
            jinst = self.insts.get(value.name)     # a child-less joint's frame; a joint variable (f.x) wins
            if (jinst is not None and jinst.cls.field("child") is not None and self.field_value(jinst, "child") is None
                    and name not in [jv.role for jv in self.joint_vars(jinst)]):
                value = self._frame_of_joint(value, None, span)
        if value.kind in ("point", "body"):
            inst = self.insts.get(value.name)
            if inst is not None and name in inst.cls.points:   # rod.a is Rod's end point a, not an acceleration
                return CompRef("point", f"{inst.name}.{name}", "Point")
            if inst is not None and inst.cls.name == "Point" and name == "R":
                return self._point_rotation(inst.name, span)
            kin = _kinematic_attr(value, name)
            if kin is not None:
                return kin
        inst = self.insts.get(value.name)
        if inst is None:  # a named point of a body (rod.a) or a derived point
            fail("E219", f"'{value.name}' has no attribute '{name}'", span, "points have r, v, a, x, y, z")
        cls = inst.cls
        if name in cls.points:
            return CompRef("point", f"{inst.name}.{name}", "Point")
        if cls.category == "joint":
            for jv in self.joint_vars(inst):
                if jv.role == name:
                    dim = dict(cls.roles + K.QUATERNION_ROLES).get(name)
                    return Scalar(jv.motion, dim)
        f = cls.field(name)
        if f is not None:
            val = self.field_value(inst, name)
            if val is None:
                fail("E219", f"'{inst.name}.{name}' is not set", span, f"give it a value: {name} = ... in the modifiers")
            return val
        roles = [jv.role for jv in self.joint_vars(inst)] if cls.category == "joint" else []
        opts = list(cls.points) + [f.name for f in cls.fields] + roles
        if cls.category in ("body", "point", "frame"):
            opts += ["r", "v", "a", "x", "y", "z", "R"] + (["w", "w_body", "alpha"] if cls.category != "point" else [])
        fail("E219", f"{cls.name} '{inst.name}' has no attribute '{name}'", span,
             did_you_mean(name, opts) or ("attributes: " + ", ".join(dict.fromkeys(opts)) if opts else None))
        raise AssertionError


    def _point_rotation(self, pname: str, span: Span) -> Val:
        """`p.R` of a named point: its axes in world axes (its body's R times its own orientation)."""
        from .assemble import point_axes
        from .orientation import matrix_value

        body = self.body_of_point(pname)
        base = self.attribute(CompRef("world" if body == "world" else "body", body, "Body"), "R", span)
        axes = point_axes(self, pname)
        return base if axes is None else V.mul(base, matrix_value(axes))


def _kinematic_attr(ref: CompRef, name: str) -> Val | None:
    p = ref.name
    if name == "r":
        return Arr(tuple(Scalar(ir.PointPos(p, i), U.LENGTH) for i in range(3)))
    if name == "v":
        return Arr(tuple(Scalar(ir.PointVel(p, i), U.VELOCITY) for i in range(3)))
    if name == "a":
        return Arr(tuple(Scalar(ir.PointAcc(p, i), U.ACCEL) for i in range(3)))
    if name in ("x", "y", "z"):
        return Scalar(ir.PointPos(p, "xyz".index(name)), U.LENGTH)
    if ref.kind == "body" and ref.type_name not in ("Point",):
        if name == "R":
            return Arr(tuple(Arr(tuple(Scalar(ir.BodyRot(p, i, j), U.ONE) for j in range(3))) for i in range(3)))
        if name in ("w", "w_body"):
            frame = "world" if name == "w" else "body"
            return Arr(tuple(Scalar(ir.BodyOmega(p, i, frame), U.dim(s=-1)) for i in range(3)))
        if name == "alpha":
            return Arr(tuple(Scalar(ir.BodyAlpha(p, i), U.dim(s=-2)) for i in range(3)))
    return None
