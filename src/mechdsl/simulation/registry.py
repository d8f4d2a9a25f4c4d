"""The one method registry: a ``MethodSpec`` record per method name any run accepts.

Each record says what the method is (family, plug-in, options, order, description) and what
it can do (needs the Jacobian, forward derivatives only, fixed step, compiled loop,
symplectic, constrained), which back ends take it (``kinds``), and how the back ends that
run it under another name do so (``dae``: the method of the DAE formulations' integrator;
``events``: the scipy one-step class of the contact back end).  Back ends and checks read
these attributes; no other module keeps a list of method names.  An unknown name is
refused the same way for every model, with one did-you-mean list.

How to add a method: docs/internals/simulation.md ("How to add an integrator").
"""
from __future__ import annotations

from dataclasses import field

from ..diagnostics import UsageError, did_you_mean
from ..model.records import record


ODE, DAE, EVENTS, FIXED = "ode", "dae", "events", "fixed-step"
ODE_FAMILIES = ("casadi", "crk", "scipy")     # the families the ODE back end's plug-ins run


@record
class MethodSpec:
    name: str
    family: str                      # casadi | crk | scipy | canonical | dae | events | auto
    plugin: str                      # CasADi plug-in, scipy class, compiled loop or scheme name
    description: str
    kinds: tuple[str, ...]           # back ends that accept the name
    options: dict = field(default_factory=dict)   # the plug-in's options
    order: int | None = None         # fixed-step methods: order used to pick a step from rtol
    needs_jacobian: bool = True      # evaluates the Jacobian of the right-hand side
    forward_only: bool = False       # differentiates the right-hand side, never forms its Jacobian
    fixed_step: bool = False
    compiled_loop: bool = False      # the compiled stepping loop (backends/crk): it compiles the model itself
    symplectic: bool = False
    constrained: bool = False        # fixed-step: runs constrained models (RATTLE)
    dae: str | None = None           # as a method of the DAE formulations: auto | bdf | adams | erk | idas
    events: str | None = None        # the scipy one-step class the contact back end steps it as


def _m(name, family, plugin, description, kinds, **kw) -> MethodSpec:
    return MethodSpec(name, family, plugin, description, kinds, **kw)


_OE, _ODE_EV = (ODE, EVENTS), (ODE, DAE, EVENTS)
SPECS: tuple[MethodSpec, ...] = (
    _m("auto", "auto", "auto", "chosen from the model", (ODE, DAE, EVENTS), dae="auto", events="DOP853"),
    _m("cvodes-bdf", "casadi", "cvodes", "CVODES variable-order BDF (stiff), Newton with a dense Jacobian", _ODE_EV,
       options={"linear_multistep_method": "bdf"}, dae="bdf", events="BDF"),
    _m("cvodes-adams", "casadi", "cvodes",
       "CVODES variable-order Adams-Moulton (non-stiff, up to order 12), functional iteration", _ODE_EV,
       options={"linear_multistep_method": "adams", "nonlinear_solver_iteration": "functional"},
       needs_jacobian=True, forward_only=True, dae="adams", events="DOP853"),
    _m("cvodes", "casadi", "cvodes", "alias of cvodes-bdf", _ODE_EV,
       options={"linear_multistep_method": "bdf"}, dae="bdf", events="BDF"),
    _m("idas", "casadi", "idas", "IDAS variable-order BDF on the ODE as an implicit DAE", _OE,
       dae="idas", events="BDF"),
    _m("erk", "casadi", "erk", "adaptive explicit Runge-Kutta 5(4) (Dormand-Prince type)", _ODE_EV,
       needs_jacobian=False, dae="erk", events="DOP853"),
    _m("rosenbrock", "casadi", "rosenbrock", "adaptive L-stable Rosenbrock-Wanner method of order 5(4)", _OE,
       events="Radau"),
    _m("rk", "casadi", "rk", "fixed-step classical Runge-Kutta of order 4", _OE,
       order=4, needs_jacobian=False, fixed_step=True, events="DOP853"),
    _m("collocation", "casadi", "collocation", "fixed-step Radau IIA collocation (order 5)", _OE,
       order=5, fixed_step=True, events="Radau"),
    _m("dopri5", "crk", "dopri5", "Dormand-Prince 5(4), compiled stepping loop (C, one call per run)", _OE,
       needs_jacobian=False, compiled_loop=True, events="RK45"),
    _m("dop853", "crk", "dop853", "Dormand-Prince 8(5,3), compiled stepping loop (C, one call per run)", _OE,
       needs_jacobian=False, compiled_loop=True, events="DOP853"),
    _m("scipy-rk45", "scipy", "RK45", "scipy RK45 (Dormand-Prince 5(4))", _OE, needs_jacobian=False, events="RK45"),
    _m("scipy-dop853", "scipy", "DOP853", "scipy DOP853 (Dormand-Prince 8(5,3))", _OE, needs_jacobian=False,
       events="DOP853"),
    _m("scipy-radau", "scipy", "Radau", "scipy Radau IIA order 5 (stiff)", _OE, events="Radau"),
    _m("scipy-bdf", "scipy", "BDF", "scipy variable-order BDF (stiff)", _OE, events="BDF"),
    _m("scipy-lsoda", "scipy", "LSODA", "scipy LSODA (automatic Adams/BDF switching)", _OE, events="LSODA"),
    _m("bdf", "dae", "cvodes", "constrained models: CVODES bdf; models with contacts: scipy BDF with event location",
       (DAE, EVENTS), dae="bdf", events="BDF"),
    _m("adams", "dae", "cvodes", "constrained models: CVODES adams", (DAE,), dae="adams"),
    _m("rk45", "events", "RK45", "models with contacts: scipy RK45 with event location", (EVENTS,), events="RK45"),
    _m("rk23", "events", "RK23", "models with contacts: scipy RK23 with event location", (EVENTS,), events="RK23"),
    _m("radau", "events", "Radau", "models with contacts: scipy Radau with event location", (EVENTS,),
       events="Radau"),
    _m("lsoda", "events", "LSODA", "models with contacts: scipy LSODA with event location", (EVENTS,),
       events="LSODA"),
    _m("stormer-verlet", "canonical", "stormer-verlet",
       "Stormer-Verlet / leapfrog (symplectic, order 2; RATTLE with constraints)", (FIXED,),
       order=2, fixed_step=True, symplectic=True, constrained=True),
    _m("implicit-midpoint", "canonical", "implicit-midpoint", "implicit midpoint rule (symplectic, order 2)", (FIXED,),
       order=2, fixed_step=True, symplectic=True),
    _m("gauss-legendre", "canonical", "gauss-legendre", "2-stage Gauss-Legendre collocation (symplectic, order 4)",
       (FIXED,), order=4, fixed_step=True, symplectic=True),
    _m("rk4", "canonical", "rk4", "classical Runge-Kutta of order 4 with a fixed step dt (not symplectic)", (FIXED,),
       order=4, fixed_step=True),
    _m("rattle", "canonical", "rattle",
       "RATTLE, constrained Stormer-Verlet (symplectic on the constraint manifold)", (FIXED,),
       order=2, fixed_step=True, symplectic=True, constrained=True),
)
METHODS: dict[str, MethodSpec] = {m.name: m for m in SPECS}

