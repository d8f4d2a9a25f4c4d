"""The contact back end: models with unilateral contacts and fixations, as a hybrid system.

``contact_run(eom, settings, progress) -> Result`` steps scipy's one-step solvers with event
location (event_loop.py), free flight in the compiled loop when it can (event_flight.py),
and applies the impact and contact laws of mechdsl.impacts.  Reads the validated settings:
the common fields and the ``contacts`` group (rest_speed, impact_order, output_events,
gap_tol, ..., and the contact objects of a hand-built model).
"""
from __future__ import annotations

import time as _time

import numpy as np

from ...diagnostics import Diagnostic, MechError, Span, UsageError
from ...eom import parameter_vector
from ...eom.start import start_vector
from ...eom.workspace import of
from ...impacts.contact_run import ContactRun
from ...impacts.contact_system import ContactSystem, contact_functions
from ...impacts.gaps import contact_gaps
from ...output import result as R
from ...output.result import INTERRUPTED
from .. import record as Rec
from ..monitors import is_conservative
from ..record import ENERGY_NAMES
from ..registry import events_method, spec
from ..settings import DEFAULT_POINTS
from . import Backend
from .event_flight import COMPILED_CLASSES, flight
from .event_companion import follow
from .event_loop import REST_BAND, Run, RunFailure


class EventsBackend(Backend):
    name = "events"
    noun = "a contact"
    groups = ("contacts",)
    ignores = ("max_steps", "integrator_options")

    def run(self, problem, progress, setup=None):
        return contact_run(problem.eom, problem.settings, progress)

    def follow(self, problem, tight, r, stride):
        """The error estimate's companion of the run ``r``: its segments between events again
        with the settings ``tight`` (event_companion.py)."""
        s = problem.settings
        band = REST_BAND * ContactRun(s.contacts, s.rtol, s.atol).offset      # the run's rest band
        parts = _contact_setup(problem.eom, tight.contacts.contacts, tight.contacts.fixations)
        return follow(problem.eom, tight, r, parts, stride, band)

    def describe(self, r):
        m = r.metadata.get("method")
        python = f"scipy:{spec(m).events if m in ('dop853', 'rk45', 'rk23', 'radau', 'bdf', 'lsoda') else m}"
        stats = r.stats or {}
        compiled, in_python = stats.get("compiled_segments", 0), stats.get("python_segments", 0)
        # name what ran: free flight in the compiled loop, the rest (or all) in scipy's stepper
        parts = ([f"crk:{m}"] if compiled else []) + ([python] if in_python or not compiled else [])
        return {"formulation": "events", "integrator": "+".join(parts), "method": m}


