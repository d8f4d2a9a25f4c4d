"""The .mech text of an imported robot: component-layer declarations in the tree's order, each
with a comment naming the URDF link or joint it comes from.

Numbers are written as Python's shortest round-trip form of the double they are, so the model
computes with exactly the URDF's values (those the importer computes, combined inertias and
composed placements, to the last bit of the double).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .names import Names
from .robot import Joint, Robot, rpy_matrix
from .shapes import Placed
from .tree import Group, Structure

WIDTH = 100
KIND = {"revolute": "Revolute", "continuous": "Revolute", "prismatic": "Prismatic", "planar": "Planar",
        "floating": "Free"}
VARIABLE = {"revolute": "phi", "continuous": "phi", "prismatic": "s"}
LIMIT_UNITS = {"angle": {"lower": "rad", "upper": "rad", "velocity": "rad/s", "effort": "N.m",
                         "damping": "N.m.s", "friction": "N.m"},
               "length": {"lower": "m", "upper": "m", "velocity": "m/s", "effort": "N",
                          "damping": "N.s/m", "friction": "N"}}


@dataclass
class Written:
    text: str
    model: str
    bodies: dict[str, str] = field(default_factory=dict)       # URDF link (group owner) -> body name
    joints: dict[str, str] = field(default_factory=dict)       # URDF joint -> joint name
    coordinates: dict[str, tuple[str, ...]] = field(default_factory=dict)  # URDF joint -> its coordinates
    lines: dict[int, tuple[str, str]] = field(default_factory=dict)        # line -> ("link" | "joint", URDF name)
    shapes: dict[str, tuple[str, int]] = field(default_factory=dict)       # Shape -> (URDF link, its <visual> index)


def num(x: float) -> str:
    x = float(x)
    if x == 0.0:
        return "0"
    if x.is_integer() and abs(x) < 1e15:
        return str(int(x))
    return repr(x)


def vec(v) -> str:
    return "{" + ", ".join(num(x) for x in v) + "}"


def short(v, tiny: float = 1e-12) -> str:
    """A drawing size or placement: 6 significant digits are plenty; entries below ``tiny``
    (what composing rotations leaves of a zero, float32 noise of a mesh) are 0."""
    return "{" + ", ".join(num(float(f"{x:.6g}") if abs(x) >= tiny else 0.0) for x in v) + "}"


def mat(m) -> str:
    return "{" + ", ".join(vec(row) for row in m) + "}"


def rpy_of(R: np.ndarray) -> np.ndarray | None:
    """URDF rpy of a rotation matrix (None when the angles do not give R back to 1e-14)."""
    p = math.asin(max(-1.0, min(1.0, -R[2, 0])))
    if abs(R[2, 0]) < 1 - 1e-12:
        r, y = math.atan2(R[2, 1], R[2, 2]), math.atan2(R[1, 0], R[0, 0])
    else:
        r, y = 0.0, math.atan2(-R[0, 1], R[1, 1])
    rpy = np.array([r, p, y])
    return rpy if np.max(np.abs(rpy_matrix(rpy) - R)) < 1e-14 else None


class _Out:
    def __init__(self):
        self.lines: list[str] = []
        self.where: dict[int, tuple[str, str]] = {}

    def add(self, text: str = "", where: tuple[str, str] | None = None) -> None:
        if where is not None:
            self.where[len(self.lines) + 1] = where
        self.lines.append(text)

    def decl(self, head: str, args: list, where=None) -> None:
        """``head(arg, arg, ...);`` wrapped under the opening bracket; an argument given as
        (prefix, [row, row, ...]) is a matrix, its rows one under the other when it does not fit."""
        line = f"  {head}("
        indent = " " * len(line)
        rows, cur = [], line
        for k, a in enumerate(args):
            end = ", " if k < len(args) - 1 else ");"
            if isinstance(a, tuple):
                prefix, mrows = a
                flat = prefix + "{" + ", ".join(mrows) + "}"
                if len(indent) + len(flat) + len(end) <= WIDTH:
                    a = flat
                else:
                    if cur.strip() != head + "(":
                        rows.append(cur.rstrip())
                        cur = indent
                    inner = " " * (len(indent) + len(prefix) + 1)
                    rows.append(cur + prefix + "{" + (",\n" + inner).join(mrows).split("\n")[0])
                    body = (",\n" + inner).join(mrows).split("\n")[1:]
                    rows.extend(body[:-1])
                    cur = body[-1] + "}" + end
                    continue
            piece = a + end
            if len(cur) + len(piece.rstrip()) > WIDTH and cur.strip() not in (head + "(",):
                rows.append(cur.rstrip())
                cur = indent
            cur += piece
        rows.append(cur if args else line + ");")
        for k, r in enumerate(rows):
            self.add(r, where if k == 0 else None)


def write(robot: Robot, st: Structure, shapes: dict[str, list[Placed]], *, floating: bool,
          measured: dict[str, str], version: str) -> Written:
    names = Names()
    o = _Out()
    source = Path(robot.file).name
    model = names.take(robot.name)
    gravity = names.take("gravity")
    world_root = st.root.name == "world" and not floating
    body = {}
    for g in st.groups:
        body[g.link.name] = "world" if (world_root and g.inbound is None) else names.take(g.link.name)
    jname = {j.name: names.take(j.name) for j in st.movable}
    point_names = {}
    for g in st.groups:
        for mb in g.members[1:]:
            point_names[mb.link.name] = names.take(mb.link.name)
    w = Written("", model)
    w.bodies = {k: v for k, v in body.items() if v != "world"}
    w.joints = dict(jname)

    o.add(f"// {robot.name}: imported from {source} by `mech import` (mechdsl {version}).")
    o.add("// Units: SI (m, kg, kg.m2, rad, s); joint limits in rad or m, rad/s or m/s, N.m or N.")
    o.add("// One Body per URDF link (a link fixed to another is merged into it: masses, centres of mass and")
    o.add("// inertias combined exactly; its frame is kept as a Point), one joint per movable URDF joint;")
    o.add("// the coordinate of URDF joint J is J.phi (revolute, continuous) or J.s (prismatic), start 0.")
    for j in st.left_out:
        o.add(f"// Left out: joint \"{j.name}\" ({j.type}, {j.parent} -> {j.child}) closes a loop.")
    doc = f"{robot.name} (URDF {source})".replace("\\", "/").replace('"', "'")
    o.add(f'model {model} "{doc}"')
    o.add(f"  Gravity {gravity}(g = {{0, 0, -9.81}});")
    for g in st.groups:
        o.add()
        if g.inbound is None:
            _root(o, g, body, names, floating, world_root, w, shapes, measured)
        else:
            _joint(o, g.inbound, g, st, body, jname, point_names, names, w)
            _body(o, g, body[g.link.name], measured.get(g.link.name), w)
        placed = shapes.get(g.link.name, [])
        _shapes(o, body[g.link.name], [sh for sh in placed if sh.link == g.link.name], names, w)
        _members(o, g, body, point_names, placed, names, w)
    o.add(f"end {model};")
    w.text = "\n".join(o.lines) + "\n"
    w.lines = o.where
    return w


def _root(o, g: Group, body, names, floating, world_root, w, shapes, measured) -> None:
    name = body[g.link.name]
    if world_root:
        o.add(f"  // link \"{g.link.name}\" (the root) is the world")
        return
    _body(o, g, name, measured.get(g.link.name), w,
          "the root: free-floating" if floating else "the root: fixed to the world")
    if floating:
        jn = names.take("root_joint")
        o.decl(f"Free {jn}", ["parent = world", f"child = {name}", 'parametrization = "quaternion"'])
        w.coordinates[""] = tuple(f"{jn}.{r}" for r in ("x", "y", "z", "q0", "q1", "q2", "q3"))
    else:
        o.add(f"  Fixed {names.take(g.link.name + '_fixed')}(parent = world, child = {name});")


def _body(o, g: Group, name: str, measured: str | None, w, note: str = "") -> None:
    what = f"  // link \"{g.link.name}\"" + (f" ({note})" if note else "")
    o.add(what)
    if measured:
        o.add(f"  // measured inertia: {measured}")
    args = [f"m = {num(g.mass)}"]
    if np.any(g.com):
        args.append(f"r_cm = {vec(g.com)}")
    if np.any(g.I):
        args.append(("I = ", [vec(row) for row in g.I]))
    if measured:
        args.append("measured_inertia = true")
    o.decl(f"Body {name}", args, ("link", g.link.name))


def _shapes(o, body: str, placed: list[Placed], names, w) -> None:
    """One Shape per visual, named after its link, where the URDF places it (a cylinder's axis is
    its z, the default); a visual's own rpy is written as the URDF gives it."""
    for sh in placed:
        sname = names.take(f"{sh.link}_visual")
        w.shapes[sname] = (sh.link, sh.index)
        tiny = 1e-6 * max(sh.size)                    # a micron on a metre-sized shape
        fmt = vec if sh.verbatim else short          # the URDF's numbers as they are, else 6 digits
        args = [f"body = {body}", f'shape = "{sh.kind}"', f"size = {fmt(sh.size)}"]
        if sh.verbatim and np.any(sh.p) or not sh.verbatim and np.any(np.abs(sh.p) >= tiny):
            args.append(f"r = {vec(sh.p) if sh.verbatim else short(sh.p, tiny)}")
        if sh.kind != "sphere":
            args += _orientation(sh.R, sh.rpy, vec if sh.rpy is not None else short)
        o.decl(f"Shape {sname}", args, ("link", sh.link))


