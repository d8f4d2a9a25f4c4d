"""The error estimate's companion of a contact run (issue 24, item 4): it follows the run's own
impacts instead of finding its own.

Segments are the spans between the run's event instants.  Each segment is integrated again at
the companion's tighter tolerance from the run's state after the events that open it (the
start values for the first), with the contact modes that state settles to, until the
companion's own first event (or a little past the run's next instant).  Per segment:

    inside:  |q_run - q_companion| at the (coarse) output times before the segment's end
    end:     d_k = |q_run(t) - q'(t)| + |qd_run(t+) - qd_run(t-)| |t - t'|
             (t, t': the run's and the companion's event time; q'(t) the companion's state
             at its event carried to t with its velocity; the second term is what an impact
             timed |t - t'| off moves the coordinates by)

The estimate at an output time of segment k is its inside difference plus the end differences
of the segments before it (summed: local errors carried forward unchanged, neither damped nor
amplified by the flow); estimate.py divides by 1 - 1/TIGHTER as for the other companions.
The cost is that of the run at the tighter tolerance, whatever the number of events (the
previous rule gave runs with more than 20 events no estimate: a loose run paid a companion a
tight one did not).  What it does not see: a bounce the run declared resting (its rest band
grows with the tolerance, so the rebound it dropped rises less than about REST_BAND event
offsets: an error of that order by construction).
"""
from __future__ import annotations

import numpy as np

from ...eom import parameter_vector
from ...eom.start import start_vector
from ...impacts.contact_run import ContactRun
from ...impacts.contact_system import ContactSystem
from ..registry import events_method
from ..settings import DEFAULT_POINTS
from .event_flight import COMPILED_CLASSES, flight
from .event_loop import Run, RunFailure

MARGIN = 0.5        # a companion segment runs at most this fraction of the segment past the run's next instant


class _Stop(Exception):
    """The companion reached its first event: time and state just before it."""

    def __init__(self, t: float, y: np.ndarray):
        super().__init__("event")
        self.t, self.y = float(t), np.array(y, float)


class _SegmentRun(Run):
    """A Run that stops at its first event (impacts included: none applied in the compiled
    loop) and records states only (no forces: the estimate compares coordinates)."""

    def _at_event(self, t, y_ev):
        raise _Stop(t, y_ev)

    def _fixations_due(self, t, y, pending, fixed):
        if any(tf <= t for tf, _ in pending):
            raise _Stop(t, y)
        return y

    def _impacts_in_c(self):
        return None

    def _store(self, gi, t, y):
        self.out_y[gi] = y

    def _store_many(self, sol, ts):
        K = len(ts)
        self.out_y[self.gi:self.gi + K] = np.asarray(sol(ts), float).reshape(2 * self.n, -1).T
        self.gi += K
        return True

    def _check_work(self, t0, t_end, y):        # the run passed it
        return None


class _Strict(ContactRun):
    """The companion's options where it resolves an instant itself: a contact touches only within
    twice its event offset (the run's touch band, 100 atol, makes contacts that land a few
    microseconds apart one simultaneous impact)."""

    @property
    def touch(self) -> float:
        return max(1e-12, 2.0 * self.offset)


class _Resolving(_SegmentRun):
    """A segment that starts just before an instant where the run merged impacts the companion
    resolves apart: it applies its own impacts (strict touch band) until every contact of the
    merged impact has had one, then stops at its next event as a _SegmentRun does."""

    LIMIT = 20          # events it applies at most

    def __init__(self, *args, pending=(), **kw):
        super().__init__(*args, **kw)
        self.pending = set(pending)

    def _record(self, ev):
        super()._record(ev)
        if ev["kind"] in ("impact", "close"):
            self.pending -= {c.strip() for c in str(ev["contact"]).split(",")}

    def _at_event(self, t, y_ev):
        if self.pending and len(self.events) < self.LIMIT:
            return Run._at_event(self, t, y_ev)
        raise _Stop(t, y_ev)


