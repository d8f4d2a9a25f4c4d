"""The error estimate every run carries by default (issue 23): ``metadata["accuracy"]["error_estimate"]``.

A companion run of the same problem, method and formulation at a tolerance ``TIGHTER`` = 10
times tighter (a fixed-step run: half the step), recorded only on a coarse subset of the
output times (at most ``COARSE`` points), compiled or not as the run ran.  With the global error
proportional to the tolerance, e(tol/10) = e(tol)/10, so the difference of the two runs is
0.9 e(tol): the estimate is the largest difference over the coarse times, divided by
1 - 1/TIGHTER (fixed steps: 1 - 2^-order, Richardson).  Why this one and not another:
docs/internals/simulation.md ("The default error estimate"); its calibration on long,
chaotic and constrained runs: benchmarks/error_estimate.py, docs/performance.md.

    estimate(r, problem, solve) -> dict    fills r.metadata["accuracy"]: error_estimate (the
                                           largest over the recorded coordinates, in their
                                           units), where (coordinate, time), the ratio to the
                                           tolerance class, per coordinate when asked
    tolerance_class(r, rtol, atol)         rtol |q|max + atol per coordinate

The tolerance class of a coordinate is rtol times its largest magnitude over the run plus
atol: what the tolerances ask of it.  A run whose estimate exceeds ``WARN_FACTOR`` times its
tolerance class warns (the accuracy warning: once, with the invariant drift,
accuracy.accuracy_warning).
"""
from __future__ import annotations

import dataclasses
import time

import numpy as np

from ..numbers import si_unit
from .difference import compare, fill     # (the comparison, without CasADi: a warm prepared run shares it)
from .accuracy import WARN_FACTOR  # noqa: F401  (the warning's threshold, with the rule of the drift)
from .backends import backend
from .backends.crk import COMPANION_INTERRUPTED, loaded_runtime
from .backends.ode import kept_setup, partner
from .prepared import prepare
from .problem import formulate
from .registry import spec
from .settings import DEFAULT_POINTS, MIN_RTOL

TIGHTER = 10.0       # the companion's tolerance is this many times tighter
COARSE = 201         # the companion records at most this many of the run's output times
MODES = ("on", "off", "coordinates")


def tolerance_class(q: np.ndarray, rtol: float, atol: float) -> np.ndarray:
    """rtol * max_t |q_i| + atol per coordinate (what the tolerances ask of each)."""
    if q.size == 0:
        return np.zeros(q.shape[1] if q.ndim == 2 else 0)
    return rtol * np.nanmax(np.abs(q), axis=0) + atol


def coarse_points(n: int) -> tuple[int, int]:
    """(points of the companion, stride in the run's output times): a uniform subset of the n
    output times with at most COARSE points (n - 1 divisible by the stride), or all of them."""
    if n <= COARSE:
        return n, 1
    for stride in range(int(np.ceil((n - 1) / (COARSE - 1))), n):
        if (n - 1) % stride == 0 and (n - 1) // stride + 1 >= 11:
            return (n - 1) // stride + 1, stride
    return n, 1


