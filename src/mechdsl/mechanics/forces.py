"""Forces and energies of components and equation-layer terms.

Every component force is both a set of spatial loads on links (used by the recursive
algorithms) and, where conservative or dissipative, a term of V or D (used for energies and
by the Lagrange route).  Equation-layer terms and generalized forces act in q-space.
"""
from __future__ import annotations

import dataclasses
from dataclasses import field

import casadi as ca

from ..model import ir
from ..diagnostics import Diagnostic, MechError
from .kinematics import Kinematics
from . import templates as tpl
from .tree import z3
from ..model.records import record


@record(frozen=False)
class Loads:
    point_forces: list = field(default_factory=list)     # (link, r in link coords, F world)
    torques: list = field(default_factory=list)          # (link, tau world)
    applied: list = field(default_factory=list)          # the subset from AppliedForce/Torque, for EOM.Q
    V: object = 0                                         # component potential energy
    D: object = 0                                         # component Rayleigh dissipation
    Q_gen: object = None                                  # q-space: GeneralizedForce (n,)
    T_terms: object = 0                                   # equation-layer terms
    V_terms: object = 0
    D_terms: object = 0

    def link_forces(self, kin: Kinematics) -> dict[int, tuple]:
        """External force per link, (n, f) in link coordinates about the link origin."""
        out: dict[int, tuple] = {}
        for i, r, F in self.point_forces:
            if i < 0:
                continue
            n, f = tpl.point_force()(kin.R[i], r, F)
            a = out.get(i)
            out[i] = (n, f) if a is None else (a[0] + n, a[1] + f)
        for i, tau in self.torques:
            if i < 0:
                continue
            n = ca.mtimes(kin.R[i].T, tau)
            a = out.get(i)
            out[i] = (n, z3()) if a is None else (a[0] + n, a[1])
        return out

    def Q_extra(self, env):
        """q-space forces of the equation layer: Q_gen - dV_terms/dq - dD_terms/dqd."""
        Q = self.Q_gen
        if not _is_zero(self.V_terms):
            Q = Q - ca.gradient(self.V_terms, env.q)
        if not _is_zero(self.D_terms):
            Q = Q - ca.gradient(self.D_terms, env.qd)
        return Q

    def Q_applied(self, kin: Kinematics, env):
        """Generalized forces of applied forces/torques by virtual work, plus Q_gen."""
        Q = self.Q_gen
        for kind, i, r, F in self.applied:
            if i < 0:
                continue
            vel = kin.link_vel(i, r) if kind == "force" else ca.mtimes(kin.R[i], kin.w[i])
            Q = Q + ca.mtimes(ca.jacobian(vel, env.qd).T, F)
        return Q


def _is_zero(x) -> bool:
    return isinstance(x, (int, float)) and x == 0 or (isinstance(x, ca.SX) and x.is_zero())


def build_loads(model: ir.Model, kin: Kinematics, env) -> Loads:
    b = _LoadBuilder(model, kin, env)
    f = None
    try:
        for f in model.forces:
            step = b.STEPS.get(type(f))
            if step is None:
                raise MechError(Diagnostic("E721", f"unsupported force '{getattr(f, 'name', f)}'"))
            step(b, f)
    except MechError as e:      # a query without a place of its own (E725): at the force
        raise located(e, getattr(f, "span", None)) from None
    b.L.V, b.L.D = b.V, b.D
    return b.L


