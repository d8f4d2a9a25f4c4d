"""The URDF document as data: links (inertial, visuals), joints (type, origin, axis, limits, mimic,
dynamics), every one with the element it came from, so that a message can name it.

Reading checks what URDF requires of each element (a name, numbers where numbers belong, a known
joint type, a parent and a child); the problems of the whole (names used twice, a missing link, a
cycle) are tree.py's.  Every problem is collected and reported together (E022 malformed).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from ..diagnostics import Diagnostic, DiagnosticBag, MechError, Span
from . import xmltree
from .xmltree import Element

JOINT_TYPES = ("revolute", "continuous", "prismatic", "fixed", "floating", "planar")


def rpy_matrix(rpy) -> np.ndarray:
    """URDF's rpy: Rz(y) Ry(p) Rx(r)."""
    r, p, y = rpy
    cr, sr, cp, sp, cy, sy = math.cos(r), math.sin(r), math.cos(p), math.sin(p), math.cos(y), math.sin(y)
    return np.array([[cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
                     [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
                     [-sp, cp * sr, cp * cr]])


@dataclass
class Pose:
    """A placement: p (3,) and R (3, 3) of a child frame in its parent frame; rpy as read."""

    p: np.ndarray = field(default_factory=lambda: np.zeros(3))
    rpy: np.ndarray = field(default_factory=lambda: np.zeros(3))

    @property
    def R(self) -> np.ndarray:
        return rpy_matrix(self.rpy)


@dataclass
class Inertial:
    mass: float
    origin: Pose                     # the centre of mass and the axes the tensor is given in
    I: np.ndarray                    # about the centre of mass, in the origin's axes
    el: Element


@dataclass
class Visual:
    kind: str                        # box | cylinder | sphere | mesh
    size: tuple[float, ...]          # box (lx, ly, lz), cylinder (R, L), sphere (R,), mesh ()
    origin: Pose
    el: Element
    filename: str = ""
    scale: np.ndarray = field(default_factory=lambda: np.ones(3))


@dataclass
class Link:
    name: str
    el: Element
    inertial: Inertial | None = None
    visuals: list[Visual] = field(default_factory=list)


@dataclass
class Joint:
    name: str
    type: str
    parent: str
    child: str
    origin: Pose
    axis: np.ndarray
    el: Element
    parent_el: Element | None = None
    child_el: Element | None = None
    limits: dict[str, float] = field(default_factory=dict)      # lower, upper, effort, velocity
    dynamics: dict[str, float] = field(default_factory=dict)    # damping, friction
    mimic: tuple[str, float, float] | None = None               # (joint, multiplier, offset)
    mimic_el: Element | None = None


@dataclass
class Robot:
    name: str
    file: str
    links: dict[str, Link]
    joints: list[Joint]
    el: Element
    warnings: list = field(default_factory=list)     # the reader's warnings (W026)

    def span(self, el: Element) -> Span:
        return xmltree.span(self.file, el)


class _Reader:
    def __init__(self, file: str):
        self.file = file
        self.diags = DiagnosticBag()

    def bad(self, el: Element, message: str, help: str) -> None:
        self.diags.error("E022", message, xmltree.span(self.file, el), help)

    def snapped(self, el: Element, name: str, axis: np.ndarray) -> np.ndarray:
        """The unit ``axis`` with components below DIRECTION_SPAN of the largest set to 0 (W026):
        an exporter's rounding (xyz="0 -1 6.12323e-17", cos 90 deg, in iCub's torso_yaw), which a
        .mech file refuses (E513: double precision cannot resolve such a tilt)."""
        from ..semantic.physical import DIRECTION_SPAN

        big = float(np.max(np.abs(axis)))
        tiny = (axis != 0) & (np.abs(axis) < DIRECTION_SPAN * big)
        if not tiny.any():
            return axis
        shown = ", ".join(f"{v:.6g}" for v in axis[tiny])
        self.diags.warning("W026", f"the axis of joint '{name}': component{'s' if tiny.sum() > 1 else ''} {shown} "
                                   f"(below {DIRECTION_SPAN:g} of the largest) set to 0", xmltree.span(self.file, el),
                           "an exporter's rounding, as read; write 0 in the URDF to silence this")
        axis = np.where(tiny, 0.0, axis)
        return axis / float(np.linalg.norm(axis))

    def numbers(self, el: Element, key: str, n: int, default=None) -> np.ndarray | None:
        text = el.get(key)
        if text is None:
            return None if default is None else np.array(default, float)
        try:
            vals = [float(x) for x in text.split()]
        except ValueError:
            vals = []
        if len(vals) != n or not all(math.isfinite(v) for v in vals):
            self.bad(el, f"<{el.tag} {key}=\"{text}\"> must be {n} finite number{'s' if n > 1 else ''}",
                     f"write {key}=\"{' '.join(['0'] * n)}\"")
            return None if default is None else np.array(default, float)
        return np.array(vals, float)

    def number(self, el: Element, key: str, required: bool = True, default: float | None = None) -> float | None:
        if el.get(key) is None:
            if required:
                self.bad(el, f"<{el.tag}> needs the attribute {key}", f"add {key}=\"...\" to <{el.tag}>")
            return default
        v = self.numbers(el, key, 1)
        return None if v is None else float(v[0])

    def attributes(self, el: Element | None, keys: tuple[str, ...]) -> dict[str, float]:
        """The numbers of those of ``keys`` that the element gives."""
        out = {}
        for key in keys:
            if el is not None and el.get(key) is not None:
                v = self.number(el, key)
                if v is not None:
                    out[key] = v
        return out

    def pose(self, parent: Element) -> Pose:
        o = parent.find("origin")
        if o is None:
            return Pose()
        return Pose(self.numbers(o, "xyz", 3, (0, 0, 0)), self.numbers(o, "rpy", 3, (0, 0, 0)))

    def name(self, el: Element) -> str:
        n = el.get("name")
        if not n:
            self.bad(el, f"<{el.tag}> has no name", f"add name=\"...\" to <{el.tag}>")
            return f"<{el.tag} at line {el.line}>"
        return n

    # -- links -------------------------------------------------------------------------
    def link(self, el: Element) -> Link:
        link = Link(self.name(el), el)
        ie = el.find("inertial")
        if ie is not None:
            link.inertial = self.inertial(ie)
        for v in el.findall("visual"):
            vis = self.visual(v)
            if vis is not None:
                link.visuals.append(vis)
        return link

    def inertial(self, el: Element) -> Inertial | None:
        me, ie = el.find("mass"), el.find("inertia")
        if me is None or ie is None:
            self.bad(el, f"<inertial> needs <mass> and <inertia> (it has {'neither' if me is None and ie is None else 'no <' + ('mass' if me is None else 'inertia') + '>'})",
                     "give <mass value=\"...\"/> and <inertia ixx=\"...\" .../>, or remove <inertial> for a massless link")
            return None
        m = self.number(me, "value")
        vals = {k: self.number(ie, k, required=k in ("ixx", "iyy", "izz"), default=0.0)
                for k in ("ixx", "ixy", "ixz", "iyy", "iyz", "izz")}
        if m is None or any(v is None for v in vals.values()):
            return None
        I = np.array([[vals["ixx"], vals["ixy"], vals["ixz"]], [vals["ixy"], vals["iyy"], vals["iyz"]],
                      [vals["ixz"], vals["iyz"], vals["izz"]]], float)
        return Inertial(m, self.pose(el), I, el)

    def visual(self, el: Element) -> Visual | None:
        g = el.find("geometry")
        shape = g.children[0] if g is not None and g.children else None
        if shape is None:
            self.bad(el, "<visual> has no <geometry>", "give <geometry><box size=\"...\"/></geometry> (or cylinder, "
                                                        "sphere, mesh)")
            return None
        origin = self.pose(el)
        if shape.tag == "box":
            size = self.numbers(shape, "size", 3, (0, 0, 0))
            return Visual("box", tuple(abs(float(x)) for x in size), origin, shape)
        if shape.tag == "cylinder":
            r, L = self.number(shape, "radius", default=0.0), self.number(shape, "length", default=0.0)
            return Visual("cylinder", (abs(r or 0.0), abs(L or 0.0)), origin, shape)
        if shape.tag == "sphere":
            return Visual("sphere", (abs(self.number(shape, "radius", default=0.0) or 0.0),), origin, shape)
        if shape.tag == "mesh":
            fn = shape.get("filename")
            if not fn:
                self.bad(shape, "<mesh> has no filename", "add filename=\"package://...\"")
                return None
            return Visual("mesh", (), origin, shape, fn, self.numbers(shape, "scale", 3, (1, 1, 1)))
        self.bad(shape, f"unknown geometry <{shape.tag}>", "URDF geometry is box, cylinder, sphere or mesh")
        return None

    # -- joints ------------------------------------------------------------------------
    def joint(self, el: Element) -> Joint | None:
        name = self.name(el)
        kind = el.get("type")
        if kind not in JOINT_TYPES:
            self.bad(el, f"joint '{name}' has the type {kind!r}" if kind else f"joint '{name}' has no type",
                     "URDF joint types: " + ", ".join(JOINT_TYPES))
            return None
        pe, ce = el.find("parent"), el.find("child")
        if pe is None or ce is None or not pe.get("link") or not ce.get("link"):
            self.bad(el, f"joint '{name}' needs <parent link=\"...\"/> and <child link=\"...\"/>",
                     "name the two links the joint connects")
            return None
        axis = np.array([1.0, 0.0, 0.0])
        ae = el.find("axis")
        if ae is not None and kind not in ("fixed", "floating"):
            axis = self.numbers(ae, "xyz", 3, (1, 0, 0))
            n = float(np.linalg.norm(axis))
            if n == 0.0:
                self.bad(ae, f"the axis of joint '{name}' is the zero vector", "give a direction, e.g. xyz=\"0 0 1\"")
                n = 1.0
                axis = np.array([1.0, 0.0, 0.0])
            axis = self.snapped(ae, name, axis / n)
        j = Joint(name, kind, pe.get("link"), ce.get("link"), self.pose(el), axis, el, pe, ce)
        j.limits = self.attributes(el.find("limit"), ("lower", "upper", "effort", "velocity"))
        j.dynamics = self.attributes(el.find("dynamics"), ("damping", "friction"))
        me = el.find("mimic")
        if me is not None:
            target = me.get("joint")
            if not target:
                self.bad(me, f"<mimic> of joint '{name}' names no joint", "add joint=\"...\"")
            else:
                j.mimic = (target, self.number(me, "multiplier", required=False, default=1.0),
                           self.number(me, "offset", required=False, default=0.0))
                j.mimic_el = me
        return j


def read_robot(data: bytes, file: str) -> Robot:
    """The Robot of a URDF document (E020 not XML, E021 not a URDF, E022 malformed elements)."""
    root = xmltree.parse(data, file)
    if root.tag != "robot":
        raise MechError(Diagnostic("E021", f"the document's root element is <{root.tag}>, not <robot>",
                                   xmltree.span(file, root), "a URDF file describes one <robot>"))
    rd = _Reader(file)
    links: dict[str, Link] = {}
    joints: list[Joint] = []
    dup = DiagnosticBag()
    for el in root.children:
        if el.tag == "link":
            link = rd.link(el)
            if link.name in links:
                dup.error("E026", f"two links are named '{link.name}'", xmltree.span(file, el),
                          f"the first is at line {links[link.name].el.line}; link names are unique")
            else:
                links[link.name] = link
        elif el.tag == "joint":
            j = rd.joint(el)
            if j is not None:
                if any(o.name == j.name for o in joints):
                    dup.error("E026", f"two joints are named '{j.name}'", xmltree.span(file, el),
                              "joint names are unique")
                else:
                    joints.append(j)
    rd.diags.extend(dup.items)
    rd.diags.raise_if_errors()
    if not links:
        raise MechError(Diagnostic("E021", "the robot has no <link>", xmltree.span(file, root),
                                   "a URDF robot is a tree of <link> elements connected by <joint> elements"))
    return Robot(root.get("name") or "robot", file, links, joints, root, rd.diags.warnings)
