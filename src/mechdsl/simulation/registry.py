"""The one method registry: every method name any run accepts, and which back ends take it.

Back ends (mechdsl.simulation.backends) keep their own tables of how a name runs (plugin,
options); this module is the only place that says which names exist, so an unknown name
is refused the same way for every model, with one did-you-mean list.
"""
from __future__ import annotations

from ..diagnostics import UsageError, did_you_mean
from ..model.records import record

ODE, DAE, EVENTS, FIXED = "ode", "dae", "events", "fixed-step"


@record
class MethodInfo:
    name: str
    backends: tuple[str, ...]     # back ends that accept the name
    description: str


# formulations of constrained models (mechdsl.dae.options.FORMULATIONS, checked by a test) and
# their aliases; 'ode' names the unconstrained problem
FORMULATIONS = ("projection", "ggl", "baumgarte", "partitioning", "augmented")
FORMULATION_NAMES = ("auto", "ode", "dae", "index1", *FORMULATIONS)


def check_formulation(name: str) -> str:
    if name not in FORMULATION_NAMES:
        hint = did_you_mean(name, FORMULATION_NAMES)
        raise UsageError(f"unknown formulation '{name}'" + (f"; {hint}" if hint else "")
                         + f" (formulations: {', '.join(n for n in FORMULATION_NAMES if n not in ('dae', 'index1'))})")
    return name


# fixed-step methods in canonical variables (mechdsl.symplectic; its METHODS are these names)
FIXED_METHODS = {"stormer-verlet": "Stormer-Verlet / leapfrog (symplectic, order 2; RATTLE with constraints)",
                 "implicit-midpoint": "implicit midpoint rule (symplectic, order 2)",
                 "gauss-legendre": "2-stage Gauss-Legendre collocation (symplectic, order 4)",
                 "rk4": "classical Runge-Kutta of order 4 with a fixed step dt (not symplectic)",
                 "rattle": "RATTLE, constrained Stormer-Verlet (symplectic on the constraint manifold)"}


def _table() -> dict[str, MethodInfo]:
    from .. import integrators as I
    from ..dae.options import DAE_METHODS, ODE_METHODS
    from ..impacts.stepper import ALIASES, SCIPY_METHODS

    out: dict[str, MethodInfo] = {"auto": MethodInfo("auto", (ODE, DAE, EVENTS), "chosen from the model")}
    for name, row in I.METHODS.items():
        kinds = (ODE,) + ((DAE,) if name in ODE_METHODS else ()) + ((EVENTS,) if name in ALIASES else ())
        out[name] = MethodInfo(name, kinds, row[3])
    for name in (*ODE_METHODS, *DAE_METHODS):
        if name not in out:
            out[name] = MethodInfo(name, (DAE,), "constrained models: " + ("IDAS (GGL formulation)" if name == "idas"
                                                                           else f"CVODES {name}"))
    for name, cls in SCIPY_METHODS.items():
        if name in out:
            out[name] = MethodInfo(name, out[name].backends + (EVENTS,), out[name].description)
        else:
            out[name] = MethodInfo(name, (EVENTS,), f"models with contacts: scipy {cls} with event location")
    for name, desc in FIXED_METHODS.items():
        out[name] = MethodInfo(name, (FIXED,), desc)
    return out


_CACHE: dict[str, MethodInfo] = {}


def methods() -> dict[str, MethodInfo]:
    """Every method name (imports the DAE and contact back ends' tables)."""
    if not _CACHE:
        _CACHE.update(_table())
    return _CACHE


def check_method(name: str) -> MethodInfo:
    """The registry entry of a method name; an unknown name is a UsageError with did-you-mean.

    Fixed-step and ODE names are answered without importing the DAE and contact back ends
    (cold start of ``mech simulate``)."""
    from .. import integrators as I

    if name in FIXED_METHODS:
        return MethodInfo(name, (FIXED,), FIXED_METHODS[name])
    if (name == "auto" or name in I.METHODS) and not _CACHE:
        return MethodInfo(name, (ODE, DAE, EVENTS), I.METHODS[name][3] if name in I.METHODS else "chosen from the model")
    table = methods()
    if name not in table:
        hint = did_you_mean(name, list(table))
        raise UsageError(f"unknown method '{name}'" + (f"; {hint}" if hint else "")
                         + f" (methods: {', '.join(table)})")
    return table[name]


def fixed_step_methods() -> tuple[str, ...]:
    return tuple(FIXED_METHODS)
