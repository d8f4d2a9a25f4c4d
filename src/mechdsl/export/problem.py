"""What an FMU takes from the simulation layer: one path to the equations and the settings.

The FMU's right-hand side, its multipliers and the pieces of its constraint handling are the
Functions a run integrates, ``Model.casadi()`` (simulation.functions.problem_functions: an
unconstrained model's minimal-coordinate ODE; a constrained model's index-1 ODE with the
multipliers solved over the independent constraints chosen at the consistent start,
mechdsl.dae.functions), so the FMU cannot disagree with ``mech simulate``
(tests/test_export_fmu.py compares them at random states).  The run's settings are
``Model.settings()`` (scene > defaults: the default end time and points); the co-simulation
stepper is the compiled loop's method for the settings' method (the registry,
``crk.loop_method``); the step budget is the ODE back end's (``ode.default_max_steps``); and
the tolerance rules the runtime applies when the importer changes the tolerance are read off
the settings' own rules (``rules``: the DAE drift bound, the contact tolerances), not copied.

What only the FMU does stays in its C runtime and is named there: the projection onto the
constraints at step events (model exchange), the drift checks between steps (co-simulation),
the consistent start after the importer set start values or parameters, and the hybrid loop
of contacts (mech_hybrid.c).
"""
from __future__ import annotations

import math

import numpy as np


def run_settings(model):
    """The settings of ``mech simulate`` for this model: argument > scene > default (the default
    end time and points included)."""
    return model.settings()


def functions(model):
    """The problem's Functions (``Model.casadi()``)."""
    return model.casadi()


def ode(model, funcs) -> tuple:
    """(Function ``mech_ode(t, x, u, p) -> (xdot, lam)``, active rows): ``funcs["ode"]`` and, for a
    constrained model, ``funcs["multipliers"]`` (every constraint's multiplier, 0 for a dropped
    redundant one; the EOM's sign convention M q'' = bias - G' lam) in one Function, their
    common subexpressions shared (the KKT solve once); the active rows are those the run holds
    (``funcs.system().active``).  An unconstrained model has no multipliers (lam empty)."""
    import casadi as ca

    f = funcs["ode"]
    constrained = model.eom.g is not None and model.eom.m > 0
    parts = [f] + ([funcs["multipliers"]] if constrained else [])
    Sym = ca.SX if all(g.is_a("SXFunction") for g in parts) else ca.MX
    args = [Sym.sym(f.name_in(i), f.sparsity_in(i)) for i in range(4)]
    xdot = ca.densify(f.call(args, True)[0])
    lam = ca.densify(parts[1].call(args, True)[0]) if constrained else Sym(0, 1)
    xdot, lam = ca.cse([xdot, lam]) if constrained else (xdot, lam)
    active = tuple(int(i) for i in funcs.system().active) if constrained else ()
    return ca.Function("mech_ode", args, [xdot, lam], ["t", "x", "u", "p"], ["xdot", "lam"]), active


def dynamics(model, funcs):
    """``mech_dyn(t, q, qd, u, p) -> M, bias`` (M q'' = bias) from the problem's ``mass_matrix``
    and ``bias``: what the runtime's projection, consistent start and contact accelerations solve
    with."""
    import casadi as ca

    M, b = funcs["mass_matrix"], funcs["bias"]
    eom = model.eom
    Sym = ca.SX if M.is_a("SXFunction") and b.is_a("SXFunction") else ca.MX
    t, q, qd = Sym.sym("t"), Sym.sym("q", eom.n), Sym.sym("qd", eom.n)
    u, p = Sym.sym("u", eom.u_sym.numel()), Sym.sym("p", eom.p.numel())
    outs = [ca.densify(M.call([q, t, p], True)[0]), ca.densify(b.call([t, ca.vertcat(q, qd), u, p], True)[0])]
    return ca.Function("mech_dyn", [t, q, qd, u, p], outs, ["t", "q", "qd", "u", "p"], ["M", "bias"])


def stepper(model, s, kind: str) -> str:
    """The co-simulation stepper ("dopri5" or "dop853") for the settings' method: a compiled-loop
    method as it is; otherwise the compiled loop running the same one-step class the back end of
    ``kind`` runs the method as (registry: a scipy method's class, the contact back end's
    ``events`` class); ``auto`` and methods without one (BDF, ...) as the compiled loop's own
    choice (``crk.loop_method``: dopri5 at rtol >= crk.DOPRI5_RTOL, else dop853)."""
    from ..simulation.backends.crk import CRK_METHODS, loop_method
    from ..simulation.registry import spec

    m = spec(str(s.method or "auto").lower())
    if m.family == "crk":
        return m.plugin
    one_step = m.events if kind == "hybrid" else (m.plugin if m.family == "scipy" else
                                                  (None if m.name == "auto" else m.events))
    for name, (_, cls) in CRK_METHODS.items():
        if cls == one_step:
            return name
    return loop_method(float(s.rtol))


def max_steps(s, points: int) -> int:
    """Integrator steps in one communication step: the run's budget per output interval."""
    from ..simulation.backends.ode import default_max_steps

    return default_max_steps(s, points)


