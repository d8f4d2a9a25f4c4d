"""``simulate_with_contacts``: simulations of models with unilateral contacts and fixations."""
from __future__ import annotations

import time as _time

import numpy as np

from .. import result as R
from ..diagnostics import Diagnostic, MechError, UsageError
from .gaps import contact_gaps
from .options import ContactOptions
from .run import Run, RunFailure
from .stepper import resolve_method
from .system import ContactSystem

# options of the ODE simulator that make no difference here (accepted so that the simulator can
# pass its options through unchanged)
_PASSED_THROUGH = ("formulation", "dt", "reactions", "compiled")
DEFAULT_POINTS = 501


def simulate_with_contacts(eom, contacts=None, t_end: float | None = None, *, t_start: float = 0.0,
                           rtol: float = 1e-8, atol: float = 1e-10, method: str | None = "auto",
                           points: int | None = None, outputs=None, p=None, q0=None, qd0=None,
                           fixations=(), rest_speed: float = 1e-3, impact_order: str = "simultaneous",
                           gap_tol: float | None = None, event_offset: float | None = None,
                           max_events: int = 100000, max_step: float | None = None, samples: int = 4,
                           **passed) -> R.Result:
    """Simulate eom with unilateral contacts from t_start to t_end; output on a uniform grid.

    contacts: ``ir.Contact`` / ``ContactGap`` / ``Fixation`` objects (default: the model's);
    fixations: more :class:`Fixation` objects.  See docs/contacts.md for the options.
    The events (impacts, contacts closing and releasing, fixations) are in ``result.events``.
    """
    for k in passed:
        if k not in _PASSED_THROUGH:
            raise UsageError(f"unknown option '{k}' for a simulation with contacts")
    if t_end is None:
        raise UsageError("give t_end")
    t_end, t_start = float(t_end), float(t_start)
    if not t_end > t_start:
        raise UsageError(f"t_end ({t_end}) must be after the start time ({t_start})")
    npts = DEFAULT_POINTS if points is None else int(points)
    if npts < 2:
        raise UsageError("points must be at least 2")
    opts = ContactOptions(rtol=float(rtol), atol=float(atol), rest_speed=float(rest_speed),
                          impact_order=impact_order, gap_tol=gap_tol, event_offset=event_offset,
                          max_events=int(max_events), max_step=max_step, samples=int(samples))
    method_cls, note = resolve_method(method)
    gaps, fixes = contact_gaps(eom, contacts)
    fixes = fixes + list(fixations)
    pv = eom.param_values if p is None else np.asarray(p, float)
    qs, qds = eom.start(pv)
    qs = qs if q0 is None else np.asarray(q0, float)
    qds = qds if qd0 is None else np.asarray(qd0, float)
    system = ContactSystem(eom, gaps, fixes, pv)
    gap0 = system.gap(t_start, qs)
    for g, v in zip(gaps, gap0):
        if v < -opts.touch:
            raise MechError(Diagnostic("E701", f"the start state penetrates contact '{g.name}' (gap {v:.6g} m)",
                                       g.span or _no_span(),
                                       "change the start values so that every gap is >= 0"))
    grid = np.linspace(t_start, t_end, npts)
    run = Run(system, opts, grid, method_cls)
    wall = _time.perf_counter()
    failure = None
    try:
        run.run(t_start, t_end, qs, qds)
    except RunFailure as f:
        failure = R.Failure(time=float(f.time), cause=f.cause, detail=f.detail)
    wall = _time.perf_counter() - wall
    m = run.gi
    Y = run.out_y[:m]
    n = eom.n
    res = R.Result(t=grid[:m].copy(), q=Y[:, :n].copy(), qd=Y[:, n:].copy(), coordinates=tuple(eom.coords),
                   events=run.events, failure=failure)
    res.signals = _signals(eom, system, grid[:m], Y, run.out_force[:m], outputs)
    res.stats = dict(run.stats, rhs_evaluations=system.n_rhs, wall_time=wall, events=len(run.events),
                     impacts=sum(1 for e in run.events if e["kind"] == "impact"))
    res.metadata = {"model": eom.name, "method": method_cls.lower(), "method_requested": method or "auto",
                    "rtol": opts.rtol, "atol": opts.atol, "t_start": t_start, "t_end": t_end, "points": npts,
                    "contacts": [g.name for g in gaps], "fixations": [f.label for f in fixes],
                    "impact_order": opts.impact_order, "rest_speed": opts.rest_speed, "gap_tol": opts.touch,
                    "event_offset": opts.offset, "simulator": "mechdsl.impacts"}
    if note:
        res.metadata["method_note"] = note
    if gaps and eom.point_position is None and any(g.kind != "gap" for g in gaps):
        res.metadata["note"] = "contacts given as gap expressions"
    return res


def _no_span():
    from ..diagnostics import Span

    return Span()


def _signals(eom, system, t, Y, force, outputs) -> dict[str, np.ndarray]:
    import casadi as ca

    n, N = eom.n, len(t)
    want = None if outputs is None else [str(o) for o in outputs]
    names, exprs = [], []
    avail = dict(eom.outputs)
    avail.update({"kinetic_energy": eom.T, "potential_energy": eom.V, "energy": eom.T + eom.V})
    for g in system.gaps:
        avail[f"{g.name}.gap"] = ca.SX(g.gap)
    forced = {f"{g.name}.force": i for i, g in enumerate(system.gaps)}
    if want is None:
        order = list(avail) + list(forced)
    else:
        coord_like = set(eom.coords) | {f"der({c})" for c in eom.coords}
        unknown = [w for w in want if w not in avail and w not in forced and w not in coord_like]
        if unknown:
            raise UsageError(f"no output named '{unknown[0]}'; available: " + ", ".join(list(avail) + list(forced)))
        order = [w for w in want if w in avail or w in forced]
    for name in order:
        if name in avail:
            names.append(name)
            exprs.append(ca.reshape(ca.SX(avail[name]), -1, 1))
    out: dict[str, np.ndarray] = {}
    if exprs and N:
        f = ca.Function("signals", [eom.t, eom.q, eom.qd, eom.p], [ca.vertcat(*exprs)])
        vals = np.array(f.map(N)(t.reshape(1, -1), Y[:, :n].T, Y[:, n:].T,
                                 np.repeat(system.p.reshape(-1, 1), N, 1)), float)
        row = 0
        for name, e in zip(names, exprs):
            k = int(e.numel())
            v = vals[row:row + k].T
            out[name] = v[:, 0] if k == 1 else v
            row += k
    elif exprs:
        out.update({name: np.zeros(0) for name in names})
    for name in order:
        if name in forced:
            out[name] = force[:, forced[name]].copy()
    return {name: out[name] for name in order if name in out}
