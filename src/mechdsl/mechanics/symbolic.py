"""T, V, D and Q of a model in sympy, for printing Lagrange's equations (``mech equations``).

The same joint hooks (joints.py) as the numeric path, evaluated with sympy matrices: world
rotations and positions link by link, velocities by differentiation in time, body angular
velocities from R^T R'.  Only for small models: the numeric path never uses this.
"""
from __future__ import annotations

import re
from dataclasses import dataclass, field

from ..model import exprs, ir
from ..diagnostics import Diagnostic, MechError
from . import joints as J


def pretty_name(name: str) -> str:
    """A sympy-friendly symbol name: 'j1.phi' -> 'phi_j1', 'q[3]' -> 'q_3', 'link[2].m' -> 'm_link2'."""
    s = name
    if "." in s:
        head, last = s.rsplit(".", 1)
        s = f"{last}_{re.sub(r'[^A-Za-z0-9]', '', head)}"
    s = re.sub(r"\[(\d+)\]", r"_\1", s)
    s = re.sub(r"[^A-Za-z0-9_]", "", s)
    return s or "x"


@dataclass
class SymbolicModel:
    t: object
    coords: list                     # sympy functions of t, in coordinate order
    names: dict = field(default_factory=dict)     # sympy name -> model name
    T: object = 0
    V: object = 0
    D: object = 0
    Q: list = field(default_factory=list)


