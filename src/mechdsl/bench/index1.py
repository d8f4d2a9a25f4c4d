"""A constrained model's index-1 ODE, for ODE methods the DAE layer does not offer.

    M q'' + G^T lambda = bias,   G q'' = gamma - 2 alpha gdot - beta^2 g      (x = [q; q'])

built from ``mechdsl.dae.constrained_system.ConstrainedSystem`` (the same equilibrated KKT solve the
``baumgarte`` formulation integrates) and handed to ``mechdsl.simulate`` as the ``ode``
Function of the model without constraints, so that any ODE method runs on it: scipy's
DOP853, erk, rk, ... .  Benchmark-only (formulation ``index1-ode`` of ``mech bench``): the
drift of g is not controlled unless ``baumgarte = (alpha, beta)`` is given, and nothing
projects.  Its runs record the constraint residuals ``residual(name)`` like the DAE layer.

Like ``mechdsl.dae``, every call builds its system anew (degrees of freedom, independent
constraints, the symbolic KKT solve), so a benchmark compares the integration and its
supervision, not caching.
"""
from __future__ import annotations

from ..diagnostics import UsageError

FORMULATION = "index1-ode"


def simulate_index1(eom, t_end, *, method, baumgarte=None, constraints="independent", p=None, x0=None, **kw):
    """``constraints``: "independent" (the subset mechdsl.dae keeps: redundant rows dropped)
    or "all" (every constraint row, as a naive implementation would: with a redundant
    constraint the KKT matrix is singular)."""
    import casadi as ca

    from ..eom import parameter_vector
    from ..simulate import simulate
    from ..eom.start import start_vector

    if eom.g is None:
        raise UsageError(f"formulation {FORMULATION!r} needs a model with constraints")
    try:
        from ..dae.dof import dof_report
        from ..dae.constrained_system import ConstrainedSystem
    except ImportError:
        raise UsageError(f"formulation {FORMULATION!r} needs mechdsl.dae, which this build lacks") from None
    if method not in _ode_methods():
        raise UsageError(f"formulation {FORMULATION!r} takes an ODE method of mechdsl.simulate, not {method!r}")
    alpha, beta = (0.0, 0.0) if baumgarte is None else _rates(baumgarte)
    pv = parameter_vector(eom, p)
    xs = start_vector(eom, x0, pv)
    n = eom.n
    dof = dof_report(eom, xs[:n], float(kw.get("t_start", 0.0) or 0.0), pv)
    if constraints not in ("independent", "all"):
        raise UsageError(f"constraints must be 'independent' or 'all' (got {constraints!r})")
    system = ConstrainedSystem.build(eom, pv, dof.independent if constraints == "independent" else None)
    q, qd, t, pp = system.symbols()            # SX, or MX when the KKT system is solved numerically
    qdd, _ = system.fn["accel"](q, qd, t, pp, alpha, beta)
    x = ca.vertcat(q, qd)
    xdot = ca.vertcat(qd, qdd)
    u = type(x)(0, 1)                          # codegen's signature (t, x, u, p), no inputs
    ode = ca.Function("ode", [t, x, u, pp], [xdot], ["t", "x", "u", "p"], ["xdot"])
    funcs = {"ode": ode}
    if method not in _no_jacobian():
        funcs["ode_jacobian"] = ca.Function("ode_jacobian", [t, x, u, pp], [ca.jacobian(xdot, x)], ["t", "x", "u", "p"],
                                            ["jac"])
    compiled_note, native_code = None, False
    if kw.pop("compiled", False):
        # the same native code as the DAE layer's compiled runs, so that a chart compares methods
        from ..eom.codegen import compile_functions

        native, compiled_note, _lib = compile_functions(list(funcs.values()), tag="index1", jacobian=False)
        if native and all(native.get(k) is not None for k in funcs):
            funcs = {k: native[k] for k in funcs}
            compiled_note, native_code = None, True
    free = eom.replace(g=None)
    free.workspace.first_integrals(lambda: None)   # the free system's symmetries are not the model's
    r = simulate(free, t_end, method=method, p=pv, x0=xs, functions=funcs, **kw)
    r.metadata["compiled"] = native_code
    if compiled_note:
        r.metadata.setdefault("notes", []).append(compiled_note)
    if len(r.t):                     # the constrained model's residuals, as every constrained run records them
        from ..simulation import record as R

        r.signals.update(R.record(eom, R.residuals(eom), r.t, r.q, r.qd, pv))
    r.metadata["formulation"] = FORMULATION
    r.metadata["baumgarte"] = [alpha, beta]
    r.metadata["active_constraints"] = [eom.constraint_names[i] for i in system.active]
    r.metadata["conservative"] = None
    return r


def _rates(b):
    if isinstance(b, (tuple, list)) and len(b) == 2:
        return float(b[0]), float(b[1])
    w = float(b)
    return w, w


def _ode_methods():
    from ..simulation.registry import ode_methods

    return ode_methods()


def _no_jacobian():
    from ..simulation.registry import METHODS

    return tuple(m.name for m in METHODS.values() if not m.needs_jacobian)
