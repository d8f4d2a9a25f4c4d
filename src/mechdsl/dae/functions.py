"""The CasADi Functions of a constrained model's formulated problem (``Model.casadi`` of a
model with constraints, issue 22).

A constrained run integrates the index-1 ODE of the DAE: at every state the accelerations and
the multipliers come from the augmented (KKT) system

    [ M   G^T ] [ q''    ]   [ bias  ]
    [ G   0   ] [ lambda ] = [ gamma ]        (G q'' = gamma keeps the state on the manifold)

over the independent constraints (mechdsl.dae.dof, chosen at the consistent start).  So the
Functions here are those of the formulated problem, with the signature of every model's
Functions (t, x = [q; qd], u, p):

    ode                  -> xdot = [qd; q'']     the run's accelerations, multipliers solved
    ode_jacobian         -> d xdot / d x
    multipliers          -> lambda               one per constraint (0 for a dropped redundant one)
    outputs              -> the model's outputs, reactions included (they read lambda)
    constraint_jacobian  -> G = dg/dq            every constraint
    mass_matrix, bias, constraints (g, gdot), energy, start, parameters, ...: as for any model

The formulations (projection, ggl, baumgarte, ...) integrate this ODE or an equivalent DAE;
their stabilization terms (Baumgarte's alpha gdot + beta^2 g) vanish on the manifold, so on a
consistent state the run's accelerations are these.
"""
from __future__ import annotations

import casadi as ca

from ..eom import fold_inputs
from ..eom.codegen import TXUP, FunctionSet, available, jacobian_of
from ..eom.specialize import shared_derivatives, specialize
from ..eom.fold import fold_parameters
from ..eom.numeric_p import numeric_p
from ..eom.start import fixed_start
from .constrained_system import ConstrainedSystem
from .dof import dof_report
from .init import initialize


OWN = ("ode", "multipliers", "outputs", "constraint_jacobian")      # built here (the rest: codegen's)


class ConstrainedFunctionSet(FunctionSet):
    """``codegen.FunctionSet`` of a constrained model: its own ``ode``, ``ode_jacobian``,
    ``multipliers``, ``outputs`` and ``constraint_jacobian`` (the module docstring)."""

    def __init__(self, eom, *, names=None, **kw):
        super().__init__(eom, names=None, **kw)
        every = tuple(available(eom)) + ("multipliers", "constraint_jacobian")
        self._names = every if names is None else tuple(n for n in every if n in names)
        self._system = None

    def __getitem__(self, name):
        if name in OWN + ("ode_jacobian",) and not self.want_compiled and name in self._names:
            if name not in self._cache:          # never the model cache's (the tree's ode)
                f = jacobian_of(self["ode"]) if name == "ode_jacobian" else self._make(name)
                self._cache[name] = numeric_p(f) if self.sx else f
            return self._cache[name]
        return super().__getitem__(name)

    def _make(self, name, loop: bool = False):
        if name not in OWN:
            return super()._make(name, loop=False)
        f = self._build_own(name)
        f = specialize(f, self.fixed, len(self.eom.params)) if self.fixed else f
        return shared_derivatives(f) if self.sx else f

    def system(self) -> ConstrainedSystem:
        """The constrained system over the independent constraints at the consistent start
        (inputs held as trailing parameters p' = [p; u])."""
        if self._system is None:
            base = fold_inputs(self.eom)
            pv = base.param_values
            q0, qd0, fq, fqd = fixed_start(base, None, pv)
            init = initialize(base, q0, qd0, 0.0, pv, fixed_q=fq, fixed_qd=fqd)
            dof = dof_report(base, init.q, 0.0, pv)
            self._system = ConstrainedSystem.build(base, pv, dof.independent)
        return self._system

    def _build_own(self, name):
        eom = self.eom
        n, m = eom.n, eom.m
        if name == "constraint_jacobian":
            x = ca.vertcat(eom.q, eom.qd)
            G = ca.jacobian(ca.SX(eom.g), eom.q)
            return ca.Function(name, [eom.t, x, eom.u_sym, eom.p], [G], TXUP, ["G"])
        system = self.system()
        Sym = ca.SX if system.route in ("sx", "schur") else ca.MX
        t, x, u, p = Sym.sym("t"), Sym.sym("x", 2 * n), Sym.sym("u", eom.u_sym.numel()), Sym.sym("p", eom.p.numel())
        qdd, lam = system.fn["accel"](x[:n], x[n:], t, ca.vertcat(p, u), 0, 0)
        if name == "ode":
            f = ca.Function("ode", [t, x, u, p], [ca.vertcat(x[n:], qdd)], TXUP, ["xdot"])
            return fold_parameters(f) if self.sx else f      # the parameters' arithmetic folded (eom.fold)
        where = {i: k for k, i in enumerate(system.active)}
        full = ca.vertcat(*[lam[where[i]] if i in where else Sym(0) for i in range(m)]) if m else Sym(0, 1)
        if name == "multipliers":
            return ca.Function(name, [t, x, u, p], [full], TXUP, ["lambda"])
        names = list(eom.outputs) if self.outputs is None else list(self.outputs)
        lam_sym = eom.lam if eom.lam is not None else ca.SX.sym("lam", m)
        raw = ca.Function("raw_outputs", [eom.t, ca.vertcat(eom.q, eom.qd), eom.u_sym, eom.p, lam_sym],
                          [ca.SX(eom.outputs[k]) for k in names], [*TXUP, "lam"], names,
                          {"allow_duplicate_io_names": True})
        return ca.Function("outputs", [t, x, u, p], raw(t, x, u, p, full), TXUP, names,
                           {"allow_duplicate_io_names": True})
