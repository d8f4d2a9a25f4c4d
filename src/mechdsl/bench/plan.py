"""The default plan of ``mech bench``: what to run when the user names no methods, no
tolerances or no end time, proportionate to the model (docs/internals/bench.md, "Default plan").

One pilot run (the simulator's own method choice at rtol = atol = 1e-6 over the scene's
horizon, stopped after PILOT_CAP CPU seconds) measures how costly the model is:

    cost (CPU s of the pilot)   horizon                         tolerances      repeats
    <= CHEAP                    the scene's                     1e-2 .. 1e-10   3 (or --repeats)
    <= RUN_TARGET               the scene's                     1e-3 .. 1e-9    1
    more                        shortened to cost RUN_TARGET    1e-3 .. 1e-8    1

and every plan gets a CPU budget for the whole sweep (SWEEP_BUDGET; a run over RUN_BUDGET
ends its method's sweep).  What was chosen and why is kept in ``notes`` and printed.
Whatever the user gave on the command line is kept as given.
"""
from __future__ import annotations

import math
import warnings
from dataclasses import dataclass, field

PILOT_TOL = 1e-6
PILOT_CAP = 2.0          # CPU seconds: the pilot stops here (where the simulator reports progress)
CHEAP = 0.1              # CPU seconds of the pilot below which the full default sweep is affordable
RUN_TARGET = 1.0         # CPU seconds of one run at PILOT_TOL that a default horizon aims at
RUN_BUDGET = 5.0         # CPU seconds: one run longer than this ends its method's sweep
SWEEP_BUDGET = 25.0      # CPU seconds for all runs of the default plan's sweep
STOP_AFTER = 2 * RUN_BUDGET     # CPU seconds after which a run of the default plan is stopped
SLOW_FORMULATIONS = ("partitioning",)   # left out of the default methods unless the model is cheap
TOLERANCES = {"cheap": "1e-2..1e-10/1", "moderate": "1e-3..1e-9/1", "costly": "1e-3..1e-8/1"}


@dataclass(kw_only=True)
class Plan:
    t_end: float
    tolerances: str | None = None       # a sweep specification (spec.parse_tolerances), None: the user's
    repeats: int | None = None          # None: the user's
    budget: float | None = None         # per run; None: the user's
    sweep_budget: float | None = None   # all runs; None: unlimited
    notes: list[str] = field(default_factory=list)
    pilot_cpu: float | None = None
    level: str | None = None            # cheap | moderate | costly (None: no pilot)
    stop_after: float | None = None     # CPU seconds after which one run is stopped (where it reports progress)


def pilot(setup, cap: float = PILOT_CAP) -> tuple[float, float, object]:
    """(CPU seconds, simulated time reached, Result or None) of one run of the simulator's
    default method at PILOT_TOL; stopped after ``cap`` CPU seconds where the simulator
    reports progress (between output points).  The cost of a stopped run is extrapolated
    from the part after the first report, which leaves out building the functions."""
    from ..simulate import simulate
    from .timing import OverBudget, cpu_call, cpu_cap

    marks: list[tuple[float, float]] = []
    kw = {}
    if setup.constrained and setup.default_formulation:
        kw["formulation"] = setup.default_formulation
    if setup.compiled:
        kw["compiled"] = True

    def run():
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            try:
                return simulate(setup.eom, setup.t_end, t_start=setup.t_start, rtol=PILOT_TOL, atol=PILOT_TOL,
                                points=setup.points, x0=setup.x0, p=setup.p, progress=cpu_cap(cap, marks),
                                error_estimate="off", warn=False, **kw)
            except OverBudget:
                return None

    cpu, result = cpu_call(run)
    if result is not None and getattr(result, "success", False):
        return cpu, setup.t_end, result
    reached = marks[-1][1] if marks else setup.t_start
    if result is not None and len(result.t):
        reached = max(reached, float(result.t[-1]))
    if len(marks) >= 2 and marks[-1][1] > marks[0][1]:
        (c1, t1), (c2, t2) = marks[0], marks[-1]
        cpu = c1 + (c2 - c1) / (t2 - t1) * (setup.t_end - t1)
    elif reached > setup.t_start:
        cpu = cpu * (setup.t_end - setup.t_start) / (reached - setup.t_start)
    else:
        cpu = math.inf
    return cpu, reached, result


def nice_below(x: float) -> float:
    """The largest of 1, 2, 5 x 10^k not above x."""
    k = math.floor(math.log10(x))
    for m in (5, 2, 1):
        if m * 10.0 ** k <= x * (1 + 1e-12):
            return float(f"{m * 10.0 ** k:.12g}")
    return float(f"{10.0 ** k:.12g}")