def contact_run(eom, s, progress=None) -> R.Result:
    """Simulate eom with unilateral contacts from t_start to t_end; output on a uniform grid.

    The contacts are ``s.contacts.contacts`` (``ir.Contact`` / ``ContactGap`` / ``Fixation``
    objects; default: the model's) and ``s.contacts.fixations``.  The events (impacts,
    contacts closing and releasing, fixations) are in ``result.events``, each with the state
    before and after it (``state_before``, ``state_after``: {coordinate: value,
    "der(coordinate)": value}).  output_events: the results also get a row just before and
    one just after every instant with events (same time; the signal ``event`` is -1 before,
    +1 after, 0 on the grid).  See docs/contacts.md.
    """
    c = s.contacts
    t_start, t_end = s.t_start, s.t_end
    npts = s.points or DEFAULT_POINTS
    opts = ContactRun(c, s.rtol, s.atol)
    method_cls, note = events_method(s.method)
    contacts, output_events, max_step = c.contacts, c.output_events, c.max_step
    gaps, fixes, functions = _contact_setup(eom, contacts, c.fixations)
    pv = parameter_vector(eom, s.p)
    xs = start_vector(eom, s.x0, pv)
    qs, qds = xs[:eom.n], xs[eom.n:]
    out_names = output_names(eom, gaps, s.outputs)
    system = ContactSystem(eom, gaps, fixes, pv, functions=functions)
    gap0 = system.gap(t_start, qs)
    for g, v in zip(gaps, gap0):
        if v < -opts.touch:
            raise MechError(Diagnostic("E861", f"the start state penetrates contact '{g.name}' (gap {v:.6g} m)",
                                       g.span or Span(),
                                       "change the start values so that every gap is >= 0"))
    grid = np.linspace(t_start, t_end, npts)
    fl, compiled_note = None, "off (requested)"
    if s.compiled is False:
        pass
    elif method_cls not in COMPILED_CLASSES or max_step is not None:
        compiled_note = "no: the compiled loop steps dop853 and rk45 without max_step"
    else:
        fl, compiled_note = flight(system, tag=eom.name)
        compiled_note = ("free flight (all contacts open) in the compiled loop; impacts, closed contacts and "
                         "fixations in Python" if fl is not None else f"no: {compiled_note}")
    run = Run(system, opts, grid, method_cls, progress=progress if callable(progress) else None,
              output_events=bool(output_events), flight=fl)
    wall = _time.perf_counter()
    failure = None
    interrupted = False
    try:
        with np.errstate(over="ignore", invalid="ignore", divide="ignore"):   # non-finite values fail the run
            run.run(t_start, t_end, qs, qds)
    except KeyboardInterrupt:       # Ctrl-C: the output rows stored so far are kept
        interrupted = True
        failure = R.Failure(time=float(run.grid[run.gi - 1]) if run.gi else float(t_start), cause="interrupted",
                            detail=INTERRUPTED)
    except RunFailure as f:
        failure = R.Failure(time=float(f.time), cause=f.cause, detail=f.detail)
    except (np.linalg.LinAlgError, FloatingPointError, OverflowError) as ex:
        failure = R.Failure(time=float(run.t_now), cause="numerical failure",
                            detail=f"{type(ex).__name__}: {ex} (a singular mass matrix or constraint Jacobian?)")
    wall = _time.perf_counter() - wall
    m = run.gi
    T, Y, force, lam, side = grid[:m], run.out_y[:m], run.out_force[:m], run.out_lam[:m], np.zeros(m)
    if output_events:
        T, Y, force, lam, side = _with_event_rows(T, Y, force, lam, run.event_rows)
    n = eom.n
    res = R.Result(t=T.copy(), q=Y[:, :n].copy(), qd=Y[:, n:].copy(), coordinates=tuple(eom.coords),
                   events=run.events, failure=failure)
    res.signals = _signals(eom, system, T, Y, force, lam, out_names, model_gaps=contacts is None)
    if output_events:
        res.signals["event"] = side
    res.stats = dict(run.stats, rhs_evals=system.n_rhs, points=m, wall_time=wall, events=len(run.events),
                     impacts=sum(1 for e in run.events if e["kind"] == "impact"))
    conservative = is_conservative(eom) and not system.friction
    if conservative and m:
        res.stats.update(_drift_between_events(res, run.events, side))
    reason = ("one-step solver with event location (models with contacts)" + (f"; {note}" if note else "")
              + ("; free flights in the compiled loop" if fl is not None else ""))
    res.metadata = {"model": eom.name, "route": eom.route, "coordinates": list(eom.coords), "warnings": [],
                    "method": method_cls.lower(), "method_reason": reason, "compiled": compiled_note, "conservative": conservative,
                    "simulator": "mechdsl.impacts",
                    "options": {"t_start": t_start, "t_end": t_end, "rtol": opts.rtol, "atol": opts.atol,
                                "points": npts, "method": s.method, "outputs": list(out_names),
                                "impact_order": opts.impact_order, "rest_speed": opts.rest_speed,
                                "gap_tol": opts.touch, "event_offset": opts.offset,
                                "output_events": bool(output_events),
                                "parameters": dict(zip(eom.params, map(float, pv))),
                                "start": {**dict(zip(eom.coords, map(float, qs))),
                                          **{f"der({c})": float(v) for c, v in zip(eom.coords, qds)}}},
                    "contacts": [g.name for g in gaps], "fixations": [f.label for f in fixes]}
    if interrupted:
        res.metadata["interrupted"] = True
    return res


