"""The run template: ``simulate(eom, settings) -> Result`` = start check, formulate, then solve.

    settings (SimulationSettings, validated once)  -- settings.py
      -> formulate(eom, settings) -> Problem         -- problem.py (mech compile --emit problem)
      -> solve(problem) -> Result                    -- the template below:
           progress -> backend.run -> non-finite check -> statistics schema
           -> accuracy report -> metadata (what ran) -> [error estimate]
           (Ctrl-C: the back end returns what it reached; RunInterrupted carries that Result)

Every caller goes through here: ``mechdsl.simulate.simulate``, ``Model.simulate`` (and so
``mech simulate``), the shims ``mechdsl.dae.simulate_dae`` and
``mechdsl.impacts.simulate_with_contacts``, sweeps and ``mech bench``.  Back ends are plug-ins
(backends/); method names live in one registry (registry.py).  See docs/internals/simulation.md.
"""
from __future__ import annotations

import dataclasses
import time

import numpy as np

from .. import integrators as I
from ..diagnostics import MechError, UsageError
from ..eom import parameter_vector
from ..eom.preflight import check_start
from ..model.friction import friction_notes
from ..interrupts import interrupt_guard, was_interrupt
from ..output.result import Result, RunInterrupted, versions
from . import accuracy as A
from .backends import backend, ignored_settings
from .backends.ode import plain_copier, record_inputs
from .estimate import estimate
from .prepared import Prepared, prepare
from .record_dae import multiplier_column_units
from .registry import spec
from .problem import Problem, formulate
from .settings import MIN_RTOL, SimulationSettings


def simulate(eom, settings: SimulationSettings, progress=None, problem: Problem | Prepared | None = None) -> Result:
    """Formulate and solve one run, after the start check (mechdsl.eom.preflight: what
    `mech check` accepts can start here; `p`, `x0` and `--set` values are judged too).  What the
    run warns about is also a MechWarning (settings.warn; sweeps collect them instead).
    ``problem``: ``formulate(eom, settings)`` (or its ``prepare``) made before (a warm Model keeps it)."""
    check_start(eom, p=settings.p, x0=settings.x0, t=settings.t_start, drift_bound=settings.dae.bound(settings.atol))
    r = solve(problem if problem is not None else formulate(eom, settings), progress=progress)
    if settings.warn:
        announce(r)
    return r


def announce(r: Result) -> None:
    """Each warning of the run (metadata["warnings"], the accuracy warning among them, once) and a
    failure as a MechWarning: a ``warnings`` category Python users can filter or make an error."""
    import warnings

    from ..diagnostics import MechWarning

    level = _caller_level()
    for msg in dict.fromkeys(r.metadata.get("warnings") or ()):
        warnings.warn(msg, MechWarning, stacklevel=level)
    if r.failure is not None:
        warnings.warn(f"{r.failure}; the results up to there are kept (Result.failure, Result.ok, "
                      "Result.raise_for_failure())", MechWarning, stacklevel=level)


def _caller_level() -> int:
    """The stacklevel of the first frame outside mechdsl (the user's call), for warnings.warn."""
    import sys

    f, level = sys._getframe(1), 1
    while f is not None and (f.f_globals.get("__name__") or "").startswith("mechdsl"):
        f, level = f.f_back, level + 1
    return level


