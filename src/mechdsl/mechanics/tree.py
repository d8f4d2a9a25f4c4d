"""The kinematic tree in CasADi SX: links (one per joint element), their joint motion,
free speeds (nu) and the body inertias in link coordinates.

A link frame is the frame after one element of a joint; the last element's frame is the
child joint frame (child body axes, origin at the child point r_C), so a body's inertia and
points are stored relative to that origin: r_link = r_body - r_C.  The world is link -1.
"""
from __future__ import annotations

from dataclasses import field

import casadi as ca

from ..model import exprs, ir
from ..diagnostics import Diagnostic, MechError
from . import joints as J
from . import templates as tpl
from .rotations import quat_G, quat_matrix, rot
from .spatial import Inertia, vee
from ..model.records import record


@record(frozen=False)
class Var:
    """A joint variable in SX: value x, rate xd, and (prescribed only) acceleration xdd."""

    kind: str                       # 'coord' | 'prescribed' | 'general'
    x: object
    xd: object
    xdd: object | None = None
    coord: int | None = None        # index in q for 'coord'


@record(frozen=False)
class Link:
    index: int
    parent: int                      # -1: the world
    joint: ir.Joint
    element: J.Element | None
    E: ca.SX                         # child axes -> parent axes
    r: ca.SX                         # child origin in parent coordinates
    Sw: ca.SX | None = None          # free motion subspace (3 x k, 3 x k), link coordinates
    Sv: ca.SX | None = None
    dofs: list[int] = field(default_factory=list)     # indices into nu
    vJw: ca.SX | None = None         # prescribed part of the joint velocity (link coords)
    vJv: ca.SX | None = None
    aJw: ca.SX | None = None         # its time derivative (componentwise in link coords)
    aJv: ca.SX | None = None
    body: ir.Body | None = None      # set on the last link of a joint
    inertia: Inertia | None = None
    quat: list[int] | None = None    # q indices of a quaternion element bound to coordinates
    post: ca.SX | None = None        # last link of a joint with an oriented child point: the child
                                     # joint frame's axes in body axes (link axes are body axes)

    @property
    def k(self) -> int:
        return len(self.dofs)

    # argument forms for the per-link templates (empty / zero where absent)
    @property
    def S_w(self):
        return self.Sw if self.dofs else ca.SX(3, 0)

    @property
    def S_v(self):
        return self.Sv if self.dofs else ca.SX(3, 0)

    @property
    def known_vw(self):
        return self.vJw if self.vJw is not None else z3()

    @property
    def known_vv(self):
        return self.vJv if self.vJv is not None else z3()

    @property
    def known_aw(self):
        return self.aJw if self.aJw is not None else z3()

    @property
    def known_av(self):
        return self.aJv if self.aJv is not None else z3()

    @property
    def I(self) -> Inertia:
        return self.inertia if self.inertia is not None else Inertia.zero()


@record(frozen=False)
class Dof:
    link: int
    col: int
    nu: object                       # SX expression of this speed in q, qd, t
    var: Var | None = None


def _pre_rotate(link: Link, P, r_pre) -> None:
    """The first element of a joint whose parent joint frame has the axes P in the parent body:
    its link sits in the parent by (P E, r_pre + P (r - r_pre)); motion subspaces and joint
    velocities are in the link's own axes and do not change."""
    link.E = ca.mtimes(P, link.E)
    link.r = r_pre + ca.mtimes(P, link.r - r_pre)


def _post_rotate(link: Link, C) -> None:
    """The last element of a joint whose child joint frame has the axes C in the child body: the
    link frame becomes the body's axes at the same origin (E C^T), and what is written in link
    coordinates turns with it (v_body = C v_joint)."""
    link.E = ca.mtimes(link.E, C.T)
    link.post = C
    if link.dofs:
        link.Sw, link.Sv = ca.mtimes(C, link.Sw), ca.mtimes(C, link.Sv)
    for name in ("vJw", "vJv", "aJw", "aJv"):
        v = getattr(link, name)
        if v is not None:
            setattr(link, name, ca.mtimes(C, v))