def _with_event_rows(T, Y, force, lam, rows):
    """The grid rows merged with the event rows by time: before-event, after-event, then a grid
    point at the same time (which shows the state after the event)."""
    if not rows:
        return T, Y, force, lam, np.zeros(len(T))
    t_all = np.r_[T, [r[0] for r in rows]]
    side = np.r_[np.zeros(len(T)), [r[1] for r in rows]]
    rank = np.r_[np.full(len(T), 2), [0 if r[1] < 0 else 1 for r in rows]]
    seq = np.r_[np.arange(len(T)), np.arange(len(rows))]
    order = np.lexsort((seq, rank, t_all))
    stack = lambda a, k: np.vstack([a, np.array([r[k] for r in rows]).reshape(len(rows), -1)])[order]  # noqa: E731
    return t_all[order], stack(Y, 2), stack(force, 4), stack(lam, 3), side[order]


def _drift_between_events(res, events, side=None) -> dict:
    """Energy drift of the integration alone: E(t) - E(0) minus the changes at the events up to t
    (not including those at t itself for a row just before an event: side -1)."""
    E = res.signals.get("energy")
    if E is None or not len(E) or not np.isfinite(E).all():
        return {}
    times = np.array([e["time"] for e in events])
    jumps = np.cumsum([float(e.get("energy_change", 0.0)) for e in events])
    k = np.searchsorted(times, res.t, side="right")
    if side is not None and len(side) == len(k):
        k = np.where(np.asarray(side) < 0, np.searchsorted(times, res.t, side="left"), k)
    expected = E[0] + np.where(k > 0, jumps[np.maximum(k - 1, 0)] if len(jumps) else 0.0, 0.0)
    dE = float(np.max(np.abs(E - expected)))
    scale = max(abs(float(E[0])), float(np.max(np.abs(res.signals["kinetic_energy"]))),
                float(np.max(np.abs(res.signals["potential_energy"]))), 1e-300)
    return {"energy_drift": dE, "energy_drift_relative": dE / scale}


def output_names(eom, gaps, outputs) -> list[str]:
    """The EOM outputs to record (all by default); unknown names are usage errors."""
    if outputs is None:
        return list(eom.outputs)
    want = [outputs] if isinstance(outputs, str) else [str(o) for o in outputs]
    extra = [f"{g.name}.{w}" for g in gaps for w in ("gap", "force")]
    known = set(eom.outputs) | set(ENERGY_NAMES) | set(extra) | set(eom.coords) | {f"der({c})" for c in eom.coords}
    unknown = [w for w in want if w not in known]
    if unknown:
        raise UsageError(f"'{unknown[0]}' is not an output of {eom.name}; outputs: "
                         + ", ".join(list(eom.outputs) + list(ENERGY_NAMES) + extra))
    return [w for w in want if w in eom.outputs]




def _contact_setup(eom, contacts, fixations):
    """(gaps, fixations, contact Functions) of the model's contacts: derived once per EOM
    object and set of contacts (kept in its workspace; a repeated run, a sweep or a benchmark
    does not rebuild them), fresh when the contacts are not hashable."""
    def build():
        gaps, fixes = contact_gaps(eom, contacts)
        fixes = fixes + list(fixations)
        return gaps, fixes, contact_functions(eom, gaps, fixes)

    key = ("contact_setup", None if contacts is None else tuple(contacts), tuple(fixations))
    try:
        hash(key)
    except TypeError:
        return build()
    gaps, fixes, functions = of(eom).memo(key, build)
    return list(gaps), list(fixes), functions

def _signals(eom, system, t, Y, force, lam, out_names, model_gaps=True) -> dict[str, np.ndarray]:
    """Outputs, energies, invariants and each contact's gap (the recorder), then each
    contact's normal force (from the run).  model_gaps: the gaps are the model's own (the
    same expressions on every run, so the recorder's Function is reused)."""
    import casadi as ca

    n = eom.n
    cols = Rec.merged(Rec.outputs(eom, out_names), Rec.energies(eom), Rec.invariants(eom),
                    {f"{g.name}.gap": ca.SX(g.gap) for g in system.gaps})
    out = Rec.record(eom, cols, t, Y[:, :n], Y[:, n:2 * n], system.p, LAM=lam,
                   using=() if model_gaps else tuple(g.gap for g in system.gaps))
    for i, g in enumerate(system.gaps):
        out[f"{g.name}.force"] = force[:, i].copy()
    return out
