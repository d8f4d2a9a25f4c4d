"""IR construction: after the declarations and equations are evaluated, the components' IR bodies,
points, joints, forces and contacts (`build_component`) and the `ir.Model` of the whole
(`build_model`), with the check for unused child-less joints (E210) and topology.py's checks.
Functions of the :class:`~mechdsl.semantic.flatten.Flattener` `fl`: they read its state."""
from __future__ import annotations

from ..model import exprs as X
from ..model import ir
from . import components as K
from . import orientation as O
from .entries import CompInst, Failed
from .evaluate import EvalError, fail
from .friction import friction_force
from .values import Arr, CompRef, Scalar, Str, Val, ValError


def build_model(fl) -> ir.Model:
    """The IR model of the evaluated declarations, components and equations, checked by topology.py."""
    params, coords, outputs = [], [], []
    built = K.Built()
    for e in sorted(fl.entries.values(), key=lambda x: x.order):
        if e.state != 2:
            continue
        params += e.params
        coords += e.coords
        outputs += e.outputs
        if e.kind == "component":
            for inst in e.elements:
                try:
                    b = build_component(fl, inst)
                except EvalError as ex:
                    fl.diags.items.append(ex.diag)
                    continue
                except Failed:
                    continue
                except ValError as ve:
                    fl.diags.error(ve.code, ve.message, inst.entry.decl.span, ve.help)
                    continue
                coords += inst.coords
                for k in ("bodies", "points", "joints", "forces", "terms", "contacts", "shapes"):
                    getattr(built, k).extend(getattr(b, k))
        # joints own coordinates too: the exact count, located at the declaration that passes it
        fl.charge("coordinates", 0, e.decl.span, total=len(coords))
    for j in built.joints:
        jinst = fl.insts.get(j.name)
        if (j.child == j.name and j.name not in fl.joint_frames and jinst is not None
                and not fl.connect_failed):
            cn = jinst.cls.connect_fields
            fl.diags.error("E210", f"{jinst.cls.name} '{j.name}' needs 'child'", jinst.entry.decl.name_span,
                           f"set it with child = ..., or connect({cn[0]}, {jinst.entry.decl.name}, {cn[1]}) in the "
                           f"equation section; a joint without a child is a massless frame only when another "
                           f"joint or point uses it (parent = {j.name})")
    fl.diags.raise_if_errors()
    forces = built.forces + fl.gen_forces
    model = ir.Model(
        name=fl.model.name, doc=fl.model.doc or "", parameters=tuple(params), coordinates=tuple(coords),
        bodies=tuple(built.bodies), points=(ir.Point("world", "world", span=fl.model.span),) + tuple(built.points),
        joints=tuple(built.joints), forces=tuple(forces), terms=tuple(built.terms + fl.terms),
        constraints=tuple(fl.constraints), outputs=tuple(outputs), contacts=tuple(built.contacts),
        span=fl.model.span, shapes=tuple(built.shapes))
    from .topology import check_model

    return check_model(model, fl.diags)


def _fields(fl, inst: CompInst) -> dict[str, Val | None]:
    return {f.name: fl.field_value(inst, f.name) for f in inst.cls.fields}


