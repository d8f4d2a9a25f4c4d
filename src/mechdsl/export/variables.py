"""The variables of an exported FMU: names, value references, causality, start values, units.

Value references are contiguous ranges, in the order the C runtime expects
(mech_fmu.h, VR_*):

    parameters      p in the EOM's order: free ones tunable, dependent ones calculated
    states          the coordinates q, then their speeds der(q) (the derivative of q)
    der(der(q))     the accelerations (the derivatives of the speeds)
    inputs          the model's control inputs u
    outputs         the model's outputs
    mechdsl.*       co-simulation settings (Real), statistics (Real), settings (Integer)
    Integer parameters (structural: constants of the FMU)
    time            (FMI 3.0: the independent variable)
    event indicators (FMI 3.0 model exchange of contacts: one per contact, its gap or force)
"""
from __future__ import annotations

import math
from dataclasses import dataclass

from ..model.units import si_unit

REAL_SETTINGS = (
    ("mechdsl.rtol", "relative tolerance of the co-simulation stepper (the importer's tolerance replaces it, "
                     "atol then scales in proportion)", None),
    ("mechdsl.atol", "absolute tolerance of the co-simulation stepper", None),
    ("mechdsl.rest_speed", "contacts: an impact leaving a contact slower than this ends in persistent contact", "m/s"),
    ("mechdsl.drift_bound", "constraints: the drift of the constraints that triggers a projection is half of "
                            "this (0: max(10 atol, 1e-10), model exchange max(10 tolerance, 1e-10))", None),
    ("mechdsl.projection_interval", "co-simulation with constraints: the longest time between drift checks "
                                    "within a communication step (0: only at its end)", "s"),
)
STATISTICS = (
    ("mechdsl.steps", "accepted integrator steps (model exchange: completed integrator steps)"),
    ("mechdsl.rejected_steps", "rejected integrator steps (co-simulation)"),
    ("mechdsl.rhs_evaluations", "evaluations of the right-hand side"),
    ("mechdsl.events", "events: impacts, contacts closing and releasing, fixations (co-simulation)"),
    ("mechdsl.projections", "projections onto the constraints"),
)
INT_SETTINGS = (
    ("mechdsl.method", "co-simulation stepper: 1 dopri5 (Dormand-Prince 5(4)), 2 dop853 (Dormand-Prince 8(5,3))",
     1, 2),
    ("mechdsl.impact_order", "contacts touching at one instant: 0 simultaneous, 1 sequential (pairwise)", 0, 1),
    ("mechdsl.max_steps", "most integrator steps in one communication step", 1, None),
    ("mechdsl.max_events", "most events in a run (co-simulation)", 1, None),
)


@dataclass
class Variable:
    name: str
    vr: int
    type: str                    # "Real" | "Integer"
    causality: str
    variability: str
    initial: str | None = None
    start: float | int | None = None
    unit: str | None = None
    min: float | None = None
    max: float | None = None
    description: str = ""
    derivative_of: int | None = None     # vr of the state this variable is the derivative of
    kind: str = ""


def _per_second(unit: str | None, power: int) -> str | None:
    if unit is None or unit in ("", "1"):
        return "1/s" if power == 1 else "1/s2"
    return f"{unit}/s" if power == 1 else f"{unit}/s2"


def table(model, plan, settings, start_calculated, fmi_version: int, event_indicators: int = 0) -> list[Variable]:
    """Every variable of the FMU (see the module docstring).  ``settings``: defaults of the
    mechdsl.* settings ({name: value}); ``event_indicators``: how many (FMI 3.0 names them).
    Value references in the order of the blocks below; a setting a model does not use keeps its
    reference (reserved) without a variable."""
    out: list[Variable] = []
    vr = _parameters(model, out, 0)
    vr = _states(model, start_calculated, out, vr)
    vr = _inputs_outputs(model, out, vr)
    vr = _mechdsl_variables(model, plan, settings, out, vr)
    if fmi_version == 3:
        out.append(Variable("time", vr, "Real", "independent", "continuous", None, None, "s", None, None,
                            "simulation time", kind="time"))
        for g in plan.gaps[:event_indicators]:
            vr += 1
            out.append(Variable(f"mechdsl.event_indicator[{g.name}]", vr, "Real", "local", "continuous",
                                "calculated", None, None, None, None,
                                f"contact {g.name}: its gap while open (+ the event offset while it opens), its "
                                "normal force (+ the offset) while closed; an event where it crosses zero",
                                kind="event_indicator"))
    names = [v.name for v in out]
    clash = sorted({x for x in names if names.count(x) > 1})
    if clash:
        from ..diagnostics import Diagnostic, MechError

        raise MechError(Diagnostic("E891", f"cannot export '{model.name}': the name '{clash[0]}' is used twice "
                                   "among its variables and the FMU's own (mechdsl.*, time)",
                                   help="rename the model's declaration"))
    return out


def _parameters(model, out: list, vr: int) -> int:
    """The model's parameters: tunable (exact) or computed from others (calculatedParameter)."""
    from ..eom.codegen import free_parameters

    eom = model.eom
    by_name = {p.name: p for p in model.model.parameters}
    free = set(free_parameters(eom))
    for name, value in zip(eom.params, eom.param_values):
        p = by_name.get(name)
        doc, unit = (p.doc, si_unit(p.unit) or None) if p is not None else ("", None)
        lo, hi = (p.min, p.max) if p is not None else (None, None)
        if name in free:
            out.append(Variable(name, vr, "Real", "parameter", "tunable", "exact", float(value), unit, lo, hi, doc,
                                kind="parameter"))
        else:
            out.append(Variable(name, vr, "Real", "calculatedParameter", "tunable", "calculated", None, unit, lo, hi,
                                doc or "computed from other parameters", kind="parameter"))
        vr += 1
    return vr