def merged(events, system, t: float, q: np.ndarray, band: float) -> list[str]:
    """The contacts of the run's simultaneous impacts at an instant (``events``, state before
    them ``q``) that were still open by more than ``band`` there: the run's touch band took them
    into the impact; a run that resolves the band would see them land (slightly) later."""
    names = [g.name for g in system.gaps]
    gap = system.gap(t, q)
    out = []
    for ev in events:
        cs = [c.strip() for c in str(ev["contact"]).split(",")]
        if ev["kind"] == "impact" and len(cs) > 1:
            out += [c for c in cs if c in names and gap[names.index(c)] > band and c not in out]
    return out


class Followed:
    """What the companion found: times and estimated errors (|differences|, per coordinate, not yet
    divided by the factor), the largest event-time difference, the work, a note when it stopped."""

    def __init__(self, n: int):
        self.t: list[np.ndarray] = []
        self.err: list[np.ndarray] = []
        self.dt_event, self.dt_event_time = 0.0, None
        self.segments, self.steps, self.rhs_evals = 0, 0, 0
        self.note = None
        self.resolved: list[tuple[float, list[str]]] = []     # instants the companion resolved itself

    def row(self, t: float, e: np.ndarray) -> None:
        self.rows(np.array([t], float), np.reshape(e, (1, -1)))

    def rows(self, t: np.ndarray, e: np.ndarray) -> None:
        self.t.append(np.asarray(t, float))
        self.err.append(np.asarray(e, float))


def instants(events) -> list[tuple[float, dict, dict, list]]:
    """(time, state before the first event, state after the last one, the events) per instant
    with events."""
    out = []
    for ev in events:
        t = float(ev["time"])
        if out and out[-1][0] == t:
            out[-1] = (t, out[-1][1], ev["state_after"], out[-1][3] + [ev])
        else:
            out.append((t, ev["state_before"], ev["state_after"], [ev]))
    return out


def _dropped(events, system, band, rest_speed, q_of, qd_of) -> np.ndarray:
    """Per coordinate, how far the rebounds the run declared resting at an instant (its
    ``events``) would have moved it:
    an impact with restitution e > 0 whose rebound e |u| was above rest_speed but ended at rest
    (the rest band: it would rise less than ``band`` in its gap) loses e times its velocity jump
    for the rise time, a displacement |jump| band / |u| (e cancels; an upper bound)."""
    names = [g.name for g in system.gaps]
    out = np.zeros(len(system.eom.coords))
    for ev in events:
        if ev["kind"] != "impact":
            continue
        cs = [x.strip() for x in str(ev["contact"]).split(",")]
        ub, ua = np.atleast_1d(ev["speed_before"]), np.atleast_1d(ev["speed_after"])
        if len(cs) != len(ub) or len(ua) != len(ub):
            continue
        inv = [abs(u) for c, u, w in zip(cs, ub, ua) if c in names and u < 0 and abs(w) <= 1e-6 * abs(u)
               and system.e[names.index(c)] * abs(u) >= rest_speed]
        if inv:
            jump = np.abs(qd_of(ev["state_after"]) - qd_of(ev["state_before"]))
            out = np.maximum(out, jump * band / min(inv))
    return out