def default_plan(setup, *, t_end_given: bool, tolerances_given: bool, repeats_given: bool,
                 budget_given: bool, log=None) -> Plan:
    """The plan for ``setup`` (whose t_end is the scene's stop time, else 10 s, unless given)."""
    plan = Plan(t_end=setup.t_end)
    if t_end_given and tolerances_given:
        return plan
    if log:
        log(f"plan: pilot run of the default method at tolerance {PILOT_TOL:g} to t = {setup.t_end:g}")
    cost, reached, result = pilot(setup)
    plan.pilot_cpu = cost
    span = setup.t_end - setup.t_start
    failed = result is not None and not result.success
    if failed:
        f = result.failure
        plan.notes.append(f"the pilot run (default method at tolerance {PILOT_TOL:g}) failed at t = {f.time:.6g}: "
                          f"{f.cause}")
    level = "cheap" if cost <= CHEAP else "moderate" if cost <= RUN_TARGET else "costly"
    plan.level = level
    if not t_end_given:
        by_cost = nice_below(span * RUN_TARGET / cost) if level == "costly" else span
        by_failure = nice_below(0.5 * (reached - setup.t_start)) if failed and reached > setup.t_start else span
        new_span = min(by_cost, by_failure, span)
        if new_span < span:
            new_span = _keep_events(setup, result, new_span, span, by_failure)
        if new_span < span:
            plan.t_end = setup.t_start + new_span
            why = (f"one run at tolerance {PILOT_TOL:g} over the whole horizon costs about {cost:.3g} s of CPU"
                   if by_cost <= by_failure else "it ends well before the pilot's failure")
            plan.notes.append(f"horizon shortened to t = {plan.t_end:g} (from {setup.t_end:g}): {why}; "
                              "give --t-end for another")
    _event_note(plan, setup, result)
    what = {"cheap": f"cheap (a run at {PILOT_TOL:g} costs {cost:.2g} s of CPU)",
            "moderate": f"moderately costly (a run at {PILOT_TOL:g} costs {cost:.2g} s of CPU)",
            "costly": f"costly (a run at {PILOT_TOL:g} over the scene's horizon costs {cost:.3g} s of CPU)"}[level]
    chosen = []
    if not tolerances_given:
        plan.tolerances = TOLERANCES[level]
        chosen.append(f"tolerances {plan.tolerances.replace('/1', '')} (one a decade)")
    if not repeats_given and level != "cheap":
        plan.repeats = 1
        chosen.append("1 timed run after the warm-up")
    if not budget_given:
        plan.budget = RUN_BUDGET
        plan.sweep_budget = SWEEP_BUDGET
        plan.stop_after = STOP_AFTER
        chosen.append(f"{RUN_BUDGET:g} s of CPU a run (stopped after {STOP_AFTER:g} s where it reports progress) "
                      f"and {SWEEP_BUDGET:g} s for the sweep")
    if chosen:
        plan.notes.append(f"default plan for a model that is {what}: " + ", ".join(chosen)
                          + "; give --tolerances, --repeats or --budget for others")
    return plan


def _event_times(result) -> list[float] | None:
    ev = getattr(result, "events", None) if result is not None else None
    return None if ev is None else sorted(float(e["time"]) for e in ev)


def _keep_events(setup, result, new_span: float, span: float, by_failure: float) -> float:
    """A shortened horizon of a contact scene reaches past its first event (a benchmark of free
    flight alone said nothing of the scene: the falling rod's was cut to 0.2 s, before the first
    impact), unless the pilot failed before it."""
    times = _event_times(result)
    if not times:
        return new_span
    first = times[0] - setup.t_start
    if new_span > first:
        return new_span
    want = nice_above(1.2 * first) if first > 0 else new_span
    return min(span, by_failure if by_failure < span else span, max(new_span, want))


def nice_above(x: float) -> float:
    """The smallest of 1, 2, 5 x 10^k not below x."""
    k = math.floor(math.log10(x))
    for m in (1, 2, 5, 10):
        if m * 10.0 ** k >= x * (1 - 1e-12):
            return float(f"{m * 10.0 ** k:.12g}")
    return float(f"{10.0 ** (k + 1):.12g}")


def _event_note(plan: Plan, setup, result) -> None:
    """Say how many of the scene's events (the pilot run's) the benchmark's horizon holds."""
    times = _event_times(result)
    if times is None:
        if result is None and getattr(getattr(setup, "eom", None), "model", None) is not None \
                and getattr(setup.eom.model, "contacts", None):
            plan.notes.append("the pilot run stopped early: how many events the horizon holds is not known")
        return
    inside = [t for t in times if t <= plan.t_end]
    if not times:
        plan.notes.append("the pilot run had no events (no contact closed, no impact) up to t = "
                          f"{plan.t_end:g}: the benchmark measures free flight only")
    elif len(inside) < len(times):
        plan.notes.append(f"the horizon holds {len(inside)} of the pilot run's {len(times)} events "
                          f"(first at t = {times[0]:.6g}, last at t = {times[-1]:.6g}); give --t-end for all")
    else:
        plan.notes.append(f"the horizon holds all {len(times)} events of the pilot run (t = {times[0]:.6g} .. "
                          f"{times[-1]:.6g})")


def plan_methods(plan: Plan, labels: list[str]) -> list[str]:
    """The default methods for this plan: a formulation that can grind for a minute in one
    run (partitioning: 65 s and a failure at 1e-3 on the slider-crank) is left out unless
    the model is cheap; a note says so."""
    if plan.level in (None, "cheap"):
        return labels
    keep = [lab for lab in labels if lab.split("+")[0] not in SLOW_FORMULATIONS]
    left = [lab for lab in labels if lab not in keep]
    if left and keep:
        plan.notes.append(f"left out {', '.join(left)}: one of its runs can take a minute on a model that is not "
                          f"cheap (a run is not interrupted inside the integrator); give --methods {left[0]} "
                          "to include it")
        return keep
    return labels