def _members(o, g: Group, body, point_names, placed: list[Placed], names, w) -> None:
    for mb in g.members[1:]:
        o.add(f"  // link \"{mb.link.name}\", fixed to \"{mb.via.parent}\" by joint \"{mb.via.name}\": merged "
              f"into {body[g.link.name]}")
        args = [f"body = {body[g.link.name]}"]
        if np.any(mb.p):
            args.append(f"r = {vec(mb.p)}")
        args += _orientation(mb.R, mb.rpy)
        o.decl(f"Point {point_names[mb.link.name]}", args, ("link", mb.link.name))
        _shapes(o, body[g.link.name], [sh for sh in placed if sh.link == mb.link.name], names, w)


def _orientation(R: np.ndarray, rpy: np.ndarray | None, fmt=vec) -> list[str]:
    if rpy is not None:
        return [f"rpy = {fmt(rpy)}"] if np.any(rpy) else []
    if np.array_equal(R, np.eye(3)):
        return []
    found = rpy_of(R)
    return [f"rpy = {fmt(found)}"] if found is not None else [f"R = {mat(R)}"]   # (exact: a rotation to 1e-6)


def _joint(o, j: Joint, g: Group, st: Structure, body, jname, point_names, names, w) -> None:
    owner, R0, p0 = st.placement[j.parent]
    parent_body = body[owner]
    name = jname[j.name]
    o.add(f"  // joint \"{j.name}\" ({j.type}): \"{j.parent}\" -> \"{j.child}\"", ("joint", j.name))
    if owner == j.parent:
        R, p, rpy = j.origin.R, j.origin.p, j.origin.rpy
    else:
        R, p, rpy = R0 @ j.origin.R, p0 + R0 @ j.origin.p, None
    role = VARIABLE.get(j.type)
    units = LIMIT_UNITS["length" if j.type == "prismatic" else "angle"]
    pnames = {}
    for key in ("lower", "upper", "effort", "velocity", "damping", "friction"):
        value = j.limits.get(key, j.dynamics.get(key))
        if value is None or (key in ("damping", "friction") and value == 0.0):
            continue
        pn = pnames[key] = names.take(f"{name}_{key}")
        what = "limit" if key in j.limits else "dynamics"
        note = " (recorded, not applied)" if key in ("damping", "friction") else ""
        o.add(f'  parameter Real {pn}(unit = "{units[key]}") = {num(value)} "URDF <{what} {key}>{note}";')
    parent = parent_body
    if np.any(p):
        parent = names.take(f"{name}_origin")
        o.decl(f"Point {parent}", [f"body = {parent_body}", f"r = {vec(p)}"])
    args = [f"parent = {parent}", f"child = {body[j.child]}"] + _orientation(R, rpy)
    if j.type != "floating":
        args.append(f"axis = {vec(j.axis)}")
    if j.type == "floating":
        args.append('parametrization = "quaternion"')
    if j.mimic is not None:
        target, mult, off = j.mimic
        t = next(k for k in st.movable if k.name == target)
        expr = f"{jname[target]}.{VARIABLE[t.type]}"
        if mult != 1.0:
            expr = f"{num(mult)}*{expr}"
        if off != 0.0:
            expr += f" {'-' if off < 0 else '+'} {num(abs(off))}"
        args.append(f"{role} = {expr}")
    o.decl(f"{KIND[j.type]} {name}", args, ("joint", j.name))
    if j.mimic is None:
        roles = {"planar": ("x", "y", "phi"), "floating": ("x", "y", "z", "q0", "q1", "q2", "q3")}.get(j.type, (role,))
        w.coordinates[j.name] = tuple(f"{name}.{r}" for r in roles)
    for key, law in (("damping", "Q = -{p}*der({c})"), ("friction", "F = {p}")):
        if key in pnames and role is not None and j.mimic is None:
            pn = pnames[key]
            comp = "GeneralizedForce" if key == "damping" else "Friction"
            o.add(f"  // to apply it: {comp} {name}_{key}_force(coordinate = {name}.{role}, "
                  + law.format(p=pn, c=f"{name}.{role}") + ");")
