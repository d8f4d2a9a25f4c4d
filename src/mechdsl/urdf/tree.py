"""The URDF's kinematic tree: its root, the order links are written in, the links merged into
their parent by fixed joints (with their inertias combined exactly), and what is left out.

- Every joint names links that exist (E024), every link but one (the root) hangs from a joint
  (E025: no root = a cycle, several roots = several robots), every link is reached from the root
  (E025 again, for a cycle beside the tree).
- A link that is the child of a second joint closes a loop; URDF describes trees (so does
  Pinocchio), so that joint is left out with the warning W025 saying so.
- A link fixed to another is merged into it: one mechdsl body per group of links welded
  together; its mass, centre of mass and inertia combine the members' exactly (parallel-axis
  theorem with each member's rotation: I = sum R_i I_i R_i^T + m_i (|d_i|^2 1 - d_i d_i^T)).
- A movable joint that moves no mass at all (no <inertial>, or one of zeros, on its child link or
  beyond) is E023: its coordinate would have no inertia.
- A mimic joint names a movable joint, without a cycle of mimics; otherwise its mimic is left out
  with the warning W029.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..diagnostics import DiagnosticBag
from .robot import Joint, Link, Robot, rpy_matrix
from .xmltree import span

MOVABLE = ("revolute", "continuous", "prismatic", "floating", "planar")


@dataclass
class Member:
    """A link of a group, placed in the group's frame (R, p) through the fixed joint ``via``."""

    link: Link
    R: np.ndarray
    p: np.ndarray
    via: Joint | None = None
    rpy: np.ndarray | None = None            # the URDF's own rpy when fixed directly to the group's link


@dataclass
class Group:
    """One mechdsl body: the links welded to ``link`` (itself first)."""

    link: Link
    inbound: Joint | None                    # the movable joint it hangs from (None: the root)
    members: list[Member] = field(default_factory=list)
    mass: float = 0.0
    com: np.ndarray = field(default_factory=lambda: np.zeros(3))
    I: np.ndarray = field(default_factory=lambda: np.zeros((3, 3)))
    verbatim: bool = False                   # one member, inertia in link axes: the URDF's numbers as they are
    subtree_inertials: int = 0               # links with an <inertial> in the subtree


@dataclass
class Structure:
    root: Link
    groups: list[Group]                      # parents before children, the URDF's order among siblings
    placement: dict[str, tuple[str, np.ndarray, np.ndarray]]   # link -> (group link, R, p)
    movable: list[Joint]                     # in the order of groups (each group's inbound joint)
    left_out: list[Joint]


def build(robot: Robot, diags: DiagnosticBag) -> Structure | None:
    f = robot.file
    links = robot.links
    ok = []
    for j in robot.joints:
        good = True
        for role, name, el in (("parent", j.parent, j.parent_el), ("child", j.child, j.child_el)):
            if name not in links:
                diags.error("E024", f"joint '{j.name}': its {role} link '{name}' does not exist", span(f, el),
                            "name a <link> of the robot (names are case-sensitive)")
                good = False
        if good and j.parent == j.child:
            diags.error("E025", f"joint '{j.name}' connects link '{j.parent}' to itself", span(f, j.el),
                        "a joint's parent and child are different links")
            good = False
        if good:
            ok.append(j)
    if diags.errors:
        return None
    children = {j.child for j in ok}
    roots = [lk for lk in links.values() if lk.name not in children]
    if not roots:
        diags.error("E025", "the joints form a cycle: every link is the child of a joint, so there is no root",
                    span(f, robot.el), "a URDF is a tree: exactly one link (the base) is no joint's child")
        return None
    if len(roots) > 1:
        names = ", ".join(f"'{r.name}'" for r in roots)
        diags.error("E025", f"the robot has {len(roots)} roots ({names}): links that are no joint's child",
                    span(f, roots[1].el), "connect them with joints into one tree (one base link)")
        return None
    root = roots[0]
    reached: dict[str, Joint | None] = {root.name: None}
    changed = True
    while changed:                            # sweep in the file's order: the first joint to reach a link wins
        changed = False
        for j in ok:
            if j.parent in reached and j.child not in reached:
                reached[j.child] = j
                changed = True
    left_out = [j for j in ok if j.child in reached and reached[j.child] is not j and j.parent in reached]
    by_parent: dict[str, list[Joint]] = {}
    for j in ok:
        if reached.get(j.child) is j:
            by_parent.setdefault(j.parent, []).append(j)
    order: list[tuple[Link, Joint | None]] = []
    stack = [(root, None)]
    while stack:                              # depth first, siblings in the file's order
        link, via = stack.pop()
        order.append((link, via))
        stack.extend(reversed([(links[j.child], j) for j in by_parent.get(link.name, [])]))
    for j in left_out:
        first = reached[j.child]
        diags.warning("W025", f"joint '{j.name}' closes a loop (link '{j.child}' already hangs from joint "
                              f"'{first.name if first else '?'}'): left out", span(f, j.el),
                      "URDF describes trees; to close the loop, add a joint between the two links in the "
                      ".mech file (docs/language.md, Topology)")
    lost = [lk for lk in links.values() if lk.name not in reached]
    if lost:
        diags.error("E025", f"links {', '.join(repr(lk.name) for lk in lost[:5])} are not reached from the root "
                            f"'{root.name}': their joints form a cycle", span(f, lost[0].el),
                    "a URDF is a tree: each link hangs from exactly one joint, down from the base")
        return None
    return _groups(robot, root, order, left_out, diags)