# formulations of constrained models (mechdsl.dae.dae_run.FORMULATIONS, checked by a test) and
# their aliases; 'ode' names the unconstrained problem
FORMULATIONS = ("projection", "ggl", "baumgarte", "partitioning", "augmented")
FORMULATION_NAMES = ("auto", "ode", "dae", "index1", *FORMULATIONS)


def check_formulation(name: str) -> str:
    if name not in FORMULATION_NAMES:
        hint = did_you_mean(name, FORMULATION_NAMES)
        raise UsageError(f"unknown formulation '{name}'" + (f"; {hint}" if hint else "")
                         + f" (formulations: {', '.join(n for n in FORMULATION_NAMES if n not in ('dae', 'index1'))})")
    return name


def methods() -> dict[str, MethodSpec]:
    """Every method name, in the registry's order."""
    return METHODS


def check_method(name: str) -> MethodSpec:
    """The registry entry of a method name; an unknown name is a UsageError with did-you-mean."""
    spec = METHODS.get(name)
    if spec is None:
        hint = did_you_mean(name, list(METHODS))
        raise UsageError(f"unknown method '{name}'" + (f"; {hint}" if hint else "")
                         + f" (methods: {', '.join(METHODS)})")
    return spec


def spec(name: str) -> MethodSpec:
    """The record of a known method name (KeyError for another)."""
    return METHODS[name]


def ode_methods() -> tuple[str, ...]:
    """The methods the ODE back end's plug-ins run (besides auto)."""
    return tuple(m.name for m in SPECS if m.family in ODE_FAMILIES)


def fixed_step_methods() -> tuple[str, ...]:
    """The fixed-step methods in canonical variables (the fixed-step back end)."""
    return tuple(m.name for m in SPECS if m.family == "canonical")


def dae_method(name: str, formulation: str) -> str:
    """The integrator method a constrained run of ``formulation`` uses for the name (auto stays
    auto for the ODE formulations: the back end resolves it); a name that does not apply is a
    UsageError listing those that do."""
    if formulation == "ggl":
        allowed = {m.name: "idas" for m in SPECS if m.dae in ("auto", "idas")}
    else:
        allowed = {m.name: m.dae for m in SPECS if m.dae is not None and m.dae != "idas"}
    if name not in allowed:
        raise UsageError(f"method {name!r} does not apply to formulation {formulation!r} of a constrained model; "
                         f"choose one of: {', '.join(allowed)}")
    return allowed[name]


def events_method(name: str | None) -> tuple[str, str]:
    """(scipy class name, note) the contact back end steps a method name as; notes say when a
    name was mapped.  A fixed-step name or an unknown one is a UsageError."""
    name = (name or "auto").lower()
    m = METHODS.get(name)
    if m is not None and m.events is not None:
        target = m.events.lower()          # the contact back end's own name of the class
        note = ""
        if name not in ("auto", target) and not name.startswith("scipy-"):
            note = (f"method '{name}' is stepped as '{target}' for event location "
                    "(models with contacts run scipy's one-step methods; dop853 and rk45 compiled between events)")
        return m.events, note
    if m is not None and m.family == "canonical" and m.name != "rk4" and m.name != "rattle":
        raise UsageError(f"the symplectic method '{name}' cannot step over impacts; "
                         "use a method with error control (e.g. auto, dop853, radau)")
    raise UsageError(f"unknown method '{name}' for a model with contacts; methods: "
                     + ", ".join(x.name for x in SPECS if x.events is not None))
