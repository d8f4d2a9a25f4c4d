"""derive(model) -> EOM: route selection and assembly (see docs/internals/mechanics.md).

Routes
- 'aba'      every coordinate drives exactly one tree joint variable (or four of them form a
             quaternion) and there are no equation-layer kinetic terms: explicit forward
             dynamics by the articulated-body algorithm (O(N)); M by CRBA, bias by RNEA.
- 'crba'     components with coordinates that are not one-to-one joint variables (general
             expressions, shared coordinates, coordinates of the equation layer) or with
             equation-layer kinetic terms: M = B^T M_nu B + d2T_terms/dqd2 and the matching
             bias (projection of the joint-space equations with B = d nu / d qd, plus Lagrange
             by AD for the terms); qdd is left to a numerical factorization.
- 'lagrange' pure equation layer (or on request): M = d2T/dqd2 etc. by automatic
             differentiation of T, V, D (for components with T from velocities obtained by AD
             of the positions: an independent check of the recursive routes).
"""
from __future__ import annotations

import casadi as ca
import numpy as np

from .. import eom as eom_mod
from ..model import exprs, ir
from ..diagnostics import Diagnostic, MechError, UsageError
from . import chain, dynamics
from . import templates as tpl
from .constraints import loop_closures
from .forces import Loads, add_terms, build_loads
from .kinematics import Kinematics
from .queries import Query
from .rotations import quat_G
from .spatial import vee
from .tree import Tree

ROUTES = ("auto", "aba", "crba", "lagrange")
SMALL_SOLVE = 6     # symbolic solve of M qdd = bias only up to this size (reaction outputs)


def derive(model: ir.Model, route: str = "auto") -> eom_mod.EOM:
    if route not in ROUTES:
        raise UsageError(f"unknown route '{route}' (one of {', '.join(ROUTES)})")
    return _Deriver(model).run(route)


def _zero(x) -> bool:
    return isinstance(x, (int, float)) and x == 0 or (isinstance(x, ca.SX) and x.is_zero())