class _Builder:
    def __init__(self, model: ir.Model):
        import sympy as sp
        from sympy.physics.vector import dynamicsymbols

        self.sp = sp
        self.model = model
        self.t = dynamicsymbols._t
        used: dict[str, str] = {}

        def unique(name):
            base = pretty_name(name)
            s = base
            k = 2
            while s in used and used[s] != name:
                s = f"{base}{k}"
                k += 1
            used[s] = name
            return s

        self.q = {c.name: dynamicsymbols(unique(c.name)) for c in model.coordinates}
        self.p = {p.name: sp.Symbol(unique(p.name), real=True) for p in model.real_parameters}
        self.names = dict(used)
        z = sp.zeros(3, 1)
        # body -> (R world, origin world, w body, v body (origin), merged axis rotation (k, angle) or None)
        self.links: dict[str, tuple] = {"world": (sp.eye(3), z, z, z, None)}
        self._pos: dict[str, object] = {}
        self._vel: dict[str, object] = {}

    # -- IR translation -----------------------------------------------------------------
    def leaf(self, n):
        sp = self.sp
        if isinstance(n, ir.Param):
            if n.name in self.p:
                return self.p[n.name]
            return sp.Float(self.model.parameter(n.name).value)
        if isinstance(n, ir.Coord):
            return self.q[n.name]
        if isinstance(n, ir.Speed):
            return sp.diff(self.q[n.name], self.t)
        if isinstance(n, ir.Time):
            return self.t
        if isinstance(n, ir.TimeDer):
            return sp.diff(self.tr(n.expr), self.t)
        if isinstance(n, ir.PointPos):
            return self.point_pos(n.point)[n.i]
        if isinstance(n, ir.PointVel):
            return self.point_vel(n.point)[n.i]
        if isinstance(n, ir.BodyRot):
            return self.links[n.body][0][n.i, n.j]
        if isinstance(n, ir.BodyOmega):
            return (self.omega_world(n.body) if n.frame == "world" else self.omega_body(n.body))[n.i]
        raise MechError(Diagnostic("E760", f"{exprs.to_text(n)} cannot appear in printed equations"))

    def tr(self, e):
        return exprs.to_sympy(e, self.leaf)

    def vec(self, v):
        return self.sp.Matrix([self.tr(c) for c in v])

    def mat(self, m):
        return self.sp.Matrix([[self.tr(c) for c in row] for row in m])

    # -- kinematics ---------------------------------------------------------------------
    def rot(self, a, x):
        sp = self.sp
        k = None
        if all(c.is_number for c in a):
            for j in range(3):
                if a[j] == 1 and all(a[i] == 0 for i in range(3) if i != j):
                    k = j
        c, s = sp.cos(x), sp.sin(x)
        if k is not None:
            i, j = (k + 1) % 3, (k + 2) % 3
            E = sp.zeros(3, 3)
            E[k, k] = 1
            E[i, i] = E[j, j] = c
            E[i, j], E[j, i] = -s, s
            return E
        K = sp.Matrix([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])
        return sp.eye(3) + s * K + (1 - c) * K * K

    def unit(self, v):
        a = self.vec(v)
        n = self.sp.sqrt(sum(x * x for x in a))
        return a if n == 1 else a / n

    def build(self):
        done = {"world"}
        pending = list(self.model.tree_joints)
        while pending:
            for j in list(pending):
                if j.parent_body in done:
                    self.add_joint(j)
                    done.add(j.child_body)
                    pending.remove(j)
                    break
            else:
                raise MechError(Diagnostic("E710", f"joint '{pending[0].name}' is not connected to the world"))

    def _axis_index(self, a):
        if all(c.is_number for c in a):
            for k in range(3):
                if a[k] == 1 and all(a[i] == 0 for i in range(3) if i != k):
                    return k
        return None

    def add_joint(self, joint):
        """World pose (R, o) and body-frame velocities (w, v of the body origin) of the child.

        Rotations about one coordinate axis in a row are merged (Rz(a) Rz(b) = Rz(a + b)) so
        planar chains need no trigonometric simplification; velocities are propagated in body
        coordinates (as in the numeric path), which keeps them short."""
        sp = self.sp
        t = self.t
        body = self.model.body(joint.child_body)
        elements = J.kind_of(joint).elements(joint, body.kind == "point")
        Rp, op, wp, vp, axp = self.links[joint.parent_body]
        pp, cp = self.model.point(joint.parent), self.model.point(joint.child)
        rP = self.vec(pp.r)
        R, o, w, v, ax = Rp, op + Rp * rP, wp, vp + wp.cross(rP), axp
        if joint.parent_R is not None:          # the parent joint frame's own axes
            P = self.mat(joint.parent_R)
            R, w, v, ax = R * P, P.T * w, P.T * v, None
        for el in elements:
            if el.kind in ("R", "P"):
                a = self.unit(el.axis)
                x = self.tr(el.vars[0].motion)
                xd = sp.diff(x, t)
                if el.kind == "R":
                    E = self.rot(a, x)
                    k = self._axis_index(a)
                    if ax is not None and k is not None and ax[0] == k:
                        ax = (k, ax[1] + x)
                        R = self.rot(a, ax[1])
                    else:
                        ax = (k, x) if (k is not None and R == sp.eye(3)) else None
                        R = R * E
                    w, v = E.T * w + a * xd, E.T * v
                else:
                    o = o + R * a * x
                    v = v + w.cross(a * x) + a * xd
            elif el.kind == "Q":
                qs = [self.tr(v_.motion) for v_ in el.vars]
                q0, q1, q2, q3 = qs
                E = sp.Matrix([
                    [q0**2 + q1**2 - q2**2 - q3**2, 2 * (q1 * q2 - q0 * q3), 2 * (q1 * q3 + q0 * q2)],
                    [2 * (q1 * q2 + q0 * q3), q0**2 - q1**2 + q2**2 - q3**2, 2 * (q2 * q3 - q0 * q1)],
                    [2 * (q1 * q3 - q0 * q2), 2 * (q2 * q3 + q0 * q1), q0**2 - q1**2 - q2**2 + q3**2]])
                G = sp.Matrix([[-q1, q0, q3, -q2], [-q2, -q3, q0, q1], [-q3, q2, -q1, q0]])
                R, ax = R * E, None
                w, v = E.T * w + 2 * G * sp.Matrix([sp.diff(x, t) for x in qs]), E.T * v
            elif el.kind == "T":
                p = self.vec(el.r)
                E = self.mat(el.R)
                o = o + R * p
                v = v + w.cross(p) + p.diff(t)
                W = E.T * E.diff(t)
                R, ax = R * E, None
                w, v = E.T * w + sp.Matrix([W[2, 1], W[0, 2], W[1, 0]]), E.T * v
        if joint.child_R is not None:           # child joint frame -> child body axes
            C = self.mat(joint.child_R)
            R, w, v, ax = R * C.T, C * w, C * v, None
        rC = self.vec(cp.r)
        self.links[body.name] = (R, o - R * rC, w, v - w.cross(rC), ax)

    def point_pos(self, name):
        if name not in self._pos:
            p = self.model.point(name)
            R, o = self.links[p.body][:2]
            self._pos[name] = o + R * self.vec(p.r)
        return self._pos[name]

    def point_vel(self, name):
        if name not in self._vel:
            p = self.model.point(name)
            R, _, w, v, _ = self.links[p.body]
            self._vel[name] = R * (v + w.cross(self.vec(p.r)))
        return self._vel[name]

    def omega_body(self, body):
        return self.links[body][2]

    def omega_world(self, body):
        return self.links[body][0] * self.omega_body(body)

    # -- energies and forces --------------------------------------------------------------
    def com(self, b):
        R, o = self.links[b.name][:2]
        return o + R * self.vec(b.com)

    def energies(self) -> SymbolicModel:
        sp = self.sp
        m = self.model
        self.build()
        coords = [self.q[c.name] for c in m.coordinates]
        qd = [sp.diff(x, self.t) for x in coords]
        T = V = D = sp.Integer(0)
        Q = [sp.Integer(0)] * len(coords)
        for b in m.bodies:
            if b.kind not in ("point", "rigid"):
                continue
            mass = self.tr(b.mass)
            _, _, w, v, _ = self.links[b.name]
            vc = v + w.cross(self.vec(b.com))          # body coordinates
            T += mass * (vc.T * vc)[0] / 2
            if b.kind == "rigid":
                T += (w.T * self.mat(b.inertia) * w)[0] / 2
        for f in m.forces:
            if isinstance(f, ir.Gravity):
                g = self.vec(f.g)
                for b in m.bodies:
                    if b.kind in ("point", "rigid"):
                        V -= self.tr(b.mass) * (g.T * self.com(b))[0]
            elif isinstance(f, ir.SpringDamper):
                d = self.point_pos(f.b) - self.point_pos(f.a)
                l = sp.sqrt((d.T * d)[0])
                if f.kind in ("spring", "spring-damper"):
                    V += self.tr(f.k) * (l - self.tr(f.l0)) ** 2 / 2
                if f.kind in ("damper", "spring-damper"):
                    D += self.tr(f.c) * sp.diff(l, self.t) ** 2 / 2
            elif isinstance(f, ir.Gravitation):
                bs = [m.body(b) for b in f.bodies]
                for i in range(len(bs)):
                    for j in range(i + 1, len(bs)):
                        d = self.com(bs[j]) - self.com(bs[i])
                        V -= self.tr(f.G) * self.tr(bs[i].mass) * self.tr(bs[j].mass) / sp.sqrt((d.T * d)[0])
            elif isinstance(f, ir.AppliedForce):
                F = self.vec(f.F)
                if f.frame != "world":
                    F = self.links[f.frame][0] * F
                v = self.point_vel(f.point)
                Q = [Q[i] + (F.T * v.diff(qd[i]))[0] for i in range(len(coords))]
            elif isinstance(f, ir.AppliedTorque):
                tau = self.vec(f.tau)
                if f.frame != "world":
                    tau = self.links[f.frame][0] * tau
                w = self.omega_world(f.body)
                Q = [Q[i] + (tau.T * w.diff(qd[i]))[0] for i in range(len(coords))]
            elif isinstance(f, ir.GeneralizedForce):
                k = m.coordinate_names.index(f.coordinate)
                Q[k] += self.tr(f.Q)
        for term in m.terms:
            e = self.tr(term.expr)
            if term.kind == "kinetic":
                T += e
            elif term.kind == "potential":
                V += e
            else:
                D += e
        return SymbolicModel(t=self.t, coords=coords, names=self.names, T=T, V=V, D=D, Q=Q)


def symbolic_model(model: ir.Model) -> SymbolicModel:
    return _Builder(model).energies()