def build_component(fl, inst: CompInst) -> K.Built:
    if inst.built is not None:
        return inst.built
    cls, span, name = inst.cls, inst.entry.decl.span, inst.name
    f = _fields(fl, inst)
    out = K.Built()
    if cls.category == "body":
        if cls.name == "Body" and f.get("I") is not None:
            if any(n.startswith("I_") and inst.entry.mod.sub.get(n) for n in f):
                fail("E211", f"give either I or I_11 ... I_32 for '{name}', not both", span, "remove one of them")
        out = K.build_body(cls, name, f, span)
        if cls.name == "PointMass":
            j = fl._cartesian_point_mass(inst, span)
            if j is not None:
                out.joints.append(j)
    elif cls.category == "point":
        body = f["body"]
        out.points.append(ir.Point(name, fl.body_of_point(body.name), K.as_vec3(f["r"], "r"), span,
                                   O.given_orientation(f, name)))
    elif cls.category == "shape":
        out.shapes.append(_build_shape(fl, inst, f, span))
    elif cls.category == "frame":
        parent = f["parent"]
        axis = K.normalized(K.as_vec3(f["axis"], "axis"), "axis")
        R = O.given_orientation(f, name)
        if R is not None:
            if inst.entry.mod.sub.get("angle") is not None:
                fail("E211", f"give either {'R' if f.get('R') is not None else 'rpy'} or axis and angle for "
                             f"'{name}', not both", span, "remove one of them")
        else:
            R = K.rodrigues(axis, K.as_expr(f["angle"], "angle"))
        for c in [*K.as_vec3(f["r"], "r"), *(x for row in R for x in row)]:
            if X.depends_on_state(c):
                fail("E306", f"the motion of frame '{name}' may depend on time and parameters only", span,
                     "a frame moves as a prescribed function of time")
        z = X.const(0.0)
        out.bodies.append(ir.Body(name, "frame", span=span))
        out.points += [ir.Point(name, name, (z, z, z), span)]
        out.joints.append(ir.Joint(f"{name}.motion", "frame", parent.name, name, fl.body_of_point(parent.name),
                                   name, (z, z, X.const(1.0)), (), None, K.as_vec3(f["r"], "r"), R, (), False,
                                   span, parent_R=point_axes(fl, parent.name)))
    elif cls.category == "joint":
        out.joints.append(_build_joint(fl, inst, f, span, out))
    elif cls.category == "force":
        out = _build_force(fl, inst, f, span)
    elif cls.category == "contact":
        fields = []
        for fl in cls.fields:
            v = f[fl.name]
            if isinstance(v, CompRef):
                fields.append((fl.name, v.name))
            elif isinstance(v, Str):
                fields.append((fl.name, v.value))
            elif isinstance(v, Arr):
                fields.append((fl.name, K.as_vec3(v, fl.name)))
            elif isinstance(v, Scalar):
                fields.append((fl.name, v.expr))
        out.contacts.append(ir.Contact(name, _contact_kind(fl, inst, f, span), tuple(fields), span))
    inst.built = out
    return out


def _build_shape(fl, inst: CompInst, f, span) -> ir.Shape:
    """A Shape: what is drawn, where on its body and turned how; all of it constant in time."""
    name = inst.name
    kind, size, axis = K.drawn_shape(f)
    r = K.as_vec3(f["r"], "r")
    R = O.given_orientation(f, name)
    for c in [*size, *r, *axis, *(x for row in (R or ()) for x in row)]:
        if X.depends_on_state(c) or X.depends_on_time(c):
            fail("E306", f"the size and placement of shape '{name}' may depend on parameters only", span,
                 "a shape is fixed on its body; it moves with the body")
    return ir.Shape(name, fl.body_of_point(f["body"].name), kind, size, r, R, axis, span)


def _contact_kind(fl, inst: CompInst, f, span) -> str:
    """'fix' (Fixation), 'gap' (Contact with a gap expression) or the Contact's surface."""
    if inst.cls.name == "Fixation":
        return "fix"
    gap = f.get("gap")
    if gap is not None:
        if f.get("point") is not None:
            fail("E211", f"give either a gap or a point for contact '{inst.name}', not both", span)
        if X.has_speed(gap.expr):
            fail("E306", f"the gap of contact '{inst.name}' may depend on coordinates and time, not on speeds",
                 span)
        return "gap"
    if f.get("point") is None:
        fail("E210", f"Contact '{inst.name}' needs 'point' (or a 'gap' expression)", inst.entry.decl.name_span,
             "add point = ... (and surface, normal, ...) or gap = ... to its modifiers")
    return f["surface"].value


def _build_joint(fl, inst: CompInst, f, span, out: K.Built) -> ir.Joint:
    cls, name = inst.cls, inst.name
    if cls.name == "RigidLink":
        a, b = f["a"], f["b"]
        end = f"{name}.end"
        out.points.append(ir.Point(end, fl.body_of_point(a.name), K.as_vec3(f["r"], "r"), span))
        z = X.const(0.0)
        return ir.Joint(name, "fixed", end, _point_name(b), fl.body_of_point(a.name), fl.body_of_point(b.name),
                        (z, z, X.const(1.0)), (), None, None, None, (), False, span,
                        child_R=point_axes(fl, _point_name(b)))
    parent, child = f["parent"], f["child"]
    if child is None:                   # the joint's own massless frame
        z = X.const(0.0)
        out.bodies.append(ir.Body(name, "frame", span=span))
        out.points.append(ir.Point(name, name, (z, z, z), span))
        child = CompRef("body", name, "JointFrame")
    pb, cb = fl.body_of_point(parent.name), fl.body_of_point(child.name)
    kind = cls.name.lower()
    axis = K.normalized(K.as_vec3(f["axis"], "axis"), "axis") if cls.field("axis") else (
        X.const(0.0), X.const(0.0), X.const(1.0))
    options = []
    if cls.field("sequence"):
        seq = f["sequence"].value
        try:
            K.check_sequence(seq)
        except ValError as ve:
            fail(ve.code, ve.message, inst.entry.mod.sub["sequence"].value.span if "sequence" in inst.entry.mod.sub else span, ve.help)
        options = [("parametrization", f["parametrization"].value), ("sequence", seq)]
    plane = None
    if kind == "planar":
        try:
            plane = K.plane_axes(axis)
        except ValError as ve:
            fail(ve.code, ve.message, span, ve.help)
    jv = fl.joint_vars(inst)
    P, C = joint_axes(fl, inst)
    return ir.Joint(name, kind, _point_name(parent), _point_name(child), pb, cb, axis, tuple(jv), plane,
                    None, None, tuple(options), False, span, parent_R=P, child_R=C)


