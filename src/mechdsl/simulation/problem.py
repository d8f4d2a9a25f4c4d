"""The problem: the named form between the equations of motion and the integrators.

``formulate(eom, settings) -> Problem`` decides once what kind of problem a run solves
(an ODE in minimal coordinates, a DAE with a formulation, a hybrid system with contacts,
or a fixed-step canonical integration) and which back end solves it; ``dump(problem)``
prints it deterministically (``mech compile --emit problem``).  ``inputs`` names the model's
control inputs and ``drive`` (drive.py) their signals: the ODE back end integrates the
closed loop; the other back ends get the equations with constant inputs folded into the
parameters, or with u replaced by the signals' expression U(t, x) (``Drive.close_eom``).
"""
from __future__ import annotations

from dataclasses import field

import casadi as ca

from ..eom import fold_inputs, parameter_vector
from ..eom.start import start_vector
from ..model.records import record
from .backends import backend
from .drive import build_drive
from .monitors import is_conservative
from .plan import plan, reaction_signals
from .registry import FIXED, check_method
from .settings import GROUPS, SimulationSettings


KINDS = {"ode": "ODE in minimal coordinates: M(q) q'' = bias(q, q', t, p)",
         "dae": "index-3 DAE with multipliers: M q'' + G' lambda = bias, g(q, t) = 0",
         "hybrid": "ODE with unilateral contacts: events and impact maps",
         "canonical": "fixed-step integration in canonical variables (q, p)"}


@record
class Problem:
    kind: str                              # one of KINDS
    backend: str                           # name in backends.BACKENDS
    model: str
    states: tuple[str, ...]                # q then der(q)
    parameters: tuple[tuple[str, float], ...]
    settings: SimulationSettings
    formulation: str | None = None         # DAE formulation as asked ('auto' resolved by the back end)
    inputs: tuple[str, ...] = ()           # control inputs u, in order
    input_signals: tuple[tuple[str, str], ...] = ()   # (name, what drives it)
    invariants: tuple[str, ...] = ()       # quantities that should stay constant (their drift is reported)
    constraints: tuple[str, ...] = ()
    contacts: tuple[str, ...] = ()         # events
    outputs: tuple[str, ...] = ()
    reactions: tuple[str, ...] = ()        # reaction/multiplier signals computed (empty: none are built)
    plan: tuple[tuple[str, str], ...] = ()  # (topic, what is computed and why): plan.py
    eom: object = field(default=None, repr=False, compare=False)
    drive: object = field(default=None, repr=False, compare=False)    # drive.Drive
    # fixed step with zero-order holds: the equations with the holds read at a trailing
    # parameter, the hold time, which each step sets to its midpoint (Drive.close_eom)
    step_eom: object = field(default=None, repr=False, compare=False)


def formulate(eom, settings: SimulationSettings) -> Problem:
    """Build the problem of a run (settings already validated)."""
    model = getattr(eom, "model", None)
    given = settings.contacts.contacts         # contact objects given to the run (a hand-built model)
    contacts = tuple(c.name for c in (given if given is not None else
                                      (model.contacts if model is not None else ()) or ()))
    constrained = eom.g is not None and getattr(eom, "m", 0) > 0
    info = check_method(settings.method)
    if contacts or settings.contacts.fixations:
        kind, backend = "hybrid", "events"
    elif FIXED in info.kinds:
        kind, backend = "canonical", "fixed-step"
    elif constrained:
        kind, backend = "dae", "dae"
    else:
        kind, backend = "ode", "ode"
    states = tuple(eom.coords) + tuple(f"der({c})" for c in eom.coords)
    pv = parameter_vector(eom, settings.p)
    params = tuple((n, float(v)) for n, v in zip(eom.params, pv))
    drive, run_eom, step_eom = None, eom, None
    if eom.inputs:
        drive = build_drive(eom, settings.inputs, settings.t_start, settings.t_end, start_vector(eom, settings.x0, pv))
        if kind != "ode":      # constant inputs: trailing parameters; signals: u = U(t, x) in the equations
            run_eom = fold_inputs(eom, drive.vector()) if drive.constant else drive.close_eom(eom)
            if backend == "fixed-step" and drive.holds and not constrained:
                step_eom = drive.close_eom(eom, hold_time=True)
    elif settings.inputs:
        build_drive(eom, settings.inputs, settings.t_start, settings.t_end)     # reports the unknown name
    outputs = settings.outputs if settings.outputs is not None else tuple(getattr(eom, "outputs", {}) or ())

    invariants = invariant_names(eom)
    return Problem(kind=kind, backend=backend, model=eom.name, states=states, parameters=params,
                   settings=settings, formulation=settings.dae.formulation if kind == "dae" else None,
                   invariants=invariants,
                   constraints=tuple(eom.constraint_names) if constrained else (), contacts=contacts,
                   outputs=tuple(outputs), reactions=reaction_signals(eom, settings, kind),
                   plan=plan(eom, settings, kind, contacts, tuple(outputs), invariants), eom=run_eom, drive=drive, step_eom=step_eom,
                   inputs=tuple(eom.inputs),
                   input_signals=tuple(drive.describe().items()) if drive is not None else ())


def invariant_names(eom) -> tuple[str, ...]:
    """The energy when the model conserves it, and the model's declared invariants."""
    names = []
    if conserves_energy(eom):
        names.append("energy")
    names += list((getattr(eom, "invariants", None) or {}))
    return tuple(names)


def conserves_energy(eom) -> bool:
    if getattr(getattr(eom, "model", None), "contacts", None):
        return False
    if not is_conservative(eom):
        return False
    if eom.g is not None and ca.depends_on(ca.SX(eom.g), eom.t):   # moving constraints do work
        return False
    return True


def dump(problem: Problem) -> str:
    """Deterministic text of a problem (``mech compile --emit problem``)."""
    s = problem.settings
    lines = [f"problem {problem.model}", f"  kind: {problem.kind} ({KINDS[problem.kind]})",
             f"  backend: {problem.backend}"]
    if problem.formulation is not None:
        lines.append(f"  formulation: {problem.formulation}")
    lines.append(f"  states ({len(problem.states)}): " + ", ".join(problem.states))
    lines.append(f"  parameters ({len(problem.parameters)}): "
                 + ", ".join(f"{n} = {v!r}" for n, v in problem.parameters))
    sig = dict(problem.input_signals)
    lines.append("  inputs: " + (", ".join(f"{n} ({sig[n]})" if n in sig else n for n in problem.inputs) or "none"))
    lines.append("  invariants: " + (", ".join(problem.invariants) or "none"))
    lines.append("  constraints: " + (", ".join(problem.constraints) or "none"))
    lines.append("  contacts: " + (", ".join(problem.contacts) or "none"))
    lines.append("  outputs: " + (", ".join(problem.outputs) or "none"))
    lines.append("  reactions: " + (", ".join(problem.reactions) or "none"))
    lines.append("  computed, and why:")
    lines += [f"    {topic}: {text}" for topic, text in problem.plan]
    lines.append("  settings:")
    own = backend(problem.backend).groups
    for k, v in s.as_dict().items():
        if k in GROUPS:             # the back end's own groups in full, the others where they differ
            default = GROUPS[k]()
            for name, x in v.items():
                if x not in (None, (), []) and (k in own or getattr(getattr(s, k), name) != getattr(default, name)):
                    lines.append(f"    {k}.{name} = {x!r}")
            continue
        if k == "compiled" and v is None:
            v = "auto"      # the ODE back end compiles when it pays
        if v is None or v == {}:
            continue
        lines.append(f"    {k} = {v!r}")
    return "\n".join(lines) + "\n"
