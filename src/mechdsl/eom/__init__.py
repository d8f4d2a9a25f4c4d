"""The equations of motion ("eom" IR): what ``derive`` hands to ``formulate``/``generate``.

All quantities are CasADi SX expressions in the symbols q, qd (column vectors in coordinate
order), t (scalar) and p (the real parameters in ``model.real_parameters`` order):

    M(q, t, p) qdd = bias(q, qd, t, p)          (Lagrange's equations)
    g(q, t, p) = 0                              (holonomic constraints, possibly empty)

with bias = Q - dD/dqd + dT/dq - dV/dq - d/dq(dT/dqd) qd - d/dt(dT/dqd).  Constrained models
add -G^T lambda to the right-hand side, G = dg/dq.

``qdd`` is the explicit forward dynamics when a recursive O(N) route produced it (tree of
components); otherwise None and ``M``/``bias`` are solved numerically.

The object is frozen (setting an attribute raises ``dataclasses.FrozenInstanceError``):
what phases derive from it and keep (Functions, searches, caches) lives in its workspace
(``mechdsl.eom.workspace.of(eom)``; ``api.Model.workspace``), never on the EOM.
"""
from __future__ import annotations

from dataclasses import field
import re
from typing import TYPE_CHECKING, Callable

from ..model.records import record

if TYPE_CHECKING:       # (an annotation only: a prepared warm run imports eom's helpers without the IR)
    from ..model import ir