def solve(problem: Problem | Prepared, progress=None) -> Result:
    """Solve a problem through the template: a ``Prepared`` problem (prepared.py) runs with what
    was built for it; a Problem is prepared inside the timed run."""
    setup = None
    if isinstance(problem, Prepared):
        problem, setup = problem.problem, problem.setup
    s = problem.settings
    back = backend(problem.backend)
    bar = None
    callback = progress if callable(progress) else None
    if progress is True:
        bar = I.Progress(True, s.t_start, s.t_end, label=f"{problem.model} ({s.method})")
        callback = lambda t, t1: bar.update(float(t))   # noqa: E731
    wall0, cpu0 = time.perf_counter(), time.process_time()
    try:
        # Ctrl-C: every back end stops within a step (or an integrator call) and returns what it
        # reached with failure "interrupted" (metadata["interrupted"]); the guard notes a Ctrl-C
        # that CasADi turns into a failure (mechdsl.interrupts)
        with interrupt_guard():
            try:
                r = back.run(problem, callback) if setup is None else back.run(problem, callback, setup=setup)
            except (RuntimeError, SystemError) as e:
                if was_interrupt(e):      # a Ctrl-C CasADi turned into an error outside a back end's loop
                    raise KeyboardInterrupt from None
                raise
    except MechError:
        _blame_signals(problem)
        raise
    finally:
        if bar is not None:
            bar.close()
    cpu, wall = time.process_time() - cpu0, time.perf_counter() - wall0
    raw = r.stats.get("raw")
    if type(raw) is dict and "companion_cpu_time" in raw:     # the estimate's companion ran in the same C call
        cpu, wall = cpu - raw["companion_cpu_time"], wall - raw["companion_wall_time"]     # (its own, below)
    if problem.drive is not None and problem.kind != "ode":
        _record_inputs(r, problem.drive)
    if problem.drive is not None:
        _signal_failure(r, problem.drive)
    A.check_finite(r)
    A.normalize_stats(r, cpu, wall)
    A.accuracy_report(r, problem, fixed_step=back.fixed_step)
    meta = r.metadata
    meta.setdefault("warnings", [])
    if back.fixed_step and problem.drive is not None:
        _hold_warning(r, problem)
    meta.setdefault("notes", [])
    meta.setdefault("conservative", "energy" in problem.invariants)
    unused, _, copy_plain = _settings_facts(back, s)
    if unused:
        meta["notes"].append(f"settings without effect on {back.noun} problem: " + ", ".join(unused))
    ran = back.describe(r)
    meta["run"] = {"problem": problem.kind, "backend": problem.backend, **ran,
                   "rtol": s.rtol, "atol": s.atol,
                   "compiled": _ran_compiled(meta, r.stats),
                   "settings": copy_plain()}
    eom = problem.eom
    notes = _friction(eom, s)
    if notes:
        meta["friction"] = notes          # regularized laws and their regularization (issue 17)
    renamed = [c for c in (eom.model.constraints if getattr(eom, "model", None) is not None else ())
               if c.alias and c.alias != c.name]
    if renamed:                           # constraints named after their description: old names still read
        meta["aliases"] = {**{f"lambda[{c.alias}]": f"lambda[{c.name}]" for c in renamed},
                           **{f"residual({c.alias})": f"residual({c.name})" for c in renamed}}
    if eom.m:                             # the unit of every multiplier recorded (issue 23)
        units = {k: u for k, u in multiplier_column_units(eom).items() if k in r.signals}
        if units:
            meta.setdefault("units", {}).update(units)
    meta["versions"] = versions()        # provenance belongs to the Result, stamped here once
    if meta.get("interrupted"):
        raise RunInterrupted(r)           # a KeyboardInterrupt carrying the results up to there
    stopped = False
    try:
        thorough = _estimate_error(r, problem) if s.estimate_error else None
        _default_estimate(r, problem, thorough, setup)
    except KeyboardInterrupt:
        # Ctrl-C during the companion run(s): the run itself is complete and is what RunInterrupted
        # carries (never the companion's partial rows); it has no estimate, and says why
        acc = meta.setdefault("accuracy", {})
        acc.update(error_estimate=None, error_estimate_unavailable="interrupted (Ctrl-C) during the companion run")
        meta["interrupted"] = True
        meta["interrupted_during"] = "the error estimate (the run itself reached its end time)"
        stopped = True
    A.accuracy_warning(r, problem)
    if stopped:
        raise RunInterrupted(r)
    return r


_FACTS: dict = {}        # id(settings) -> (settings, its facts): a kept problem's runs share one settings object