class _LoadBuilder:
    """build_loads's state: the loads so far, the potential V and the dissipation D, one method
    per kind of force (STEPS)."""

    def __init__(self, model: ir.Model, kin: Kinematics, env):
        self.model, self.kin, self.env, self.tree = model, kin, env, kin.tree
        self.L = Loads(Q_gen=ca.SX.zeros(len(env.coords), 1))
        self.V, self.D = ca.SX(0), ca.SX(0)
        self.masses = {b.name: env.translate(b.mass) for b in model.bodies if b.kind in ("point", "rigid")}

    def vec(self, v):
        return ca.vertcat(*[ca.SX(self.env.translate(c)) for c in v])

    def gravity(self, f) -> None:
        kin, g = self.kin, self.vec(f.g)
        for b in self.model.bodies:
            if b.name not in self.masses:
                continue
            i, c = kin.com_link(b)
            m = self.masses[b.name]
            self.L.point_forces.append((i, c, m * g))
            self.V = self.V - m * ca.dot(g, kin.link_pos(i, c))

    def spring_damper(self, f) -> None:
        kin = self.kin
        ia, ra = self.tree.point_in_link(f.a)
        ib, rb = self.tree.point_in_link(f.b)
        d = kin.link_pos(ib, rb) - kin.link_pos(ia, ra)
        dd = kin.link_vel(ib, rb) - kin.link_vel(ia, ra)
        k, c, l0 = (self.env.translate(x) for x in (f.k, f.c, f.l0))
        l0_zero = isinstance(f.l0, ir.Const) and f.l0.value == 0
        l = ca.norm_2(d)
        F = ca.SX.zeros(3, 1)
        if f.kind in ("spring", "spring-damper") and not _is_zero(ca.SX(k)):
            F = F - (k * d if l0_zero else k * (l - l0) * d / l)
            self.V = self.V + 0.5 * k * ((ca.dot(d, d) if l0_zero else (l - l0) ** 2))
        if f.kind in ("damper", "spring-damper") and not _is_zero(ca.SX(c)):
            ldot = ca.dot(d, dd) / l
            F = F - c * ldot * d / l
            self.D = self.D + 0.5 * c * ldot ** 2
        self.L.point_forces.append((ib, rb, F))
        self.L.point_forces.append((ia, ra, -F))

    def gravitation(self, f) -> None:
        G = self.env.translate(f.G)
        bodies = [self.model.body(b) for b in f.bodies]
        cs = [self.kin.com_link(b) for b in bodies]
        pos = [self.kin.link_pos(i, c) for i, c in cs]
        for a in range(len(bodies)):
            for b in range(a + 1, len(bodies)):
                ma, mb = self.masses.get(bodies[a].name, 0), self.masses.get(bodies[b].name, 0)
                d = pos[b] - pos[a]
                r = ca.norm_2(d)
                F = -G * ma * mb * d / r ** 3          # on b
                self.L.point_forces.append((cs[b][0], cs[b][1], F))
                self.L.point_forces.append((cs[a][0], cs[a][1], -F))
                self.V = self.V - G * ma * mb / r

    def applied_force(self, f) -> None:
        i, r = self.tree.point_in_link(f.point)
        F = self.vec(f.F)
        if f.frame != "world":
            F = ca.mtimes(self.kin.body_rot(f.frame), F)
        self.L.point_forces.append((i, r, F))
        self.L.applied.append(("force", i, r, F))

    def applied_torque(self, f) -> None:
        i = self.tree.body_link[f.body]
        tau = self.vec(f.tau)
        if f.frame != "world":
            tau = ca.mtimes(self.kin.body_rot(f.frame), tau)
        self.L.torques.append((i, tau))
        self.L.applied.append(("torque", i, None, tau))

    def generalized_force(self, f) -> None:
        try:
            k = self.env.coords.index(f.coordinate)
        except ValueError:
            raise MechError(Diagnostic("E720", f"generalized force '{f.name}' on unknown coordinate "
                                               f"'{f.coordinate}'", f.span)) from None
        self.L.Q_gen[k] = self.L.Q_gen[k] + self.env.translate(f.Q)

    STEPS = {ir.Gravity: gravity, ir.SpringDamper: spring_damper, ir.Gravitation: gravitation,
             ir.AppliedForce: applied_force, ir.AppliedTorque: applied_torque,
             ir.GeneralizedForce: generalized_force}


def located(err: MechError, span) -> MechError:
    """``err`` with ``span`` given to its diagnostics that have no place (line 0)."""
    if span is None or not span.line:
        return err
    return MechError([d if d.span.line else dataclasses.replace(d, span=span) for d in err.diagnostics])


def add_terms(L: Loads, model: ir.Model, env) -> None:
    """Equation-layer terms (and the component Potential) into L.T_terms/V_terms/D_terms."""
    T, V, D = ca.SX(0), ca.SX(0), ca.SX(0)
    for t in model.terms:
        e = env.translate(t.expr)
        if t.kind == "kinetic":
            T = T + e
        elif t.kind == "potential":
            V = V + e
        elif t.kind == "dissipation":
            D = D + e
        else:
            raise MechError(Diagnostic("E722", f"unknown term kind '{t.kind}'", t.span))
    L.T_terms, L.V_terms, L.D_terms = T, V, D