@record(eq=False)      # eq=False: hashed and compared by identity (workspace key)
class EOM:
    name: str
    coords: tuple[str, ...]
    params: tuple[str, ...]
    param_values: np.ndarray
    q: object
    qd: object
    t: object
    p: object
    T: object
    V: object
    D: object
    Q: object                      # non-conservative generalized forces other than -dD/dqd
    M: object
    bias: object
    qdd: object | None = None      # explicit forward dynamics (recursive route), or None
    g: object | None = None        # constraint residuals (m,), or None
    constraint_names: tuple[str, ...] = ()
    outputs: dict[str, object] = field(default_factory=dict)
    q0: object | None = None       # start values as SX in p (n,)
    qd0: object | None = None
    fixed_q: tuple[bool, ...] = ()
    fixed_qd: tuple[bool, ...] = ()
    route: str = "lagrange"        # 'aba' | 'lagrange' | 'crba'
    model: ir.Model | None = None
    point_position: Callable[[str], object] | None = None   # point name -> SX (3,) in q, t, p
    notes: list[str] = field(default_factory=list)
    point_velocity: Callable[[str], object] | None = None   # point name -> SX (3,) in q, qd, t, p
    # scalars in q (and t, p) that vanish where a parametrization is singular (Euler-angle gimbal
    # lock), by name "<joint>.gimbal"; a simulator reports when a run comes near zero.
    singularity_monitors: dict[str, object] = field(default_factory=dict)
    # drift measures that stay 0 in exact arithmetic ("<joint>.quaternion_norm" = |q| - 1)
    invariants: dict[str, object] = field(default_factory=dict)
    # multipliers of the constraints (DAE models): an SX symbol (m,) that outputs and
    # `reactions` may depend on; the DAE simulator substitutes the computed multipliers.
    lam: object | None = None
    reactions: dict[str, object] = field(default_factory=dict)   # name -> SX in q, qd, t, p, lam
    body_rotation: Callable[[str], object] | None = None    # body name -> SX (3, 3) in q, t, p (drawing)
    # control inputs (``input Real F``): an SX symbol (n_u,) the forces may depend on, and names
    u: object | None = None
    inputs: tuple[str, ...] = ()
    input_defaults: tuple[float, ...] = ()     # the value of each input when nothing drives it
    # qdd as loops over per-link kernels (mechanics/chain.py ChainPlan: ``.ode(eom)`` gives the
    # MX Function), or None where the topology has no run of identical links
    qdd_loop: object | None = None

    @property
    def u_sym(self):
        """The input symbol u (an empty SX column when the model has no inputs)."""
        import casadi as ca

        return ca.SX(0, 1) if self.u is None else self.u

    @property
    def nu(self) -> int:
        return len(self.inputs)

    @property
    def n(self) -> int:
        return len(self.coords)

    def replace(self, **changes) -> "EOM":
        """A shallow copy with some fields changed.  Unlike dataclasses.replace it does not
        touch the other fields, so fields that derive computes on first access (M and bias
        on the 'aba' route, whose O(N^2) CRBA a simulation does not need) stay lazy.  The
        copy gets a fresh workspace that shares the content-keyed values (workspace.inherit)."""
        import copy

        from . import workspace

        for k in changes:
            if k not in self.__dataclass_fields__:
                raise TypeError(f"EOM has no field {k!r}")
        new = copy.copy(self)
        for k, v in changes.items():
            object.__setattr__(new, k, v)        # the copy is not yet shared with anyone
        workspace.inherit(new, self)
        return new

    @property
    def workspace(self):
        """The derived values kept for this EOM (mechdsl.eom.workspace)."""
        from . import workspace

        return workspace.of(self)

    @property
    def m(self) -> int:
        return 0 if self.g is None else int(self.g.numel())

    @property
    def energy(self):
        return self.T + self.V

    def start(self, p: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Numeric start values (q0, qd0) for parameter vector p (default: model values)."""
        import casadi as ca
        import numpy as np

        pv = np.asarray(self.param_values if p is None else p, float)
        kept = self.workspace.memo("start_values", dict)      # by parameter values: a run asks twice
        key = pv.tobytes()
        hit = kept.get(key)
        if hit is None:
            f = self.workspace.start_function(self)
            a, b = f(pv)
            hit = (np.array(a, float).ravel(), np.array(b, float).ravel())
            if len(kept) >= 64:
                kept.pop(next(iter(kept)), None)
            kept[key] = hit
        return hit[0].copy(), hit[1].copy()


def explicit_constraints(eom: "EOM") -> tuple[bool, ...]:
    """Per constraint: True for an explicit constraint equation, False for a loop-closing joint's
    closure row (whose multiplier already is a reaction component in the joint frame)."""
    if eom.model is None:
        return (True,) * eom.m
    names = {c.name for c in eom.model.constraints}
    return tuple(n in names for n in eom.constraint_names)


CLOSURE_ROW = re.compile(r".+\.(f|t)[xyz123]")     # a cut joint's closure row: <joint>.fx, <joint>.ty, ...


def multiplier_units(eom: "EOM") -> tuple[str | None, ...]:
    """The unit of each multiplier, as reported (unscaled: the lambda of M q'' = f - G' lambda).

    An explicit constraint g = lhs - rhs: J / [g] (model.units.multiplier_unit: N for a length,
    N.m for an angle, N/m for a squared length; None when g's unit is unknown).  A cut joint's
    closure rows are reaction components: N (``.f?``) and N.m (``.t?``).  Issue 23: the
    multipliers were reported times |dg/dq| (issue 17), a number that is a force only when g
    involves one point's coordinates."""
    from ..model.units import multiplier_unit

    dims = {c.name: c.dim for c in eom.model.constraints} if eom.model is not None else {}
    out = []
    for name in eom.constraint_names:
        if name in dims:
            out.append(multiplier_unit(dims[name]))
        elif eom.model is not None and CLOSURE_ROW.fullmatch(name):
            out.append("N" if name.rsplit(".", 1)[1].startswith("f") else "N.m")
        else:
            out.append(None)
    return tuple(out)


def fold_inputs(eom: "EOM", u=None) -> "EOM":
    """The same equations with the inputs held constant as trailing parameters: p' = [p; u],
    valued ``u`` (default: the inputs' defaults).  For the phases that treat inputs as
    constants (equilibria, linearization's B by d bias/dp, the DAE, contact and fixed-step
    back ends); the structure is built once per EOM."""
    if not eom.inputs:
        return eom
    import casadi as ca
    import numpy as np

    base = eom.workspace.folded("base", lambda: eom.replace(p=ca.vertcat(eom.p, eom.u), params=eom.params + eom.inputs,
                                                    u=None, inputs=(), input_defaults=()))
    uv = np.asarray(eom.input_defaults if u is None else u, float).ravel()
    return base.replace(param_values=np.r_[np.asarray(eom.param_values, float).ravel(), uv])


def parameter_vector(eom: "EOM", p=None) -> np.ndarray:
    """The numeric parameter vector: the model's values, or overrides (a dict by name, or a
    full vector).  Shared by every phase that takes ``p=``."""
    import numpy as np

    from ..diagnostics import UsageError, did_you_mean

    base = np.array(eom.param_values, float).ravel().copy()
    if p is None:
        return base
    if isinstance(p, dict):
        from ..numbers import declared_value

        units = {q.name: q.unit for q in eom.model.parameters} if eom.model is not None else {}
        for k, v in p.items():
            if k not in eom.params:
                hint = did_you_mean(k, eom.params)
                raise UsageError(f"'{k}' is not a parameter of {eom.name}" + (f"; {hint}" if hint else ""))
            base[list(eom.params).index(k)] = declared_value(v, units.get(k), k)   # by name: the declared unit
        return base
    arr = np.array(p, float).ravel()
    if arr.size != base.size:
        raise UsageError(f"p has {arr.size} entries; {eom.name} has {base.size} parameters "
                         f"({', '.join(eom.params)})")
    return arr


def lagrange_terms(T, V, D, Q, q, qd, t):
    """M and bias of Lagrange's equations by automatic differentiation (CasADi SX)."""
    import casadi as ca

    dT_dqd = ca.gradient(T, qd)
    M = ca.jacobian(dT_dqd, qd)
    M = 0.5 * (M + M.T)
    bias = (Q - ca.gradient(D, qd) + ca.gradient(T, q) - ca.gradient(V, q)
            - ca.mtimes(ca.jacobian(dT_dqd, q), qd) - ca.jacobian(dT_dqd, t))
    return ca.simplify(M) if M.numel() <= 16 else M, bias


def from_lagrangian(name, coords, params, param_values, q, qd, t, p, T, V, D=None, Q=None, g=None,
                    q0=None, qd0=None, outputs=None, constraint_names=None, **kw) -> EOM:
    """Build an EOM from T, V, D, Q given as SX (the equation-layer route).

    Convenient for tests of formulations and analyses: write T and V in CasADi directly.
    """
    import casadi as ca
    import numpy as np

    n = len(coords)
    D = ca.SX(0) if D is None else D
    Q = ca.SX.zeros(n) if Q is None else Q
    M, bias = lagrange_terms(T, V, D, Q, q, qd, t)
    if g is not None and g.numel() == 0:
        g = None
    m = 0 if g is None else g.numel()
    return EOM(name=name, coords=tuple(coords), params=tuple(params),
               param_values=np.asarray(param_values, float), q=q, qd=qd, t=t, p=p,
               T=T, V=V, D=D, Q=Q, M=M, bias=bias, g=g,
               constraint_names=tuple(constraint_names or (f"g{i + 1}" for i in range(m))),
               outputs=dict(outputs or {}),
               q0=ca.SX.zeros(n) if q0 is None else ca.SX(q0),
               qd0=ca.SX.zeros(n) if qd0 is None else ca.SX(qd0),
               fixed_q=(True,) * n, fixed_qd=(True,) * n, **kw)
