"""A joint's variables (`j1.phi`, ...): each role bound to an expression (`phi = q`,
`phi = omega*time`) or to a coordinate the joint owns (`j1.phi`, with its start, speed and fixed
attributes from the role's modifier), then the vector starts rewrite those coordinates. A mixin of
:class:`~mechdsl.semantic.flatten.Flattener`."""
from __future__ import annotations

from ..model import exprs as X
from ..model import ir
from ..model import units as U
from . import components as K
from . import values as V
from .entries import COORD_ATTRS, CompInst, constval, pick
from .evaluate import fail
from .mods import Mod
from .values import CompRef, Scalar


class JointVariables:
    def joint_vars(self, inst: CompInst) -> list[ir.JointVar]:
        if inst.jointvars is not None:
            return inst.jointvars
        if ("jointvars", "busy") in inst.busy:
            fail("E208", f"the variables of joint '{inst.name}' are defined in terms of themselves",
                 inst.entry.decl.name_span, "break the cycle of definitions")
        inst.busy.add(("jointvars", "busy"))
        try:
            cls = inst.cls
            param = "euler"
            if cls.field("parametrization") is not None:
                param = self.field_value(inst, "parametrization").value  # type: ignore[union-attr]
            child = self.field_value(inst, "child") if cls.field("child") is not None else None   # RigidLink: b
            point_mass_child = isinstance(child, CompRef) and self._body_class_of(child) == "PointMass"
            roles = K.joint_roles(cls, param, point_mass_child)
            out: list[ir.JointVar] = []
            for role, dim in roles:
                m = inst.entry.mod.sub.get(role)
                if m is not None and m.value is not None:
                    key = ("role", role)
                    if key not in inst.entry.cache:
                        inst.entry.cache[key] = self.eval(m.value)
                    v = pick(inst.entry.cache[key], inst, 0, m.each)
                    if not isinstance(v, Scalar):
                        fail("E301", f"joint variable '{role}' of '{inst.name}' must be a scalar, "
                                     f"got {V.describe_shape(v)}", m.value.span,
                             f"bind it to a coordinate ({role} = q) or a function of time ({role} = omega*time)")
                    self.check_dim(v, dim, f"'{role}' of '{inst.name}'", m.value.span)
                    if X.has_speed(v.expr):
                        fail("E308", f"joint variable '{role}' of '{inst.name}' depends on speeds", m.value.span,
                             "a joint's motion may depend on coordinates and time only")
                    if m.sub:
                        fail("E214", f"'{role}' of '{inst.name}' is bound to an expression", m.span,
                             "set start values on the coordinate itself: coordinate Real q(start = ...)")
                    coord = v.expr.name if isinstance(v.expr, ir.Coord) else None
                    out.append(ir.JointVar(role, v.expr, coord))
                    continue
                c = self._own_coordinate(inst, role, "rad" if dim == U.ONE else "m", inst.name,
                                         {"start": X.const(1.0 if role == "q0" else 0.0)})
                inst.coords.append(c)
                out.append(ir.JointVar(role, ir.Coord(c.name), c.name))
            self._vector_starts(inst, out, param)
            inst.jointvars = out
            return out
        finally:
            inst.busy.discard(("jointvars", "busy"))

    def _own_coordinate(self, inst: CompInst, role: str, unit: str, owner: str, defaults: dict) -> ir.Coordinate:
        """The coordinate `<inst>.<role>` a component owns, with the attributes of its modifier
        `role(start = .., speed = .., fixed = .., speed_fixed = ..)` over `defaults`."""
        m = inst.entry.mod.sub.get(role)
        sub = m.sub if m is not None else {}
        self._check_attrs(Mod(sub=sub), COORD_ATTRS)
        name = f"{inst.name}.{role}"
        vals = {"start": X.const(0.0), "speed": X.const(0.0), "fixed": X.const(1.0), "speed_fixed": X.const(1.0)}
        vals.update(defaults)
        for attr in vals:
            sm = sub.get(attr)
            if sm is None or sm.value is None:
                continue
            key = ("role", role, attr)
            if key not in inst.entry.cache:
                inst.entry.cache[key] = self.eval(sm.value)
            v = pick(inst.entry.cache[key], inst, 0, sm.each)
            if not isinstance(v, Scalar):
                fail("E301", f"{attr} of '{name}' must be a scalar", sm.value.span, f"e.g. {role}({attr} = 0)")
            if X.depends_on_state(v.expr) or X.depends_on_time(v.expr):
                fail("E306", f"the {attr} value may only depend on parameters", sm.value.span,
                     "start values are numbers or expressions in parameters")
            vals[attr] = v.expr
        return ir.Coordinate(name, vals["start"], vals["speed"], bool(constval(vals["fixed"])),
                             bool(constval(vals["speed_fixed"])), unit, "", owner, inst.entry.decl.name_span)