def joint_axes(fl, inst: CompInst) -> tuple[ir.Mat3 | None, ir.Mat3 | None]:
    """(P, C): the axes of a joint's parent joint frame in the parent body (the parent point's
    orientation, then the joint's own rpy / R) and of its child joint frame in the child body
    (the child point's orientation); None where they are the body's axes."""
    parent, child = fl.field_value(inst, "parent"), fl.field_value(inst, "child")
    own = {k: fl.field_value(inst, k) for k in ("rpy", "R")}
    P = O.compose(point_axes(fl, _point_name(parent)), O.given_orientation(own, inst.name))
    return P, (point_axes(fl, _point_name(child)) if child is not None else None)


def point_axes(fl, pname: str) -> ir.Mat3 | None:
    """The orientation of a named point in its body's axes (None: the body's own axes)."""
    inst = fl.insts.get(pname)
    if inst is None or inst.cls.name != "Point":
        return None
    try:
        return O.given_orientation({k: fl.field_value(inst, k) for k in ("rpy", "R")}, pname)
    except ValError:
        raise Failed() from None       # reported where the point is built


def _build_force(fl, inst: CompInst, f, span) -> K.Built:
    cls, name = inst.cls, inst.name
    out = K.Built()
    e = K.as_expr
    if cls.name == "Gravity":
        out.forces.append(ir.Gravity(name, K.as_vec3(f["g"], "g"), span))
    elif cls.name in ("Spring", "Damper", "SpringDamper"):
        a, b = _point_name(f["a"]), _point_name(f["b"])
        if a == b:
            fail("E503", f"{cls.name} '{name}' connects a point to itself", span, "a and b must be different points")
        zero = X.const(0.0)
        kind = {"Spring": "spring", "Damper": "damper", "SpringDamper": "spring-damper"}[cls.name]
        out.forces.append(ir.SpringDamper(name, kind, a, b, e(f["k"], "k") if "k" in f else zero,
                                          e(f["c"], "c") if "c" in f else zero,
                                          e(f["l0"], "l0") if "l0" in f else zero, span))
    elif cls.name == "Force":
        out.forces.append(ir.AppliedForce(name, _point_name(f["point"]), K.as_vec3(f["F"], "F"),
                                          f["frame"].name, span))
    elif cls.name == "Torque":
        out.forces.append(ir.AppliedTorque(name, f["body"].name, K.as_vec3(f["tau"], "tau"), f["frame"].name, span))
    elif cls.name == "GeneralizedForce":
        out.forces.append(ir.GeneralizedForce(name, f["coordinate"].expr.name, e(f["Q"], "Q"), span))
    elif cls.name == "Friction":
        out.forces.append(friction_force(fl, name, f, span))
    elif cls.name == "Gravitation":
        names = tuple(b.name for b in f["bodies"].items)
        if len(set(names)) != len(names):
            fail("E202", f"a body appears twice in '{name}'", span, "list each body once")
        out.forces.append(ir.Gravitation(name, names, e(f["G"], "G"), span))
    elif cls.name == "Potential":
        v = f["V"]
        if X.has_speed(v.expr):
            fail("E308", f"potential '{name}' must not depend on speeds", span,
                 "velocity-dependent forces go into a Force, GeneralizedForce or the dissipation function")
        out.terms.append(ir.Term("potential", v.expr, name, span))
    return out


# ---------------------------------------------------------------------------- helpers


def _point_name(v: Val) -> str:
    assert isinstance(v, CompRef)
    return v.name