def follow(eom, s, r, parts, stride: int = 1, band: float = 0.0) -> Followed:
    """Integrate the segments of the contact run ``r`` with the (tighter) settings ``s`` and the
    model's contact ``parts`` (gaps, fixations, Functions: events._contact_setup); output times:
    every ``stride``-th of the run's grid; ``band``: the run's rest band in its gaps (REST_BAND
    event offsets of the run)."""
    c = s.contacts
    opts = ContactRun(c, s.rtol, s.atol)
    strict = _Strict(c, s.rtol, s.atol)
    method_cls, _ = events_method(s.method)
    gaps, fixes, functions = parts
    pv = parameter_vector(eom, s.p)
    xs = start_vector(eom, s.x0, pv)
    n = eom.n
    system = ContactSystem(eom, gaps, fixes, pv, functions=functions)
    fl = None
    if s.compiled is not False and method_cls in COMPILED_CLASSES and c.max_step is None:
        fl, _ = flight(system, tag=eom.name)
    npts = s.points or DEFAULT_POINTS
    grid = np.linspace(s.t_start, s.t_end, npts)[::stride]
    coords = list(eom.coords)
    q_of = lambda st: np.array([st[k] for k in coords], float)                    # noqa: E731
    qd_of = lambda st: np.array([st[f"der({k})"] for k in coords], float)         # noqa: E731
    # the run's rows on the grid (without event rows)
    T, Q = np.asarray(r.t), np.asarray(r.q)
    keep = np.r_[True, np.diff(T) > 0] & np.r_[np.diff(T) > 0, True] if len(T) > 1 else np.ones(len(T), bool)
    T, Q = T[keep], Q[keep]
    inst = instants(r.events)
    out = Followed(n)
    carried = np.zeros(n)
    starts = [(s.t_start, xs[:n], xs[n:])] + [(t, q_of(a), qd_of(a)) for t, _, a, _ in inst]
    for k, (tk, q0, qd0) in enumerate(starts):
        if tk >= s.t_end and k:
            break
        last = k >= len(inst)
        t_next = s.t_end if last else inst[k][0]
        stop = s.t_end if last else min(s.t_end, t_next + MARGIN * (t_next - tk),
                                         inst[k + 1][0] if k + 1 < len(inst) else s.t_end)
        pts = grid[(grid >= tk) & (grid <= stop)]
        apart = []
        if k:        # the run's events at tk: impacts it merged that the companion resolves apart
            _, before, _, evs = inst[k - 1]
            apart = merged(evs, system, tk, q_of(before), strict.touch)
        if apart:
            out.resolved.append((tk, apart))
            q0, qd0 = q_of(before), qd_of(before)
            run = _Resolving(system, strict, pts, method_cls, flight=fl, pending=apart)
        else:
            run = _SegmentRun(system, opts, pts, method_cls, flight=fl)
        hit = None
        try:
            with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
                y_end = run.run(tk, stop, np.array(q0, float), np.array(qd0, float))
        except _Stop as e:
            hit, y_end = e.t, e.y
        except (RunFailure, np.linalg.LinAlgError, FloatingPointError, OverflowError, ValueError) as e:
            out.note = (f"the companion stopped in the segment from t = {tk:.6g} s "
                        f"({getattr(e, 'cause', None) or type(e).__name__}): the estimate covers the times before")
            break
        finally:
            out.segments += 1
            out.steps += run.stats["steps"]
            out.rhs_evals += system.n_rhs
            system.n_rhs = 0
        # inside: the output times before both ends
        t_cut = t_next if hit is None else min(t_next, hit)
        m = run.gi
        inside = (pts[:m] < t_cut) if not last else (pts[:m] <= t_cut)
        tt, yy = pts[:m][inside], run.out_y[:m][inside]
        if len(tt):
            j = np.clip(np.searchsorted(T, tt), 0, len(T) - 1)
            jm = np.maximum(j - 1, 0)
            j = np.where(np.abs(T[jm] - tt) < np.abs(T[j] - tt), jm, j)
            ok = np.abs(T[j] - tt) <= 1e-12 * np.maximum(1.0, np.abs(tt))
            out.rows(tt[ok], carried + np.abs(Q[j[ok]] - yy[ok, :n]))
        if last:
            break
        t_run, before, after, evs = inst[k]
        t_c = stop if hit is None else hit           # no event before stop: at least that late
        q_c = y_end[:n] + (t_run - t_c) * y_end[n:]
        jump = np.abs(qd_of(after) - qd_of(before))
        d = np.abs(q_of(before) - q_c) + jump * abs(t_run - t_c)
        if not np.all(np.isfinite(d)):
            d = np.where(np.isfinite(d), d, np.inf)
        carried = carried + d
        out.row(t_run, carried + _dropped(evs, system, band, c.rest_speed, q_of, qd_of))
        if abs(t_run - t_c) >= out.dt_event:
            out.dt_event, out.dt_event_time = abs(t_run - t_c), t_run
    if out.resolved and out.note is None:
        t0, names = out.resolved[0]
        more = f" and {len(out.resolved) - 1} more instant(s)" if len(out.resolved) > 1 else ""
        out.note = (f"at t = {t0:.6g} s{more} the run took contacts still open within its touch band into "
                    f"one simultaneous impact ({', '.join(names)}); the estimate includes the companion's own "
                    "impacts there, one after another")
    return out

