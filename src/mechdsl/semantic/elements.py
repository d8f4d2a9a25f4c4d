"""Component declarations (`Revolute j1(...)`, arrays of them) and their elements: the value of a
field (modifier, connect(...), default; split or broadcast over an array), its check, the massless
frame of a child-less joint named as a point or body (issue 17), and the body a point lies on.
A mixin of :class:`~mechdsl.semantic.flatten.Flattener`."""
from __future__ import annotations

from ..model import ir
from ..diagnostics import Span, did_you_mean
from . import components as K
from . import values as V
from .entries import CompInst, Entry, Failed, pick
from .evaluate import fail
from .values import Arr, CompRef, Scalar, Str, Val, ValError
from .vector_starts import VECTOR_STARTS

FIELD_RANK = {"scalar": 0, "vec3": 1, "mat3": 2, "point": 0, "body": 0, "bodies": 1, "coordinate": 0,
              "string": 0, "bool": 0, "vector": 1}


class ComponentElements:
    def _component(self, e: Entry, dims: tuple[int, ...]) -> Val:
        d = e.decl
        if len(dims) > 1:
            fail("E301", "arrays of components have one dimension", d.span, f"write {d.type_name} {d.name}[n](...)")
        cartesian = {"x", "y", "z"} if e.cls.name == "PointMass" and ("r" in e.mod.sub or "v" in e.mod.sub) else set()
        allowed = {f.name for f in e.cls.fields} | {r for r, _ in e.cls.roles} | set(VECTOR_STARTS.get(e.cls.name, ())) | cartesian | (
            {r for r, _ in K.QUATERNION_ROLES} if e.cls.name in ("Spherical", "Free") else set())
        for k, m in e.mod.sub.items():
            if k not in allowed:
                fail("E204", f"{e.cls.name} has no field '{k}'", m.name_span,
                     did_you_mean(k, allowed) or "fields: " + ", ".join(f.name for f in e.cls.fields))
        if not e.elements:
            if dims:
                e.elements = [CompInst(f"{d.name}[{k + 1}]", e, k) for k in range(dims[0])]
            else:
                e.elements = [CompInst(d.name, e, -1)]
            for inst in e.elements:
                self.insts[inst.name] = inst
        kind = {"body": "body", "point": "point", "frame": "body", "joint": "joint", "force": "force",
                "contact": "contact", "shape": "shape"}[e.cls.category]
        refs = [CompRef(kind, i.name, e.cls.name) for i in e.elements]
        return Arr(tuple(refs)) if dims else refs[0]

    def _elements(self, e: Entry) -> list[CompInst]:
        self.value_of(e)
        return e.elements

    def field_value(self, inst: CompInst, fname: str) -> Val | None:
        """The value of one field of a component element (None when optional and absent)."""
        if fname in inst.fields:
            return inst.fields[fname]
        cls = inst.cls
        f = cls.field(fname)
        assert f is not None, fname
        if fname in inst.connections:
            val = inst.connections[fname]
        else:
            m = inst.entry.mod.sub.get(fname)
            if m is not None and m.value is not None:
                key = ("field", fname)
                if (fname, "busy") in inst.busy:
                    fail("E208", f"'{inst.name}.{fname}' is defined in terms of itself", m.value.span,
                         "break the cycle of definitions")
                inst.busy.add((fname, "busy"))
                try:
                    if key not in inst.entry.cache:
                        inst.entry.cache[key] = self.eval(m.value)
                finally:
                    inst.busy.discard((fname, "busy"))
                val = pick(inst.entry.cache[key], inst, FIELD_RANK[f.kind], m.each)
                val = self._frame_of_joint(val, f, m.value.span)
                self._check_field(inst, f, val, m.value.span)
            elif f.default is K.REQUIRED:
                hint = None
                if cls.connect_fields and fname in cls.connect_fields and self.connect_failed:
                    raise Failed()  # most likely set by the connect(...) already reported
                if cls.connect_fields and fname in cls.connect_fields:
                    hint = f"set it with {fname} = ..., or connect({cls.connect_fields[0]}, {inst.entry.decl.name}, " \
                           f"{cls.connect_fields[1]}) in the equation section"
                fail("E210", f"{cls.name} '{inst.name}' needs '{fname}'", inst.entry.decl.name_span,
                     hint or f"add {fname} = ... to its modifiers")
                raise AssertionError
            elif f.default is None:
                val = None
            elif f.default == "world":
                val = CompRef("world", "world", "World")
            else:
                val = K.python_to_val(f.default)
        inst.fields[fname] = val
        return val

    def _frame_of_joint(self, val: Val, f: K.Field | None, span: Span) -> Val:
        """A joint named where a body or point is expected (`parent = turn`) means the joint's
        own massless frame, when the joint has no child of its own (issue 17)."""
        if not (isinstance(val, CompRef) and val.kind == "joint") or (f is not None and f.kind not in ("point", "body")):
            return val
        inst = self.insts.get(val.name)
        if inst is None or inst.cls.field("child") is None:
            return val
        child = self.field_value(inst, "child")
        if child is not None:
            fail("E209", f"joint '{val.name}' has the child '{child.name}' (a joint is not a point)", span,  # type: ignore[union-attr]
                 f"name its child ({child.name}) or a point on it; a joint without a child is a massless frame"  # type: ignore[union-attr]
                 " that others can use")
        self.joint_frames.add(val.name)
        return CompRef("body", val.name, "JointFrame")

    def _check_field(self, inst: CompInst, f: K.Field, val: Val, span: Span) -> None:
        try:
            if f.kind in ("point", "body"):
                if not isinstance(val, CompRef):
                    fail("E209", f"'{f.name}' of {inst.cls.name} '{inst.name}' must be a {f.kind}, "
                                 f"got {V.describe_shape(val)}", span,
                         "name a body, a point on a body (e.g. rod.a) or world" if f.kind == "point"
                         else "name a body or world")
                ok = {"point": ("point", "body", "world"), "body": ("body", "world")}[f.kind]
                if val.kind not in ok:
                    fail("E209", f"'{f.name}' of '{inst.name}' must be a {f.kind}, got the {val.kind} '{val.name}'", span,
                         "name a body, a point on a body (e.g. rod.a) or world" if f.kind == "point"
                         else "name a body or world")
            elif f.kind == "bodies":
                items = val.items if isinstance(val, Arr) else ()
                if not items or not all(isinstance(i, CompRef) and i.kind == "body" for i in items):
                    fail("E209", f"'{f.name}' must be a list of bodies", span, "e.g. bodies = {sun, earth}")
            elif f.kind == "string":
                if not isinstance(val, Str):
                    fail("E301", f"'{f.name}' must be a string", span,
                         f'{f.name} = "{f.choices[0] if f.choices else "..."}"')
                if f.choices and val.value not in f.choices:
                    fail("E217", f"'{val.value}' is not a valid {f.name}", span,
                         "choose one of: " + ", ".join(f.choices))
            elif f.kind == "coordinate":
                if not (isinstance(val, Scalar) and isinstance(val.expr, ir.Coord)):
                    fail("E218", f"'{f.name}' must be a coordinate", span, "name a `coordinate` or a joint variable such as j1.phi")
            elif f.kind in ("scalar", "bool"):
                if not isinstance(val, Scalar):
                    fail("E301", f"'{f.name}' of '{inst.name}' must be a scalar, got {V.describe_shape(val)}", span,
                         "give one number or expression")
                if f.dim is not None:
                    self.check_dim(val, f.dim, f"'{f.name}' of '{inst.name}'", span)
            elif f.kind == "vector":
                if not isinstance(val, Arr) or len(V.shape_of(val)) != 1 or not 1 <= V.shape_of(val)[0] <= 3:
                    fail("E301", f"'{f.name}' of '{inst.name}' must be a vector of 1 to 3 numbers, "
                                 f"got {V.describe_shape(val)}", span, "e.g. {0.1, 0.2, 0.3}")
                if f.dim is not None:
                    for s in V.flatten(val):
                        self.check_dim(s, f.dim, f"'{f.name}' of '{inst.name}'", span)
            elif f.kind in ("vec3", "mat3"):
                want = (3,) if f.kind == "vec3" else (3, 3)
                if not isinstance(val, Arr) or V.shape_of(val) != want:
                    fail("E301", f"'{f.name}' of '{inst.name}' must be {'a vector of 3' if f.kind == 'vec3' else 'a 3x3 matrix'}, "
                                 f"got {V.describe_shape(val)}", span,
                         "write it as {x, y, z}" if f.kind == "vec3" else "write it as {{..}, {..}, {..}}")
                if f.dim is not None:
                    for s in V.flatten(val):
                        self.check_dim(s, f.dim, f"'{f.name}' of '{inst.name}'", span)
        except ValError as ve:
            fail(ve.code, ve.message, span, ve.help)

    def _body_class_of(self, ref: CompRef) -> str:
        base = ref.name
        inst = self.insts.get(base)
        if inst is None and "." in base:
            inst = self.insts.get(base.rsplit(".", 1)[0])
        if inst is None:
            return ""
        if inst.cls.name == "Point":
            b = self.field_value(inst, "body")
            return self._body_class_of(b) if isinstance(b, CompRef) and b.name != inst.name else ""
        return inst.cls.name

    def body_of_point(self, pname: str) -> str:
        """The body a point name lies on ('world' for world points)."""
        if pname == "world":
            return "world"
        inst = self.insts.get(pname)
        if inst is not None:
            if inst.cls.name == "Point":
                b = self.field_value(inst, "body")
                return self.body_of_point(b.name)  # type: ignore[union-attr]
            return inst.name
        return self.body_of_point(pname.rsplit(".", 1)[0])