def linear_rule(f, what: str) -> tuple[float, float]:
    """(factor, floor) of a rule ``f(a) = max(factor a, floor)`` (a >= 0), read off ``f`` itself
    and checked at tolerances over the whole range: a rule of another form is an internal error
    (the FMU's runtime evaluates this form), never a silent difference."""
    floor, factor = float(f(0.0)), float(f(1.0))
    for a in (1e-15, 1e-13, 1e-11, 1e-10, 1e-9, 1e-8, 1e-6, 1e-4, 1e-2, 0.5):
        want, got = float(f(a)), max(factor * a, floor)
        if not math.isclose(want, got, rel_tol=1e-12, abs_tol=0.0):
            raise AssertionError(f"internal: the rule of {what} is not max(c a, floor) (at {a:g}: {want:g} "
                                 f"against {got:g}); the FMU runtime (mech_fmu.h, MechRules) must follow it")
    return factor, floor


def rules(s, constrained: bool, contacts: bool) -> dict:
    """The tolerance rules of the runtime (mech_fmu.h ``MechRules``), from the settings' defaults
    and the modules that define them: the DAE back end's drift bound (``DaeOptions.bound``); for
    a constrained model the consistent start's feasibility tolerance (``dae.init``); for a model
    with contacts the event offset, contact touch distance and speed threshold of the event loop
    (``impacts.contact_run.ContactRun``), the contact system's rank tolerance and the event
    loop's Zeno guard.  Rules a model does not use are 0 (the runtime never reads them)."""
    import inspect

    from ..simulation.settings import DaeOptions

    dae = DaeOptions()
    out = {"drift": linear_rule(dae.bound, "the DAE drift bound (DaeOptions.bound)"),
           "offset": (0.0, 0.0), "touch": (0.0, 0.0), "v_eps": 0.0, "rank_tol": 0.0,
           "zeno_events": 1, "zeno_span": 0.0, "init_tol": 0.0}
    if constrained:
        from ..dae.init import initialize

        out["init_tol"] = float(inspect.signature(initialize).parameters["tol"].default)
    if contacts:
        from ..impacts.contact_run import ContactRun

        group = s.contacts

        def run(a, rest=None):
            opts = group if rest is None else type(group)(**{**{k: getattr(group, k) for k in
                                                                 group.__dataclass_fields__}, "rest_speed": rest})
            return ContactRun(opts, s.rtol, a)

        out["offset"] = linear_rule(lambda a: run(a).offset, "the event offset (ContactRun.offset)")
        if out["offset"][1] != 0.0:
            raise AssertionError("internal: ContactRun.offset is no longer proportional to atol")
        out["touch"] = linear_rule(lambda a: run(a).touch, "the touch distance (ContactRun.touch)")
        factor, floor = linear_rule(lambda v: run(float(s.atol), v).v_eps, "the speed threshold (ContactRun.v_eps)")
        if floor != 0.0:
            raise AssertionError("internal: ContactRun.v_eps is no longer proportional to rest_speed")
        out.update(v_eps=factor, rank_tol=float(module_constant("mechdsl.impacts.contact_system", "RANK_TOL")),
                   zeno_events=int(module_constant("mechdsl.simulation.backends.event_loop", "ZENO_EVENTS")),
                   zeno_span=float(module_constant("mechdsl.simulation.backends.event_loop", "ZENO_SPAN")))
    return out


def module_constant(module: str, name: str):
    """A module's constant ``NAME = <literal>``, read from its source when the module is not
    imported yet (the contact system and the event loop import scipy: 2.4 s of an export),
    else from the module."""
    import ast
    import importlib
    import importlib.util
    import sys

    if module not in sys.modules:
        spec = importlib.util.find_spec(module)
        try:
            tree = ast.parse(spec.loader.get_source(module))
        except (AttributeError, ImportError, OSError, SyntaxError):
            tree = None
        for node in (tree.body if tree is not None else ()):
            if isinstance(node, ast.Assign) and any(isinstance(t, ast.Name) and t.id == name for t in node.targets):
                try:
                    return ast.literal_eval(node.value)
                except ValueError:
                    break
    return getattr(importlib.import_module(module), name)


def contacts(eom):
    """(gaps, fixations) of the model's contacts (mechdsl.impacts.gaps)."""
    from ..impacts.gaps import contact_gaps

    return contact_gaps(eom)


def point_position(eom, point):
    """World position (SX (3,)) of a named point (a fixation's point)."""
    from ..impacts.gaps import point_position as pp

    return pp(eom, point)


def contact_defaults(settings) -> dict:
    """The contact options of a run with these settings (the settings group ``contacts``, with
    the tolerances the event loop derives from them, mechdsl.impacts.contact_run.ContactRun):
    rest_speed, impact order (0 simultaneous, 1 sequential), max_events, samples, acc_tol."""
    from ..impacts.contact_run import ContactRun

    o = ContactRun(settings.contacts, settings.rtol, settings.atol)
    return {"rest_speed": o.rest_speed, "impact_order": 1 if o.impact_order == "sequential" else 0,
            "max_events": o.max_events, "samples": o.samples, "acc_tol": o.acc_tol}


def start_depends_on_parameters(eom) -> np.ndarray:
    """(2n,) bool: which start values are expressions in the parameters (FMI initial="calculated")."""
    import casadi as ca

    q0 = ca.SX(eom.q0) if eom.q0 is not None else ca.SX.zeros(eom.n)
    qd0 = ca.SX(eom.qd0) if eom.qd0 is not None else ca.SX.zeros(eom.n)
    x0 = ca.vertcat(q0, qd0)
    return np.array([bool(ca.depends_on(x0[i], eom.p)) for i in range(2 * eom.n)], bool)