class _Deriver:
    def __init__(self, model: ir.Model):
        self.model = model
        coords = model.coordinate_names
        params = tuple(p.name for p in model.real_parameters)
        self.env0 = exprs.CasadiEnv.symbols(coords, params, inputs=tuple(p.name for p in model.inputs))
        e = self.env0
        self.q, self.qd, self.t, self.p = e.q, e.qd, e.t, e.p
        self.n = len(coords)

    def run(self, route: str) -> eom_mod.EOM:
        model, n = self.model, self.n
        q, qd, t = self.q, self.qd, self.t
        tree = self.tree = _guard(lambda: Tree(model, self.env0))
        kin = self.kin = Kinematics(tree)
        query = self.query = Query(model, kin)
        env = self.env = exprs.CasadiEnv(self.env0.coords, self.env0.params, q, qd, t, self.p, query=query,
                                         inputs=self.env0.inputs, u=self.env0.u)
        loads = self.loads = _guard(lambda: build_loads(model, kin, env))
        _guard(lambda: add_terms(loads, model, env))
        self._check_inertia(loads)

        one_to_one = (not tree.has_general and all(tree.coord_uses.get(i, 0) == 1 for i in range(n)))
        if route == "auto":
            if not tree.links:
                route = "lagrange"
            elif one_to_one and _zero(loads.T_terms):
                route = "aba"
            else:
                route = "crba"
        if route == "aba" and not (one_to_one and _zero(loads.T_terms)):
            raise UsageError("route 'aba' needs every coordinate to be exactly one tree joint variable "
                             "and no kinetic terms of the equation layer")
        self.route = route
        self.fext = loads.link_forces(kin)
        self.quats = [idx for _, idx in tree.quaternions]
        qdd = qdd_loop = None
        if route == "lagrange":
            T_body = self._kinetic_ad()
            T = T_body + loads.T_terms
            V = loads.V + loads.V_terms
            D = loads.D + loads.D_terms
            Q = loads.Q_applied(kin, env)
            M, bias = eom_mod.lagrange_terms(T, V, D, Q, q, qd, t)
            bias = self._project(bias)
            M, bias = self._regularize(M, bias)
        else:
            T = self._kinetic_tree() + loads.T_terms
            V = loads.V + loads.V_terms
            D = loads.D + loads.D_terms
            Q = _Lazy(lambda: loads.Q_applied(kin, env))
            if route == "aba":
                qdd = self._aba()
                M = bias = _Lazy(self._tmt)          # only when someone asks (CRBA is O(N^2))
                qdd_loop = _Lazy(lambda: chain.plan(tree, loads.link_forces, self.tau, qdd, self._qdd_of))
            else:
                M, bias = self._tmt()
        self.M, self.bias, self.qdd = M, bias, qdd

        query.energies = {"kinetic": T, "potential": V, "dissipation": D, "energy": T + V}
        query.reaction = self._reaction
        query.acceleration = self._acceleration

        g_list, g_names = [], []
        for c in model.constraints:
            g_list.append(_guard(lambda c=c: env.translate(c.residual)))
            g_names.append(c.name)
        self.n_explicit = len(g_list)
        lr, ln, self.closures = loop_closures(model, tree, kin, offset=len(g_list))
        g_list += lr
        g_names += ln
        self.constrained = bool(g_list)
        if self.constrained:
            self._check_quadratic(M)
        g = ca.vertcat(*[ca.SX(x) for x in g_list]) if g_list else None
        self.g = g
        self.lam = ca.SX.sym("lam", len(g_list)) if g_list else None

        outputs = {o.name: _guard(lambda o=o: ca.SX(env.translate(o.expr))) for o in model.outputs}
        e0 = self.env0
        q0 = ca.vertcat(*[ca.SX(_guard(lambda c=c: e0.translate(c.start))) for c in model.coordinates]) if n else ca.SX(0, 1)
        qd0 = ca.vertcat(*[ca.SX(_guard(lambda c=c: e0.translate(c.speed))) for c in model.coordinates]) if n else ca.SX(0, 1)
        monitors = dict(tree.euler_monitors)
        invariants = {}
        for joint, idx in tree.quaternions:
            qb = ca.vertcat(*[q[i] for i in idx])
            invariants[f"{joint.name}.quaternion_norm"] = ca.norm_2(qb) - 1
        notes = [self._route_note()]
        self._check_inputs(T, g)
        return LazyEOM(
            name=model.name, coords=model.coordinate_names, params=e0.params,
            param_values=np.array([p.value for p in model.real_parameters], float),
            q=q, qd=qd, t=t, p=self.p, T=T, V=V, D=D, Q=Q, M=M, bias=bias, qdd=qdd, g=g,
            constraint_names=tuple(g_names), outputs=outputs, q0=q0, qd0=qd0,
            fixed_q=tuple(c.fixed for c in model.coordinates),
            fixed_qd=tuple(c.speed_fixed for c in model.coordinates),
            route=route, model=model, point_position=kin.point_pos, point_velocity=kin.point_vel, qdd_loop=qdd_loop,
            body_rotation=kin.body_rot,
            singularity_monitors=monitors, invariants=invariants, notes=notes, lam=self.lam,
            u=e0.u, inputs=e0.inputs, input_defaults=tuple(float(p.value) for p in model.inputs))

    def _check_inputs(self, T, g):
        """An input in the kinematics (a prescribed motion, a moving frame) would need its time
        derivatives, which a signal u(t) does not give: refused (E760) instead of a silent
        wrong answer (d/dt would miss du/dt)."""
        u = self.env0.u
        if u is None or u.numel() == 0:
            return
        kin = self.kin
        poses = [ca.SX(x) for i in range(len(kin.R)) for x in (kin.R[i], kin.o[i]) if x is not None]
        moving = [ca.SX(T)] + ([ca.SX(g)] if g is not None else []) + poses
        for j, p in enumerate(self.model.inputs):
            if any(ca.depends_on(e, u[j]) for e in moving):
                raise MechError(Diagnostic(
                    "E760", f"input '{p.name}' moves part of the mechanism (a prescribed motion, a moving "
                            "frame or a constraint): its time derivatives would be needed, which an input "
                            "signal does not provide", p.span,
                    "inputs act through forces, torques and generalized forces; for a driven motion use a "
                    "coordinate driven by a stiff spring or a force, or a prescribed function of time"))

    # -- energies ---------------------------------------------------------------------
    def _kinetic_tree(self):
        T = ca.SX(0)
        kin = self.kin
        for lk in self.tree.links:
            if lk.inertia is None or lk.body is None:
                continue
            i = lk.index
            I = lk.inertia
            T = T + tpl.kinetic()(I.A, I.B, I.C, kin.w[i], kin.v[i])
        return T

    def _kinetic_ad(self):
        """T from velocities obtained by differentiating positions and rotations (AD)."""
        q, qd, t = self.q, self.qd, self.t
        kin = self.kin
        T = ca.SX(0)
        for b in self.model.bodies:
            if b.kind not in ("point", "rigid"):
                continue
            i, c = kin.com_link(b)
            if i < 0:
                continue
            m = self.env0.translate(b.mass)
            pc = kin.link_pos(i, c)
            vc = ca.jtimes(pc, q, qd) + ca.jacobian(pc, t)
            T = T + 0.5 * m * ca.dot(vc, vc)
            if b.kind == "rigid":
                R = kin.R[i]
                Rd = ca.reshape(ca.jtimes(ca.vec(R), q, qd) + ca.jacobian(ca.vec(R), t), 3, 3)
                w = vee(ca.mtimes(R.T, Rd))
                Ic = self.tree.mat(b.inertia)
                T = T + 0.5 * ca.dot(w, ca.mtimes(Ic, w))
        return T

    # -- dynamics ---------------------------------------------------------------------
    def _Bgamma(self):
        nu = self.tree.nu
        B = ca.jacobian(nu, self.qd)
        gam = ca.jtimes(nu, self.q, self.qd) + ca.jacobian(nu, self.t)
        return B, gam

    def _tmt(self):
        """M and bias in q-space from the joint-space CRBA/RNEA: B^T (M_nu (B qdd + gamma) - b_nu)."""
        if hasattr(self, "_tmt_result"):
            return self._tmt_result
        self._tmt_result = self._tmt_compute()
        return self._tmt_result

    def _tmt_compute(self):
        tree, kin, loads = self.tree, self.kin, self.loads
        q, qd, t = self.q, self.qd, self.t
        Mnu = dynamics.crba(tree)
        Cnu, _ = dynamics.rnea(tree, kin, self.fext)
        B, gam = self._Bgamma()
        M = ca.mtimes(ca.mtimes(B.T, Mnu), B)
        bias = ca.mtimes(B.T, -Cnu - ca.mtimes(Mnu, gam)) + self._project(loads.Q_extra(self.env))
        if not _zero(loads.T_terms):
            Mt, bt = eom_mod.lagrange_terms(loads.T_terms, ca.SX(0), ca.SX(0), ca.SX.zeros(self.n, 1), q, qd, t)
            M, bias = M + Mt, bias + bt
        return self._regularize(M, bias)

    def _tau(self):
        """Joint-space forces of the q-space forces Q_extra: tau = H^T Q (H = d qd / d nu)."""
        tree, q = self.tree, self.q
        Qx = self.loads.Q_extra(self.env)
        tau = ca.SX.zeros(len(tree.dofs), 1)
        for lk in tree.links:
            if not lk.dofs:
                continue
            if lk.quat:
                tq = 0.5 * ca.mtimes(quat_G(_sub(q, lk.quat)), _sub(Qx, lk.quat))
                for col, k in enumerate(lk.dofs):
                    tau[k] = tq[col]
            else:
                for k in lk.dofs:
                    tau[k] = Qx[tree.dofs[k].var.coord]
        return tau

    def _aba(self):
        self.tau = self._tau()
        nud, self.acc = dynamics.aba(self.tree, self.kin, self.fext, self.tau)
        self.nud = nud
        return self._qdd_of(nud)

    def _qdd_of(self, nud):
        """q'' from the joint-space accelerations nu' (the identity for plain coordinates)."""
        tree, q, qd = self.tree, self.q, self.qd
        qdd = ca.SX.zeros(self.n, 1)
        gam = None
        for lk in tree.links:
            if not lk.dofs:
                continue
            if lk.quat:
                if gam is None:
                    gam = self._Bgamma()[1]
                qb, qdb = _sub(q, lk.quat), _sub(qd, lk.quat)
                wd = _sub(nud, lk.dofs) - _sub(gam, lk.dofs)
                qq = 0.5 * ca.mtimes(quat_G(qb).T, wd) - qb * ca.dot(qdb, qdb) / ca.dot(qb, qb)
                for a, i in enumerate(lk.quat):
                    qdd[i] = qq[a]
            else:
                for k in lk.dofs:
                    qdd[tree.dofs[k].var.coord] = nud[k]
        return qdd

    def _project(self, Q):
        """Remove the components along q of quaternion blocks (absorbed by |q| = const)."""
        if not self.quats:
            return Q
        Q = ca.SX(Q)
        for idx in self.quats:
            qb = _sub(self.q, idx)
            Qb = _sub(Q, idx)
            Qb = Qb - qb * ca.dot(qb, Qb) / ca.dot(qb, qb)
            for a, i in enumerate(idx):
                Q[i] = Qb[a]
        return Q

    def _regularize(self, M, bias):
        """Quaternion blocks: add mu q q^T to M and -mu q |qd|^2 to bias, i.e. the equation
        q . qdd + |qd|^2 = 0 (d/dt (q . qd) = 0) along the null direction q of the block."""
        if not self.quats:
            return M, bias
        M, bias = ca.SX(M), ca.SX(bias)
        for idx in self.quats:
            qb, qdb = _sub(self.q, idx), _sub(self.qd, idx)
            mu = sum(M[i, i] for i in idx) / 3
            add = mu * ca.mtimes(qb, qb.T)
            for a, i in enumerate(idx):
                bias[i] = bias[i] - mu * qb[a] * ca.dot(qdb, qdb)
                for b, j in enumerate(idx):
                    M[i, j] = M[i, j] + add[a, b]
        return M, bias

    # -- reactions --------------------------------------------------------------------
    def _reaction(self, ref: ir.ReactionRef):
        """Reaction outputs: RNEA after the forward dynamics.  In constrained models the loop
        closures' multipliers act as loads (SX in EOM.lam, which the DAE solver substitutes)
        and a cut joint's reaction is its multipliers turned into the child joint frame."""
        if not hasattr(self, "_reactions"):
            self._reactions = self._all_reactions(ref)
        if ref.joint not in self._reactions:
            raise MechError(Diagnostic("E752", f"no joint '{ref.joint}' for a reaction output"))
        n, f = self._reactions[ref.joint]
        if ref.what not in ("force", "torque") or not 0 <= ref.i < 3:
            raise MechError(Diagnostic("E753", f"bad reaction component {ref.what}[{ref.i + 1}]"))
        return (f if ref.what == "force" else n)[ref.i]

    # -- accelerations (p.a, b.alpha) ----------------------------------------------------
    def _acceleration(self, key, velocity):
        """d/dt of a velocity-level SX (a point's velocity, a body's angular velocity) along
        the motion: (dv/dq) qd + (dv/dqd) qdd + dv/dt with qdd of the forward dynamics (SX in
        EOM.lam in a constrained model, which the DAE solver substitutes)."""
        memo = self.__dict__.setdefault("_accelerations", {})
        if key not in memo:
            v = velocity()
            qdd = self._qdd_all(key)
            memo[key] = (ca.mtimes(ca.jacobian(v, self.q), self.qd) + ca.mtimes(ca.jacobian(v, self.qd), qdd)
                         + ca.jacobian(v, self.t))
        return memo[key]

    def _qdd_all(self, key):
        if not hasattr(self, "_qdd_memo"):
            if self.route == "aba" and not self.constrained:
                self._qdd_memo = self.qdd
            elif self.n <= SMALL_SOLVE:
                M, bias = (self.M, self.bias) if self.route == "lagrange" else self._tmt()
                if self.constrained:
                    bias = bias - ca.mtimes(ca.jacobian(self.g, self.q).T, self.lam)
                self._qdd_memo = ca.solve(M, bias)
            else:
                what = f"{key[1]}.{key[0]}"
                raise MechError(Diagnostic("E750", f"the acceleration {what} needs the explicit forward dynamics, "
                                                   f"not available on route '{self.route}' with {self.n} coordinates",
                                           help="accelerations are available for trees of joints and for models "
                                                f"with at most {SMALL_SOLVE} coordinates"))
        return self._qdd_memo

    def _all_reactions(self, ref) -> dict:
        tree, kin = self.tree, self.kin
        fext = dict(self.fext)
        out = {}
        if self.constrained:
            if self.n_explicit:
                raise MechError(Diagnostic("E751", f"reaction of joint '{ref.joint}' in a model with explicit "
                                                   "constraint equations",
                                           help="reactions are available for trees and for loops closed by joints"))
            loads = []
            for clo in self.closures:
                F, T = clo.loads(kin, self.lam)
                j = clo.joint
                ic, rc = tree.point_in_link(j.child)
                ip, rp = tree.point_in_link(j.parent)
                loads += [(ic, rc, F, T), (ip, rp, -F, -T)]
                Rc = _frame(kin.body_rot(j.child_body), tree.joint_axes(j)[1])
                out[j.name] = (ca.mtimes(Rc.T, T), ca.mtimes(Rc.T, F))
            for i, r, F, T in loads:
                if i < 0:
                    continue
                n, f = tpl.point_force()(kin.R[i], r, F)
                n = n + ca.mtimes(kin.R[i].T, T)
                a = fext.get(i)
                fext[i] = (n, f) if a is None else (a[0] + n, a[1] + f)
        if self.route == "aba":
            nud = dynamics.aba(tree, kin, fext, self.tau)[0] if self.constrained else self.nud
        elif self.n <= SMALL_SOLVE:
            B, gam = self._Bgamma()
            M, bias = self._tmt() if self.route == "crba" else (self.M, self.bias)
            if self.constrained:
                bias = bias - ca.mtimes(ca.jacobian(self.g, self.q).T, self.lam)
            nud = ca.mtimes(B, ca.solve(M, bias)) + gam
        else:
            raise MechError(Diagnostic("E750", f"reaction of joint '{ref.joint}' needs the explicit "
                                               f"forward dynamics, not available on route '{self.route}'"))
        out.update(dynamics.joint_reactions(tree, kin, fext, nud))
        return out

    # -- checks and notes -------------------------------------------------------------
    def _check_inertia(self, loads: Loads):
        """A coordinate with no inertia at all (no joint, no kinetic term) makes M singular."""
        tree = self.tree
        used = set(tree.coord_uses)
        for d in tree.dofs:
            if d.var is not None and d.var.kind == "general":
                used |= {i for i in range(self.n) if ca.depends_on(d.nu, self.qd[i])}
        for _, idx in tree.quaternions:
            used |= set(idx)
        if not _zero(loads.T_terms):
            used |= {i for i in range(self.n) if ca.depends_on(loads.T_terms, self.qd[i])}
        missing = [self.model.coordinates[i] for i in range(self.n) if i not in used]
        if missing and not self.model.constraints and not any(j.closes_loop for j in self.model.joints):
            c = missing[0]
            raise MechError(Diagnostic("E731", f"coordinate '{c.name}' has no inertia: it drives no joint "
                                               "and appears in no kinetic energy term", c.span))

    def _check_quadratic(self, M) -> None:
        """The constrained formulations solve M(q) q'' + G^T lambda = bias: a kinetic energy that
        is not quadratic in the speeds (M depends on them) has no such form (E754)."""
        if isinstance(M, _Lazy) or not isinstance(M, ca.SX) or not ca.depends_on(M, self.qd):
            return
        spans = [t.span for t in self.model.terms if t.kind == "kinetic"]
        raise MechError(Diagnostic("E754", "the kinetic energy is not quadratic in the speeds (its second "
                                           "derivative in them depends on the speeds): a model with "
                                           "constraints needs T = 1/2 der(q)' M(q) der(q)",
                                   spans[0] if spans else self.model.span,
                                   "write the kinetic energy as a quadratic form of der(...), or remove the "
                                   "constraints (an unconstrained model accepts any kinetic energy)"))

    def _route_note(self) -> str:
        tree = self.tree
        nb = len(self.model.bodies)
        if self.route == "aba":
            return (f"route aba: {nb} bodies, {len(tree.links)} links, {len(tree.dofs)} joint speeds; "
                    "explicit forward dynamics by the articulated-body algorithm")
        if self.route == "crba":
            return ("route crba: joint-space M (CRBA) and bias (RNEA) projected on the coordinates"
                    + (" plus Lagrange terms of the equation layer" if not _zero(self.loads.T_terms) else "")
                    + "; M qdd = bias is solved numerically")
        return "route lagrange: M = d2T/dqd2 and the bias by automatic differentiation of T, V, D"