def _groups(robot: Robot, root: Link, order, left_out, diags) -> Structure:
    placement: dict[str, tuple[str, np.ndarray, np.ndarray]] = {}
    groups: dict[str, Group] = {}
    for link, via in order:
        if via is None or via.type in MOVABLE:
            g = groups[link.name] = Group(link, via)
            g.members.append(Member(link, np.eye(3), np.zeros(3)))
            placement[link.name] = (link.name, np.eye(3), np.zeros(3))
            continue
        owner, R0, p0 = placement[via.parent]            # a fixed joint: weld to the parent's group
        R = R0 @ via.origin.R
        p = p0 + R0 @ via.origin.p
        placement[link.name] = (owner, R, p)
        groups[owner].members.append(Member(link, R, p, via, via.origin.rpy if via.parent == owner else None))
    ordered = list(groups.values())
    for g in ordered:
        _combine(g)
    _subtree_inertials(ordered, placement)
    for g in ordered:
        j = g.inbound
        if j is not None and not g.subtree_inertials:
            diags.error("E023", f"joint '{j.name}' moves no mass: link '{g.link.name}' has no mass or inertia "
                                "(no <inertial>, or zeros), and neither has any link beyond it",
                        span(robot.file, g.link.el),
                        "give the link an <inertial> (mass, inertia), or make the joint fixed")
    _check_mimics(robot, [g.inbound for g in ordered if g.inbound is not None], diags)
    return Structure(root, ordered, placement, [g.inbound for g in ordered if g.inbound is not None], left_out)


def _combine(g: Group) -> None:
    """Mass, centre of mass and inertia of the group, in the group link's frame (exact sums)."""
    parts = []
    for mb in g.members:
        ine = mb.link.inertial
        if ine is None:
            continue
        Rl = mb.R @ ine.origin.R
        parts.append((ine.mass, mb.p + mb.R @ ine.origin.p, Rl @ ine.I @ Rl.T, mb))
    if not parts:
        return
    g.verbatim = (len(parts) == 1 and parts[0][3] is g.members[0] and not np.any(parts[0][3].link.inertial.origin.rpy))
    if len(parts) == 1:
        g.mass, g.com, g.I = parts[0][0], parts[0][1], parts[0][2]
        if g.verbatim:
            g.I = g.members[0].link.inertial.I
        return
    m = sum(p[0] for p in parts)
    g.mass = m
    g.com = sum(p[0] * p[1] for p in parts) / m if m > 0 else np.zeros(3)
    I = np.zeros((3, 3))
    for mi, ci, Ii, _ in parts:
        d = ci - g.com
        I += Ii + mi * (float(d @ d) * np.eye(3) - np.outer(d, d))
    g.I = 0.5 * (I + I.T)


def _has_mass(link: Link) -> bool:
    """An <inertial> with a mass or an inertia that is not zero (a negative mass counts: E508 says so)."""
    ine = link.inertial
    return ine is not None and (ine.mass != 0.0 or bool(np.any(ine.I)))


def _subtree_inertials(groups: list[Group], placement) -> None:
    by_link = {g.link.name: g for g in groups}
    for g in reversed(groups):               # children come after their parents
        g.subtree_inertials += sum(_has_mass(mb.link) for mb in g.members)
        if g.inbound is not None:
            parent = by_link[placement[g.inbound.parent][0]]
            parent.subtree_inertials += g.subtree_inertials


def _check_mimics(robot: Robot, movable: list[Joint], diags) -> None:
    """A mimic that cannot be honoured (it names no movable joint, or mimics form a cycle) is left
    out, with the warning W029: the joint then moves on its own (as Pinocchio reads it by default)."""
    names = {j.name: j for j in movable}
    all_joints = {j.name: j for j in robot.joints}
    follows = ("revolute", "continuous", "prismatic")
    for j in movable:
        if j.mimic is None:
            continue
        target = j.mimic[0]
        t = names.get(target)
        why = None
        if t is None or t.type not in follows or j.type not in follows:
            why = ("is not a joint of the robot" if target not in all_joints else
                   f"is a {all_joints[target].type} joint" if t is None or t.type not in follows
                   else f"is followed by a {j.type} joint")
        else:
            seen, k = {j.name}, t
            while k is not None and k.mimic is not None and why is None:
                if k.name in seen:
                    why = "leads back to it through other mimic joints (a cycle)"
                seen.add(k.name)
                k = names.get(k.mimic[0])
        if why is not None:
            diags.warning("W029", f"joint '{j.name}' mimics '{target}', which {why}: the mimic is left out, the "
                                  "joint moves on its own", span(robot.file, j.mimic_el),
                          "a mimic joint follows a revolute, continuous or prismatic joint of the robot; fix the "
                          "name to bind it")
            j.mimic = None


__all__ = ["build", "Structure", "Group", "Member", "MOVABLE", "rpy_matrix"]
