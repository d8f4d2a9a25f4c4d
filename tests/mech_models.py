"""Hand-built ir.Models for the mechanics tests and benchmarks (no front end needed)."""
from __future__ import annotations

import math

from mechdsl import ir
from mechdsl.exprs import const, div, mul, neg

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