def companion(problem, r):
    """(settings of the companion run, factor the difference is divided by, what it is) or
    (None, None, why not)."""
    s = problem.settings
    fixed = problem.kind == "canonical"          # the fixed-step back end
    n = len(r.t)
    base = dict(error_estimate="off", estimate_error=False, warn=False)
    if fixed:
        dt = float((r.stats or {}).get("dt") or s.fixed_step.step(s.t_end - s.t_start))
        order = spec(s.method).order or 1
        steps = int(round((s.t_end - s.t_start) / dt))
        tight = s.replace(**base, dt=dt / 2, points=n if n >= 2 else None,
                          budget=max(s.budget, 4 * steps + 4))
        return tight, 1.0 - 2.0 ** -order, f"a run with half the step (dt = {dt / 2:.3g}; order {order})"
    k = TIGHTER
    rtol = s.rtol / k
    if rtol < MIN_RTOL:
        k = s.rtol / MIN_RTOL
        rtol = MIN_RTOL
        if k < 2:
            return None, None, (f"rtol = {s.rtol:g}: a companion run tighter than it would be below "
                                f"{MIN_RTOL:g}, which double precision cannot deliver")
    points, _ = coarse_points(n) if problem.kind == "ode" else (n, 1)
    method = s.method
    ran = r.metadata.get("run") or {}
    if problem.kind == "ode" and s.method == "auto" and ran.get("method"):
        method = ran["method"]             # auto chooses by tolerance: keep the method that ran
    elif problem.kind == "ode" and spec(s.method).family == "scipy":
        # a method stepped in Python: its companion at rtol/10 can cost 100x the run (scipy's Radau
        # at 1e-12 on a stiff pendulum: 40 s against 0.4 s).  The companion need not be the same
        # method, only 10x more accurate: the default path at the tighter tolerance is
        method = "auto"
    # the outputs of the run (their recorder is built already and kept); compiled as the run ran.
    # A run in the stepping loop with compiled unset keeps it unset: the companion's engine then
    # follows the same rules (crk.engine_for, payback.py; the same bits).  compiled = false would
    # step an interpreted model in Python at 2-3x the run's cost per evaluation, and compiled =
    # true would build a second library for a large model the pay-back rule switched to compiled
    # code (a third gcc call of the 200-link chain's runs) (issue 24)
    in_loop = r.metadata.get("loop_engine") is not None
    compiled = None if in_loop and s.compiled is None else bool(ran.get("compiled"))
    if problem.kind == "hybrid":
        compiled = s.compiled            # free flight in the compiled loop as the run stepped it
    extra = dict(base, rtol=rtol, atol=s.atol / k, method=method, compiled=compiled)
    if problem.kind == "ode":
        extra["points"] = points
    if problem.drive is not None and problem.kind != "ode":
        extra["inputs"] = None              # problem.eom has the inputs built in
    return s.replace(**extra), 1.0 - 1.0 / k, (f"a run at rtol = {rtol:.3g}, atol = {s.atol / k:.3g} ({k:g}x tighter"
                                         + (f", method {method})" if method != s.method and s.method != "auto" else ")"))


def estimate(r, problem, solve, given=None, run_setup=None) -> None:
    """Run the companion and fill r.metadata["accuracy"] (the run must have succeeded).  ``given``:
    (a run already made at a tighter tolerance, its factor, what it is) to use instead.
    ``run_setup``: the run's OdeSetup when known (a prepared problem): the companion is then
    registered on it, to run in the same C call as its next runs (backends/ode.Partner)."""
    acc = r.metadata.setdefault("accuracy", {})
    s = problem.settings
    if given is not None:
        other, factor, how = given
        acc["error_estimate_method"] = how
    else:
        tight, factor, how = _kept_companion(problem, r)
        acc["error_estimate_method"] = how
        if tight is None:
            acc.update(error_estimate=None, error_estimate_unavailable=how)
            return
        if problem.kind == "hybrid":
            _follow(r, problem, tight, factor)
            return
        cpu0 = time.process_time()
        r.stats["error_estimate_cpu_time"] = None
        try:
            other = _companion_run(problem, tight, solve, run_setup)
        except Exception as e:  # noqa: BLE001 - the run itself is fine; say why there is no estimate
            why = str(e).strip().splitlines()[0] if str(e).strip() else type(e).__name__
            acc.update(error_estimate=None, error_estimate_unavailable=f"the companion run could not run: {why}")
            return
        finally:
            r.stats["error_estimate_cpu_time"] = time.process_time() - cpu0      # besides the run's own cpu_time
        # the companion's work, besides the run's own steps and rhs_evals (benchmarks count both)
        # a companion run in the run's own C call (backends/ode.Partner) says its seconds there
        r.stats["error_estimate_cpu_time"] += (other.stats or {}).get("cpu_time") or 0.0
        r.stats["error_estimate_steps"] = (other.stats or {}).get("steps")
        r.stats["error_estimate_rhs_evals"] = (other.stats or {}).get("rhs_evals")
    compare(r, other, factor, s, lambda c: _unit(problem.eom, c), rt=loaded_runtime())


def _follow(r, problem, tight, factor) -> None:
    """A contact run's estimate: the companion follows the run's own impacts
    (backends/event_companion.py), whatever their number."""
    acc = r.metadata["accuracy"]
    cpu0 = time.process_time()
    r.stats["error_estimate_cpu_time"] = None
    try:
        f = backend(problem.backend).follow(problem, tight, r, coarse_points(tight.points or DEFAULT_POINTS)[1])
    finally:
        r.stats["error_estimate_cpu_time"] = time.process_time() - cpu0
    r.stats.update(error_estimate_steps=f.steps, error_estimate_rhs_evals=f.rhs_evals,
                   error_estimate_segments=f.segments)
    acc["error_estimate_method"] = (f"the run's {f.segments} segment{'s' if f.segments != 1 else ''} between its "
                                    f"events again at rtol = {tight.rtol:.3g}, atol = {tight.atol:.3g} "
                                    f"({1 / (1 - factor):.3g}x tighter), each from the run's state after its events")
    if not f.t:
        acc.update(error_estimate=None, error_estimate_unavailable=f.note or "the companion recorded no time")
        return
    fill(r, np.vstack(f.err), np.concatenate(f.t), factor, problem.settings, lambda c: _unit(problem.eom, c))
    acc["error_estimate_event_time"] = f.dt_event / factor      # s: the largest difference of an event's time
    if f.note:
        acc["error_estimate_note"] = f.note