def _frame(R, axes):
    """World axes of a joint frame: its body's rotation R times the frame's axes in the body."""
    return R if axes is None else ca.mtimes(R, axes)


class _Lazy:
    """A field computed on first access (see LazyEOM); the value is shared by copies."""

    def __init__(self, fn):
        self.fn = fn
        self.done = False
        self.value = None

    def get(self):
        if not self.done:
            self.value = self.fn()
            self.done = True
        return self.value


class LazyEOM(eom_mod.EOM):
    """An EOM whose expensive fields (M and bias on the 'aba' route, where the simulator
    needs only qdd; Q; the looped form qdd_loop) are built on first access.  Behaves as a
    plain EOM otherwise; the field keeps its _Lazy holder (which keeps the value), so the
    object stays frozen."""

    def __getattribute__(self, name):
        if name in ("M", "bias", "Q", "qdd_loop"):
            v = object.__getattribute__(self, "__dict__").get(name)
            if isinstance(v, _Lazy):
                r = v.get()
                if name in ("M", "bias") and isinstance(r, tuple):
                    return r[0] if name == "M" else r[1]
                return r
        return object.__getattribute__(self, name)


def _sub(v, idx):
    return ca.vertcat(*[v[i] for i in idx])


def _guard(fn):
    """Translate IR evaluation failures into diagnostics."""
    try:
        return fn()
    except (MechError, UsageError):
        raise
    except (ValueError, KeyError) as e:
        raise MechError(Diagnostic("E729", f"cannot derive the equations: {e}")) from None