def _settings_facts(back, s) -> tuple:
    """(the settings ``back`` does not use, the settings as plain data without x0 and p, a function
    returning a fresh plain_copy of that), worked out once per settings object (the settings are
    frozen)."""
    hit = _FACTS.get(id(s))
    if hit is not None and hit[0] is s and hit[1] is back:
        return hit[2]
    plain = {k: v for k, v in s.as_dict().items() if k not in ("x0", "p")}
    facts = (ignored_settings(back, s), plain, plain_copier(plain))
    if len(_FACTS) >= 16:
        _FACTS.pop(next(iter(_FACTS)))
    _FACTS[id(s)] = (s, back, facts)
    return facts


_FRICTION: dict = {}     # id(settings) -> (settings, eom, notes): the same for every run of a kept problem


def _friction(eom, s) -> list:
    """friction_notes of ``eom`` at the settings' parameter values, worked out once per settings
    object and equations (a fresh list each run)."""
    hit = _FRICTION.get(id(s))
    if hit is not None and hit[0] is s and hit[1] is eom:
        return list(hit[2])
    notes = friction_notes(getattr(eom, "model", None), dict(zip(eom.params, parameter_vector(eom, s.p))))
    if len(_FRICTION) >= 16:
        _FRICTION.pop(next(iter(_FRICTION)))
    _FRICTION[id(s)] = (s, eom, tuple(notes))
    return list(notes)


def _default_estimate(r: Result, problem: Problem, thorough=None, setup=None) -> None:
    """metadata["accuracy"]["error_estimate"] of every run (simulation/estimate.py), unless turned
    off; from the thorough run of estimate_error when there is one (no third run).  ``setup``:
    the back end's setup the run used, when the problem came prepared (its runs' companion is
    kept on it)."""
    s = problem.settings
    acc = r.metadata.setdefault("accuracy", {})
    if s.error_estimate == "off":
        acc.update(error_estimate=None, error_estimate_unavailable="turned off (error_estimate = off)")
    elif r.failure is not None:
        acc.update(error_estimate=None, error_estimate_unavailable="the run failed")
    elif len(r.t) < 2:
        acc.update(error_estimate=None, error_estimate_unavailable="fewer than two output times")
    else:
        estimate(r, problem, solve, thorough, run_setup=setup)


def _record_inputs(r: Result, drive) -> None:
    """The inputs on the recorded times, as signals named after them (the ODE back end records
    its own), and the bound warnings of signals known only during the run."""
    X = np.c_[r.q, r.qd] if len(r.t) else np.zeros((0, 2 * len(r.coordinates)))
    r.metadata.setdefault("inputs", drive.describe())
    record_inputs(drive, drive.values(np.asarray(r.t, float), X), r.signals, r.metadata)


def _blame_signals(problem: Problem) -> None:
    """A back end that could not evaluate the equations before its run (the fixed-step back end
    probes them): when a Python input signal failed there, that is the error to report."""
    errors = problem.drive.signal_errors() if problem.drive is not None else []
    if errors:
        raise UsageError(f"{'; '.join(errors)} (the {problem.backend} back end evaluates the equations, "
                         "input signals included, at sample states before it starts)") from None


def _signal_failure(r: Result, drive) -> None:
    """A Python input signal that failed during the run is the cause of the run's failure."""
    errors = drive.signal_errors()
    if not errors:
        return
    if r.failure is not None:
        r.failure = dataclasses.replace(r.failure, cause="input signal failed",
                                        detail=f"{'; '.join(errors)} (the back end then reported: "
                                               f"{r.failure.cause}: {r.failure.detail})")
    else:
        r.metadata.setdefault("warnings", []).extend(errors)