def depends(x, sym) -> bool:
    """ca.depends_on that accepts empty symbol vectors and constant expressions."""
    x = ca.SX(x)
    if sym.numel() == 0 or x.numel() == 0:
        return False
    return bool(ca.depends_on(x, sym))


def z3():
    return ca.SX(3, 1)


class Tree:
    """Links in parent-before-child order, the free speeds nu, and lookups."""

    def __init__(self, model: ir.Model, env: exprs.CasadiEnv):
        self.model = model
        self.env = env
        self.links: list[Link] = []
        self.dofs: list[Dof] = []
        self.body_link: dict[str, int] = {"world": -1}
        self.body_offset: dict[str, ca.SX] = {"world": z3()}   # r_C of the body's inbound joint
        self.quaternions: list[tuple[ir.Joint, list[int]]] = []
        self.euler_monitors: dict[str, object] = {}
        self.has_general = False
        self.coord_uses: dict[int, int] = {}
        self._points = {p.name: p for p in model.points}
        self._memo: dict = {}
        self._build()

    # -- helpers --------------------------------------------------------------------
    def tr(self, e: ir.Expr):
        return self.env.translate(e)

    def vec(self, v: ir.Vec3) -> ca.SX:
        """A Vec3 of IR expressions in SX (memoized: bodies of an array share their data)."""
        key = ("v", v)
        r = self._memo.get(key)
        if r is None:
            r = self._memo[key] = ca.vertcat(*[ca.SX(self.tr(c)) for c in v])
        return r

    def mat(self, m: ir.Mat3) -> ca.SX:
        key = ("m", m)
        r = self._memo.get(key)
        if r is None:
            r = self._memo[key] = ca.vertcat(*[ca.horzcat(*[ca.SX(self.tr(c)) for c in row]) for row in m])
        return r

    def unit(self, v: ir.Vec3) -> ca.SX:
        a = self.vec(v)
        if all(a[i].is_constant() for i in range(3)):
            vals = [float(a[i]) for i in range(3)]
            n = sum(x * x for x in vals) ** 0.5
            if n == 0:
                raise MechError(Diagnostic("E706", "a joint axis is the zero vector"))
            return ca.SX([x / n for x in vals]) if abs(n - 1) > 0 else a
        return a / ca.norm_2(a)

    def point(self, name: str) -> ir.Point:
        try:
            return self._points[name]
        except KeyError:
            raise MechError(Diagnostic("E707", f"unknown point '{name}'")) from None

    def point_in_link(self, name: str) -> tuple[int, ca.SX]:
        """(link index, position in link coordinates) of a named point."""
        p = self.point(name)
        return self.body_link[p.body], self.vec(p.r) - self.body_offset[p.body]

    # -- variables ------------------------------------------------------------------
    def var(self, jv: ir.JointVar, joint: ir.Joint, count: bool = True) -> Var:
        env = self.env
        m = jv.motion
        if isinstance(m, ir.Coord) and jv.coordinate == m.name and m.name in env._ci:
            i = env._ci[m.name]
            if count:
                self.coord_uses[i] = self.coord_uses.get(i, 0) + 1
            return Var("coord", env.q[i], env.qd[i], coord=i)
        x = ca.SX(self.tr(m))
        if not depends(x, ca.vertcat(env.q, env.qd)):
            xd = ca.jacobian(x, env.t)
            return Var("prescribed", x, xd, ca.jacobian(xd, env.t))
        if depends(x, env.qd):
            raise MechError(Diagnostic("E708", f"joint variable {joint.name}.{jv.role} depends on speeds",
                                       joint.span, "a joint variable may depend on coordinates and time only"))
        if count:
            self.has_general = True
        return Var("general", x, ca.jtimes(x, env.q, env.qd) + ca.jacobian(x, env.t))

    # -- building -------------------------------------------------------------------
    def _order(self) -> list[ir.Joint]:
        pending = list(self.model.tree_joints)
        done = {"world"}
        out = []
        while pending:
            progress = False
            for j in list(pending):
                if j.parent_body in done:
                    if j.child_body in done:
                        raise MechError(Diagnostic("E709", f"body '{j.child_body}' has two joints to its parent side "
                                                           f"('{j.name}' is one); mark one as closing a loop", j.span))
                    out.append(j)
                    done.add(j.child_body)
                    pending.remove(j)
                    progress = True
            if not progress:
                j = pending[0]
                raise MechError(Diagnostic("E710", f"joint '{j.name}': its parent body '{j.parent_body}' "
                                                   "is not connected to the world", j.span))
        for b in self.model.bodies:
            if b.name not in done:
                raise MechError(Diagnostic("E711", f"body '{b.name}' is attached to nothing", b.span,
                                           "connect it with a joint (a Free joint for a free body)"))
        return out

    def _build(self):
        for joint in self._order():
            self._add_joint(joint)
        for i, n in sorted(self.coord_uses.items()):
            if n > 1:
                self.has_general = True   # one coordinate drives several joint variables

    def _add_joint(self, joint: ir.Joint):
        body = self.model.body(joint.child_body)
        point_child = body.kind == "point"
        elements = J.kind_of(joint).elements(joint, point_child)
        parent = self.body_link[joint.parent_body]
        pp = self.point(joint.parent)
        cp = self.point(joint.child)
        if pp.body != joint.parent_body or cp.body != joint.child_body:
            raise MechError(Diagnostic("E712", f"joint '{joint.name}': its points are not on its bodies", joint.span))
        r_pre = self.vec(pp.r) - self.body_offset[joint.parent_body]
        P, C = self.joint_axes(joint)
        if not elements:
            self._new_link(parent, joint, None, ca.SX.eye(3) if P is None else P, r_pre)
        for k, el in enumerate(elements):
            parent = self._add_element(parent, joint, el, r_pre)
            if k == 0 and P is not None:
                _pre_rotate(self.links[-1], P, r_pre)
            r_pre = z3()
        link = self.links[-1]          # the child joint frame
        if C is not None:              # ... turned into the child body's axes
            _post_rotate(link, C)
        link.body = body
        r_C = self.vec(cp.r)
        self.body_link[body.name] = link.index
        self.body_offset[body.name] = r_C
        if body.kind in ("frame", "world"):
            link.inertia = Inertia.zero()
        else:
            m = self.tr(body.mass)
            Ic = self.mat(body.inertia) if body.kind != "point" else ca.SX(3, 3)
            link.inertia = Inertia(*tpl.rigid_inertia()(m, self.vec(body.com) - r_C, Ic))
        self._euler_monitor(joint, elements)

    def joint_axes(self, joint: ir.Joint) -> tuple[ca.SX | None, ca.SX | None]:
        """(P, C): the axes of the parent and child joint frames in their bodies' axes (SX), None
        where they are the body's own."""
        return (None if joint.parent_R is None else self.mat(joint.parent_R),
                None if joint.child_R is None else self.mat(joint.child_R))

    def _new_link(self, parent, joint, el, E, r) -> Link:
        link = Link(index=len(self.links), parent=parent, joint=joint, element=el, E=E, r=r)
        self.links.append(link)
        return link

    def _free(self, link: Link, Sw, Sv, nus, var=None):
        link.Sw, link.Sv = Sw, Sv
        for col, nu in enumerate(nus):
            link.dofs.append(len(self.dofs))
            self.dofs.append(Dof(link.index, col, nu, var))

    def _add_element(self, parent: int, joint: ir.Joint, el: J.Element, r_pre) -> int:
        env = self.env
        if el.kind in ("R", "P"):
            a = self.unit(el.axis)
            v = self.var(el.vars[0], joint)
            if el.kind == "R":
                link = self._new_link(parent, joint, el, rot(a, v.x), r_pre)
                Sw, Sv = a, z3()
            else:
                link = self._new_link(parent, joint, el, ca.SX.eye(3), r_pre + a * v.x)
                Sw, Sv = z3(), a
            if v.kind == "prescribed":
                link.vJw, link.vJv = Sw * v.xd, Sv * v.xd
                link.aJw, link.aJv = Sw * v.xdd, Sv * v.xdd
            else:
                self._free(link, Sw, Sv, [v.xd], v)
            return link.index
        if el.kind == "Q":
            vs = [self.var(jv, joint) for jv in el.vars]
            kinds = {v.kind for v in vs}
            x = ca.vertcat(*[v.x for v in vs])
            xd = ca.vertcat(*[v.xd for v in vs])
            link = self._new_link(parent, joint, el, quat_matrix(x), r_pre)
            n2 = ca.dot(x, x)
            w = 2 * ca.mtimes(quat_G(x), xd) / n2
            if kinds == {"coord"}:
                idx = [v.coord for v in vs]
                if len(set(idx)) != 4:
                    raise MechError(Diagnostic("E713", f"quaternion of joint '{joint.name}' needs four distinct coordinates",
                                               joint.span))
                link.quat = idx
                self.quaternions.append((joint, idx))
                self._free(link, ca.SX.eye(3), ca.SX(3, 3), [w[i] for i in range(3)])
            elif kinds == {"prescribed"}:
                link.vJw, link.vJv = w, z3()
                link.aJw, link.aJv = ca.jacobian(w, env.t), z3()
            else:
                raise MechError(Diagnostic("E714", f"quaternion variables of joint '{joint.name}' must all be "
                                                   "coordinates or all be prescribed", joint.span))
            return link.index
        if el.kind == "T":
            E = self.mat(el.R)
            p = self.vec(el.r)
            if depends(ca.vertcat(ca.vec(E), p), ca.vertcat(env.q, env.qd)):
                raise MechError(Diagnostic("E705", f"moving frame '{joint.name}' depends on the state",
                                           joint.span, "a frame's motion is a function of time and parameters"))
            link = self._new_link(parent, joint, el, E, r_pre + p)
            if ca.depends_on(ca.vertcat(ca.vec(E), p), env.t):
                Ed = ca.reshape(ca.jacobian(ca.vec(E), env.t), 3, 3)
                link.vJw = vee(ca.mtimes(E.T, Ed))
                link.vJv = ca.mtimes(E.T, ca.jacobian(p, env.t))
                link.aJw = ca.jacobian(link.vJw, env.t)
                link.aJv = ca.jacobian(link.vJv, env.t)
            return link.index
        raise AssertionError(el.kind)

    def _euler_monitor(self, joint: ir.Joint, elements: list[J.Element]):
        """det of the rotational motion subspace of an Euler-angle joint: 0 at gimbal lock."""
        rots = [el for el in elements if el.kind == "R"]
        if joint.kind not in ("spherical", "free") or len(rots) != 3:
            return
        links = self.links[-3:]
        if any(not lk.dofs for lk in links):
            return
        # columns of S in the child frame: axis_k carried through the later rotations
        cols = []
        for i, lk in enumerate(links):
            a = lk.Sw
            for later in links[i + 1:]:
                a = ca.mtimes(later.E.T, a)
            cols.append(a)
        self.euler_monitors[f"{joint.name}.gimbal"] = ca.det(ca.horzcat(*cols))

    # -- summaries ------------------------------------------------------------------
    @property
    def nu(self) -> ca.SX:
        return ca.vertcat(*[d.nu for d in self.dofs]) if self.dofs else ca.SX(0, 1)

    def children(self) -> list[list[int]]:
        ch = [[] for _ in self.links]
        for lk in self.links:
            if lk.parent >= 0:
                ch[lk.parent].append(lk.index)
        return ch