class _Plan:
    """A kept companion plan: for the settings object ``settings`` and the run's ``key`` (output
    times, method, engine, equations), ``companion(...)``'s answer and, once the companion ran,
    its OdeSetup, the environment it was built in and its start values."""

    __slots__ = ("settings", "key", "plan", "eom", "setup", "env", "start")

    def __init__(self, settings, key, plan, eom):
        self.settings, self.key, self.plan, self.eom = settings, key, plan, eom
        self.setup = self.env = self.start = None


_PLANS: dict = {}        # id(settings) -> _Plan
PLANS_KEPT = 16


def _plain_ode(problem) -> bool:
    """An ODE problem whose companion runs as its trajectory alone (``_companion_run``)."""
    return problem.kind == "ode" and problem.drive is None and problem.step_eom is None


def _kept_companion(problem, r):
    """``companion(problem, r)``, kept for the next run of the same (frozen) settings object with
    the same output times, method and engine (a warm Model.simulate): the same settings object
    each time, so its setup is found without hashing the settings again."""
    if not _plain_ode(problem):
        return companion(problem, r)
    s = problem.settings
    ran = r.metadata.get("run") or {}
    key = (len(r.t), ran.get("method"), bool(ran.get("compiled")), id(problem.eom))
    hit = _PLANS.get(id(s))
    if hit is not None and hit.settings is s and hit.key == key:
        return hit.plan
    plan = companion(problem, r)
    if len(_PLANS) >= PLANS_KEPT:
        _PLANS.pop(next(iter(_PLANS)))
    _PLANS[id(s)] = _Plan(s, key, plan, problem.eom)
    return plan


def _kept_states(problem, tight, run_setup=None):
    """The companion's trajectory (OdeSetup.states) with its setup and start values looked up
    once per kept plan (the environment checked on every run, as kept_setup checks it)."""
    from .backends.ode import setup_environment

    hit = _PLANS.get(id(problem.settings))
    env = setup_environment()
    if hit is None or hit.plan[0] is not tight or hit.eom is not problem.eom:
        hit = None
    elif hit.setup is not None and hit.env == env:
        pv, xs = hit.start
        if run_setup is None or getattr(run_setup, "partner", False) is False:     # (not an OdeSetup)
            return hit.setup.states(pv.copy(), xs.copy())
        pair = partner(run_setup, hit.setup, pv, xs)     # the next run calls both at once
        ready, pair.ready = pair.ready, None
        if ready is COMPANION_INTERRUPTED:  # a Ctrl-C during the companion in the run's own C call
            raise KeyboardInterrupt
        if ready is not None:               # run with the run itself, in the same C call (the same bits)
            return ready
        return hit.setup.states(pv.copy(), xs.copy())
    setup = kept_setup(problem.eom, tight, lambda: prepare(formulate(problem.eom, tight.validated())).setup)
    start = setup.start_of(tight)
    if hit is not None:
        hit.setup, hit.env, hit.start = setup, env, (start[0].copy(), start[1].copy())
        if run_setup is not None and getattr(run_setup, "partner", False) is not False:
            partner(run_setup, setup, *hit.start)
    return setup.states(*start)


def _companion_run(problem, tight, solve, run_setup=None):
    """The companion run of ``problem`` with the settings ``tight``: an ODE problem's as its
    trajectory alone (OdeSetup.states: no signals recorded, no Result built; its setup kept
    for the next run of the same settings, backends/ode.kept_setup), others through ``solve``."""
    if _plain_ode(problem):
        other = _kept_states(problem, tight, run_setup)
        if other.failure is not None and other.failure.cause == "interrupted":
            raise KeyboardInterrupt           # as solve raises RunInterrupted for a run Ctrl-C stopped
        return other
    tp = formulate(problem.eom, tight.validated())
    if problem.step_eom is not None:
        tp = dataclasses.replace(tp, step_eom=problem.step_eom)
    return solve(prepare(tp))


def _unit(eom, coordinate: str) -> str | None:
    """The unit of a coordinate's values (SI: rad for an angle declared in deg)."""
    model = getattr(eom, "model", None)
    try:
        return si_unit(model.coordinate(coordinate).unit) if model is not None else None
    except KeyError:
        return None
