"""Hand-built ir.Models for the mechanics tests and benchmarks (no front end needed)."""
from __future__ import annotations

import math

from mechdsl.model import ir
from mechdsl.model.exprs import const, div, mul, neg

Z, O = ir.ZERO, ir.ONE
P = ir.Param


def v3(x, y, z):
    return tuple(const(c) if isinstance(c, (int, float)) else c for c in (x, y, z))


def diag(a, b, c):
    return ((a, Z, Z), (Z, b, Z), (Z, Z, c))


def mat(rows):
    return tuple(tuple(const(x) if isinstance(x, (int, float)) else x for x in r) for r in rows)


def coord_var(role, name):
    return ir.JointVar(role, ir.Coord(name), name)


def rod_body(name, m, L):
    """Uniform slender rod along -y from its body origin (end a) to end b at (0, -L, 0)."""
    I = div(mul(m, mul(L, L)), const(12))
    body = ir.Body(name, "rigid", mass=m, com=(Z, neg(div(L, const(2))), Z), inertia=diag(I, Z, I),
                   shape="rod", shape_size=(L,), axis=v3(0, -1, 0))
    pts = [ir.Point(name, name), ir.Point(f"{name}.a", name), ir.Point(f"{name}.b", name, (Z, neg(L), Z))]
    return body, pts


def nlink(N: int, g=9.81, m=1.0, L=1.0) -> ir.Model:
    params = (ir.Parameter("m", m), ir.Parameter("l", L), ir.Parameter("g", g))
    bodies, points, joints, coords = [], [ir.Point("world", "world")], [], []
    for i in range(1, N + 1):
        b, pts = rod_body(f"link{i}", P("m"), P("l"))
        bodies.append(b)
        points += pts
        parent, pb = ("world", "world") if i == 1 else (f"link{i - 1}.b", f"link{i - 1}")
        joints.append(ir.Joint(f"j{i}", "revolute", parent, f"link{i}.a", pb, f"link{i}",
                               axis=v3(0, 0, 1), variables=(coord_var("phi", f"q{i}"),)))
        coords.append(ir.Coordinate(f"q{i}", start=const(math.pi / 2 if i == 1 else 0.0), owner=f"j{i}"))
    return ir.Model(f"NLink{N}", parameters=params, coordinates=tuple(coords), bodies=tuple(bodies),
                    points=tuple(points), joints=tuple(joints),
                    forces=(ir.Gravity("gravity", (Z, neg(P("g")), Z)),),
                    outputs=(ir.Output("x_tip", ir.PointPos(f"link{N}.b", 0)),
                             ir.Output("E", ir.EnergyRef("energy"))))


# --------------------------------------------------------------------------- generic test chains

def rigid(name, m, com, I):
    return ir.Body(name, "rigid", mass=const(m), com=v3(*com), inertia=mat(I))


def point(name, body, r=(0, 0, 0)):
    return ir.Point(name, body, v3(*r))


def fn(op, *args):
    return ir.Op(op, tuple(args))


def rot_z_expr(angle):
    c, s = fn("cos", angle), fn("sin", angle)
    return ((c, neg(s), Z), (s, c, Z), (Z, Z, O))


def t_expr(a=0.0, b=0.0, w=0.0, c=0.0):
    """a + b*t + c*sin(w*t) as an IR expression of time."""
    t = ir.Time()
    e = const(a)
    e = ir.Op("add", (e, mul(const(b), t)))
    if c:
        e = ir.Op("add", (e, mul(const(c), fn("sin", mul(const(w), t)))))
    return e


IA = ((0.30, 0.02, -0.01), (0.02, 0.40, 0.03), (-0.01, 0.03, 0.50))
IB = ((0.20, -0.03, 0.00), (-0.03, 0.25, 0.01), (0.00, 0.01, 0.15))
ROLES = {"revolute": ("phi",), "prismatic": ("s",), "cylindrical": ("phi", "s"),
         "planar": ("x", "y", "phi"), "spherical": ("phi", "theta", "psi"),
         "free": ("x", "y", "z", "phi", "theta", "psi"), "fixed": (), "frame": ()}


def joint_chain(kind: str, *, options=(), axis=(0.48, 0.6, 0.64), prescribed: dict | None = None,
                point_child=False, second=True, spring=True, frame=None) -> ir.Model:
    """world --kind--> A --revolute--> B, with gravity and a spring; every variable of the
    joint under test is a coordinate unless `prescribed` maps its role to an IR expression."""
    prescribed = prescribed or {}
    opts = dict(options)
    roles = ROLES[kind]
    if kind in ("spherical", "free") and opts.get("parametrization") == "quaternion":
        roles = roles[:-3] + ("q0", "q1", "q2", "q3")
    if point_child:
        roles = {"free": ("x", "y", "z"), "planar": ("x", "y")}.get(kind, roles)
    jvars, coords = [], []
    for r in roles:
        if r in prescribed:
            jvars.append(ir.JointVar(r, prescribed[r]))
        else:
            jvars.append(coord_var(r, f"jA.{r}"))
            coords.append(ir.Coordinate(f"jA.{r}", start=const(1.0 if r == "q0" else 0.0)))
    bodies = [ir.Body("A", "point", mass=const(1.3)) if point_child else rigid("A", 1.3, (0.1, -0.2, 0.05), IA)]
    points = [point("world", "world"), point("anchor", "world", (0.1, 0.2, -0.3)), point("A", "A"),
              point("A.p", "A", (0.2, -0.1, 0.05)), point("A.q", "A", (0.0, -0.6, 0.1))]
    parent, pbody = "anchor", "world"
    joints = []
    if frame is not None:        # a moving frame F between the world and the joint under test
        bodies.append(ir.Body("F", "frame"))
        points += [point("F", "F"), point("F.o", "F", (0.0, 0.0, 0.0)), point("F.p", "F", (0.3, 0.0, 0.0))]
        joints.append(ir.Joint("jF", "frame", "anchor", "F.o", "world", "F", frame_R=frame[0], frame_r=frame[1]))
        parent, pbody = "F.p", "F"
    joints.append(ir.Joint("jA", kind, parent, "A.p", pbody, "A", axis=v3(*axis), variables=tuple(jvars),
                           options=tuple(options)))
    forces = [ir.Gravity("gravity", v3(0, -9.81, 0))]
    if second:
        bodies.append(rigid("B", 0.7, (0.0, -0.3, 0.02), IB))
        points += [point("B", "B"), point("B.c", "B", (0.05, 0.1, 0.0)), point("B.tip", "B", (0.0, -0.7, 0.0))]
        joints.append(ir.Joint("jB", "revolute", "A.q", "B.c", "A", "B", axis=v3(0.3, 0.5, 0.8),
                               variables=(coord_var("phi", "jB.phi"),)))
        coords.append(ir.Coordinate("jB.phi", start=const(0.3)))
        if spring:
            forces.append(ir.SpringDamper("spr", "spring-damper", "anchor", "B.tip", k=const(20.0),
                                          c=const(0.7), l0=const(0.5)))
    return ir.Model(f"chain_{kind}", coordinates=tuple(coords), bodies=tuple(bodies), points=tuple(points),
                    joints=tuple(joints), forces=tuple(forces))
