"""``simulate_with_contacts``: simulations of models with unilateral contacts and fixations."""
from __future__ import annotations

import time as _time

import numpy as np

from ...output import result as R
from ...diagnostics import Diagnostic, MechError, UsageError
from ...impacts.gaps import contact_gaps
from ...impacts.options import ContactOptions
from .event_flight import COMPILED_CLASSES, flight
from .event_loop import Run, RunFailure
from ...impacts.stepper import resolve_method
from ...impacts.system import ContactSystem
from ...eom import parameter_vector  # noqa: F401  (re-exported)
from ..inputs import start_vector
from .. import record as Rec
from ..record import ENERGY_NAMES

# options of the ODE simulator (mechdsl.simulate) that make no difference here: accepted so that
# the simulator can pass its options through unchanged
_PASSED_THROUGH = ("formulation", "dt", "reactions", "compiled", "max_steps", "integrator_options",
                   "singularity_threshold", "functions")
DEFAULT_POINTS = 501


def simulate_with_contacts(eom, contacts=None, t_end: float | None = None, *, t_start: float = 0.0,
                           rtol: float = 1e-8, atol: float = 1e-10, method: str | None = "auto",
                           points: int | None = None, outputs=None, x0=None, p=None, progress=None,
                           q0=None, qd0=None, fixations=(), rest_speed: float | None = None,
                           impact_order: str | None = None, gap_tol: float | None = None,
                           event_offset: float | None = None, max_events: int = 100000,
                           max_step: float | None = None, samples: int = 4, output_events: bool = False,
                           **passed) -> R.Result:
    """Simulate eom with unilateral contacts from t_start to t_end; output on a uniform grid.

    contacts: ``ir.Contact`` / ``ContactGap`` / ``Fixation`` objects (default: the model's);
    fixations: more :class:`Fixation` objects.  x0 ([q; qd] or {name: value, "der(name)": value})
    and p (vector or {name: value}) as for ``mechdsl.simulate.simulate``; q0/qd0 override the
    start values directly.  progress: a callable(t, t_end) called after every step.
    rest_speed (m/s, default 1e-3), impact_order ("simultaneous" | "sequential"): see
    docs/contacts.md.  The events (impacts, contacts closing and releasing, fixations) are
    in ``result.events``, each with the state before and after it (``state_before``,
    ``state_after``: {coordinate: value, "der(coordinate)": value}).  output_events: the
    results also get a row just before and one just after every instant with events (same
    time; the signal ``event`` is -1 before, +1 after, 0 on the grid).
    """
    for k in passed:
        if k not in _PASSED_THROUGH:
            raise UsageError(f"unknown option '{k}' for a simulation with contacts")
    if t_end is None:
        raise UsageError("give t_end")
    t_end, t_start = float(t_end), float(t_start)
    if not (np.isfinite(t_end) and np.isfinite(t_start) and t_end > t_start):
        raise UsageError(f"t_end ({t_end}) must be after the start time ({t_start})")
    npts = DEFAULT_POINTS if points is None else int(points)
    if npts < 2:
        raise UsageError("points must be at least 2")
    rest_speed = 1e-3 if rest_speed is None else float(rest_speed)
    impact_order = impact_order or "simultaneous"
    opts = ContactOptions(rtol=float(rtol), atol=float(atol), rest_speed=float(rest_speed),
                          impact_order=impact_order, gap_tol=gap_tol, event_offset=event_offset,
                          max_events=int(max_events), max_step=max_step, samples=int(samples))
    method_cls, note = resolve_method(method)
    gaps, fixes, functions = _contact_setup(eom, contacts, fixations)
    pv = parameter_vector(eom, p)
    xs = start_vector(eom, x0, pv)
    qs, qds = xs[:eom.n], xs[eom.n:]
    if q0 is not None:
        qs = np.asarray(q0, float).ravel()
    if qd0 is not None:
        qds = np.asarray(qd0, float).ravel()
    out_names = output_names(eom, gaps, outputs)
    system = ContactSystem(eom, gaps, fixes, pv, functions=functions)
    gap0 = system.gap(t_start, qs)
    for g, v in zip(gaps, gap0):
        if v < -opts.touch:
            raise MechError(Diagnostic("E861", f"the start state penetrates contact '{g.name}' (gap {v:.6g} m)",
                                       g.span or _no_span(),
                                       "change the start values so that every gap is >= 0"))
    grid = np.linspace(t_start, t_end, npts)
    fl, compiled_note = None, "off (requested)"
    if passed.get("compiled") is False:
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
    try:
        with np.errstate(over="ignore", invalid="ignore", divide="ignore"):   # non-finite values fail the run
            run.run(t_start, t_end, qs, qds)
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
    conservative = _conservative(eom) and not system.friction
    if conservative and m:
        res.stats.update(_drift_between_events(res, run.events, side))
    reason = ("one-step solver with event location (models with contacts)" + (f"; {note}" if note else "")
              + ("; free flights in the compiled loop" if fl is not None else ""))
    res.metadata = {"model": eom.name, "route": eom.route, "coordinates": list(eom.coords), "warnings": [],
                    "method": method_cls.lower(), "method_reason": reason, "compiled": compiled_note, "conservative": conservative,
                    "simulator": "mechdsl.impacts",
                    "options": {"t_start": t_start, "t_end": t_end, "rtol": opts.rtol, "atol": opts.atol,
                                "points": npts, "method": method or "auto", "outputs": list(out_names),
                                "impact_order": opts.impact_order, "rest_speed": opts.rest_speed,
                                "gap_tol": opts.touch, "event_offset": opts.offset,
                                "output_events": bool(output_events),
                                "parameters": dict(zip(eom.params, map(float, pv))),
                                "start": {**dict(zip(eom.coords, map(float, qs))),
                                          **{f"der({c})": float(v) for c, v in zip(eom.coords, qds)}}},
                    "contacts": [g.name for g in gaps], "fixations": [f.label for f in fixes]}
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


def _conservative(eom) -> bool:
    """No dissipation, no other generalized forces, no explicit time (impacts aside)."""
    import casadi as ca

    try:
        return bool(ca.SX(eom.D).is_zero() and ca.SX(eom.Q).is_zero()
                    and not ca.depends_on(ca.vertcat(ca.SX(eom.T), ca.SX(eom.V)), eom.t))
    except Exception:  # noqa: BLE001 -- a non-SX energy: make no claim
        return False


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




def _no_span():
    from ...diagnostics import Span

    return Span()



def _contact_setup(eom, contacts, fixations):
    """(gaps, fixations, contact Functions) of the model's contacts: derived once per EOM
    object and set of contacts (kept in its workspace; a repeated run, a sweep or a benchmark
    does not rebuild them), fresh when the contacts are not hashable."""
    from ...impacts.system import contact_functions

    def build():
        gaps, fixes = contact_gaps(eom, contacts)
        fixes = fixes + list(fixations)
        return gaps, fixes, contact_functions(eom, gaps, fixes)

    key = ("contact_setup", None if contacts is None else tuple(contacts), tuple(fixations))
    try:
        hash(key)
    except TypeError:
        return build()
    from ...eom.workspace import of

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