def _states(model, start_calculated, out: list, vr: int) -> int:
    """The states q, der(q) (start exact, approx when made consistent, or calculated) and the
    accelerations der(der(q))."""
    eom = model.eom
    coords = {c.name: c for c in model.model.coordinates}
    n = eom.n
    fixed_q = list(eom.fixed_q) if len(eom.fixed_q) == n else [True] * n
    fixed_qd = list(eom.fixed_qd) if len(eom.fixed_qd) == n else [True] * n
    q0, qd0 = eom.start(eom.param_values)
    x_vr = vr
    for part, names in ((0, eom.coords), (1, [f"der({c})" for c in eom.coords])):
        for i, c in enumerate(eom.coords):
            info = coords.get(c)
            unit = (si_unit(info.unit) or None) if info is not None else None
            j = part * n + i
            fixed = (fixed_q if part == 0 else fixed_qd)[i]
            if start_calculated[j]:
                initial, start = "calculated", None
            else:
                initial, start = ("exact" if fixed else "approx"), float((q0 if part == 0 else qd0)[i])
            doc = (info.doc if info is not None else "") if part == 0 else f"speed of {c}"
            if not fixed:
                doc = (doc + "; " if doc else "") + "start value a guess, made consistent with the constraints"
            out.append(Variable(names[i], vr, "Real", "local", "continuous", initial, start,
                                unit if part == 0 else _per_second(unit, 1), None, None, doc,
                                derivative_of=None if part == 0 else x_vr + i, kind="state"))
            vr += 1
    for i, c in enumerate(eom.coords):
        info = coords.get(c)
        out.append(Variable(f"der(der({c}))", vr, "Real", "local", "continuous", "calculated", None,
                            _per_second((si_unit(info.unit) or None) if info is not None else None, 2), None, None,
                            f"acceleration of {c}", derivative_of=x_vr + n + i, kind="derivative"))
        vr += 1
    return vr


def _inputs_outputs(model, out: list, vr: int) -> int:
    for inp in model.inputs:
        out.append(Variable(inp.name, vr, "Real", "input", "continuous", None, float(inp.default), si_unit(inp.unit) or None,
                            inp.min, inp.max, inp.doc, kind="input"))
        vr += 1
    outs = {o.name: o for o in model.model.outputs}
    for name in model.eom.outputs:
        base = name.split("[")[0]
        o = outs.get(base)
        out.append(Variable(name, vr, "Real", "output", "continuous", "calculated", None,
                            (si_unit(o.unit) or None) if o is not None else None, None, None, o.doc if o is not None else "",
                            kind="output"))
        vr += 1
    return vr


def _mechdsl_variables(model, plan, settings, out: list, vr: int) -> int:
    """The mechdsl.* settings (those the model uses), the run's statistics, and the structural
    Integer parameters (constants of this FMU)."""
    used = _settings_used(plan)
    for name, doc, unit in REAL_SETTINGS:
        if name in used:
            out.append(Variable(name, vr, "Real", "parameter", "fixed", "exact", float(settings[name]), unit, 0.0,
                                None, doc, kind="setting"))
        vr += 1
    for name, doc in STATISTICS:
        out.append(Variable(name, vr, "Real", "local", "discrete", "calculated", None, None, None, None, doc,
                            kind="statistic"))
        vr += 1
    for name, doc, lo, hi in INT_SETTINGS:
        if name in used:
            out.append(Variable(name, vr, "Integer", "parameter", "fixed", "exact", int(settings[name]), None, lo, hi,
                                doc, kind="setting"))
        vr += 1
    for p in model.model.parameters:
        if p.integer and not p.input:
            out.append(Variable(p.name, vr, "Integer", "local", "constant", "exact", int(round(p.value)), None,
                                None, None, (p.doc + "; " if p.doc else "") + "structural: fixed in this FMU",
                                kind="constant"))
            vr += 1
    return vr


def _settings_used(plan) -> set[str]:
    """The mechdsl.* settings that mean something for this model (the others are left out of
    the modelDescription; their value references stay reserved)."""
    used = {"mechdsl.rtol", "mechdsl.atol", "mechdsl.method", "mechdsl.max_steps"}
    if plan.m or plan.k or plan.nfix:
        used |= {"mechdsl.drift_bound", "mechdsl.projection_interval"}
    if plan.k or plan.nfix:
        used |= {"mechdsl.rest_speed", "mechdsl.impact_order", "mechdsl.max_events"}
    return used


def unit_definition(unit: str) -> tuple[dict, float]:
    """FMI BaseUnit exponents (kg, m, s, A, K, mol, cd, rad) and factor of a unit, ({}, 1) when
    they cannot be stated (fractional exponents, an unknown unit)."""
    from ..model.units import parse_unit

    try:
        factor, dim = parse_unit(unit)
    except ValueError:
        return {}, 1.0
    names = ("m", "kg", "s", "A", "K", "mol", "cd")
    exps = {}
    for b, e in zip(names, dim.e):
        if e.denominator != 1:
            return {}, 1.0
        if e:
            exps[b] = int(e)
    num = unit.split("/")[0]
    if any(tok in ("rad", "deg") for tok in num.replace("*", ".").split(".")):
        exps["rad"] = 1
    if not math.isfinite(factor):
        return {}, 1.0
    return exps, float(factor)