def _estimate_error(r: Result, problem: Problem):
    """A second run at a tolerance 100 times tighter (fixed step: a step 4 times shorter); returns
    (that run, the factor its difference is divided by, what it is), or None."""
    s = problem.settings
    if backend(problem.backend).fixed_step:
        dt = s.fixed_step.step(s.t_end - s.t_start)
        tighter = s.replace(dt=dt / 4, estimate_error=False, error_estimate="off",
                            budget=max(s.budget, 4 * int((s.t_end - s.t_start) / dt) + 4))
        how = f"dt = {dt / 4:g}"
    elif s.rtol / 100 < MIN_RTOL:
        r.metadata["error_estimate"] = {
            "reference": None, "max_abs_difference": {},
            "unavailable": f"rtol = {s.rtol:g}: a run 100 times tighter would be below {MIN_RTOL:g}, which double "
                           "precision cannot deliver; estimate at a looser rtol"}
        return None
    else:
        tighter = s.replace(rtol=s.rtol / 100, atol=s.atol / 100, estimate_error=False, error_estimate="off")
        how = f"rtol = {tighter.rtol:g}, atol = {tighter.atol:g}"
    if backend(problem.backend).fixed_step and s.points is None:
        tighter = tighter.replace(points=len(r.t)) if len(r.t) >= 2 else tighter
    if problem.drive is not None and problem.kind != "ode":
        tighter = tighter.replace(inputs=None)        # problem.eom has the inputs built in
    tight_problem = formulate(problem.eom, tighter.validated())
    if problem.step_eom is not None:                  # the holds kept over each step there too
        tight_problem = dataclasses.replace(tight_problem, step_eom=problem.step_eom)
    tight = solve(prepare(tight_problem))
    est = A.error_estimate(r, tight)
    r.metadata["error_estimate"] = {"reference": how, "max_abs_difference": est,
                                    "reference_failed": None if tight.success else str(tight.failure)}
    if backend(problem.backend).fixed_step:
        factor = 1.0 - 4.0 ** -(spec(s.method).order or 1)
    else:
        factor = 1.0 - 1.0 / 100
    return tight, factor, f"the run of estimate_error ({how})"


def _hold_warning(r: Result, problem: Problem) -> None:
    """A fixed-step run holds every zero-order hold over a step (Problem.step_eom); it keeps the
    method's order when the steps land on the samples.  A warning when some do not (or when
    the holds are read at the stage times: constrained models)."""
    s, drive = problem.settings, problem.drive
    breaks = drive.breakpoints(s.t_start, s.t_end)
    jumps = drive.held_names if breaks.size else []
    if not jumps:
        return
    if problem.step_eom is None:
        r.metadata["warnings"].append(
            f"the fixed-step method steps across the zero-order hold of {', '.join(jumps)}: a stage at a "
            "step's end that lands on a sample sees the next value, so a jump can add an error of first "
            "order in dt (the method's own order is lost there); an adaptive method restarts at every jump")
        return
    h = float((r.stats or {}).get("dt") or 0.0)
    k = (breaks - s.t_start) / h if h > 0 else np.zeros(0)
    off = breaks[np.abs(k - np.round(k)) > 1e-9 * np.maximum(1.0, k)]
    if off.size:
        r.metadata["warnings"].append(
            f"{off.size} sample(s) of the zero-order hold of {', '.join(jumps)} fall inside a step (first at "
            f"t = {off[0]:.6g}; step {h:.6g}): the step across a sample reads the value held at its midpoint, an "
            "error of first order in dt there; choose dt so that the samples lie on the step grid "
            "(t_start + k dt), or use an adaptive method, which restarts at every jump")


def _ran_compiled(meta, stats=None) -> bool:
    """Whether compiled code ran: the back end's flag (a bool; the ODE back end's
    ``metadata.compiled`` is the decision's text, its flag is ``options.compiled``); a contact
    run counts its free-flight segments in the compiled loop."""
    if (stats or {}).get("compiled_segments"):
        return True
    flag = meta.get("compiled")
    if not isinstance(flag, bool):
        flag = (meta.get("options") or {}).get("compiled", False)
    return bool(flag)

