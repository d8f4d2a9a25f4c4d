"""The hybrid simulation loop: step, locate events on the dense output, apply impacts, restart.

Modes.  Every contact is *open* (free flight, its gap watched) or *closed* (persistent:
its gap held at zero as a bilateral constraint, its normal force watched).  Fixations, once
their time has come, are bilateral for good; the model's own constraints always are.

Events in one accepted step [t_a, t_b] (dense output y(t)):
    open contact i:    e_i(t) = gap_i(y(t)) + offset     crosses to <= 0   -> impact
    closed contact i:  e_i(t) = lam_i(y(t))              crosses to <= 0   -> release
The event function E(t) = min_i e_i(t) is sampled at ``samples`` sub-intervals of the
step; the first sign change is shrunk by a safeguarded Illinois iteration on the
interpolant to the time resolution of double precision.  E(t_a) > 0 holds at every step
start (after an event the state is taken on the positive side of the bracket, and a
contact left touching is projected out of penetration), so an event at the very start of
a step, or a hop shorter than one step, is still found.  Grid points before the event come
from this step's interpolant; the integrator restarts at the event.
"""
from __future__ import annotations

import collections
import math

import numpy as np

from ...impacts.impact_map import ImpactError, ImpactSolution, solve_impact
from ...impacts.one_step import IMPLICIT, make_solver, steps_per_period
from ...impacts.rootfind import bracket_root
from .event_flight import CANCELLED, COMPILED_CLASSES, EVENT, OK


ZENO_EVENTS = 500           # this many events ...
IMPACTS_PER_CALL = 1024     # impact records one compiled call may hold
ZENO_SPAN = 1e-6            # ... within this fraction of the run's span: the events accumulate (Zeno)
BATCH = 4                   # output rows of one step from this many on: their multipliers in one batched call
REST_BAND = 2.0             # a rebound must rise this many event offsets to count as a bounce


class RunFailure(Exception):
    def __init__(self, time: float, cause: str, detail: str = ""):
        super().__init__(cause)
        self.time, self.cause, self.detail = time, cause, detail


class Run:
    def __init__(self, system, opts, grid: np.ndarray, method_cls: str, progress=None, output_events: bool = False,
                 flight=None):
        self.s, self.o = system, opts
        self.grid = np.asarray(grid, float)
        self.method_cls = method_cls
        self.progress = progress
        self._progress_t = -math.inf
        self.t_now = math.nan              # time reached (for failure reports)
        n, k = system.n, system.k
        self.closed = [False] * k
        self.fix_sel: dict[int, list[int]] = {}
        self.active: list[int] = list(system.model_rows)
        self.events: list[dict] = []
        self.out_y = np.full((len(self.grid), 2 * n), np.nan)
        self.out_force = np.zeros((len(self.grid), k))
        self.out_lam = np.zeros((len(self.grid), system.m))
        self.gi = 0
        # output_events: rows (t, y, lam, force) just before (side -1) and after (+1) each instant with events
        self.output_events = output_events
        self.event_rows: list[tuple[float, int, np.ndarray, np.ndarray, np.ndarray]] = []
        self.stats = {"steps": 0, "rejected_steps": 0, "restarts": 0, "projections": 0, "events": 0,
                      "root_evaluations": 0}
        self._burst = (math.nan, 0)
        self._recent = collections.deque(maxlen=ZENO_EVENTS)     # times of the latest events
        # the compiled loop for free flight (impacts/compiled.py), or None: all in Python
        self.flight = flight if method_cls in COMPILED_CLASSES and opts.max_step is None else None
        if self.flight is not None:
            self.stats.update(compiled_segments=0, python_segments=0, compiled_calls=0, compiled_impacts=0)

    # ------------------------------------------------------------------ helpers
    @property
    def n(self) -> int:
        return self.s.n

    def names(self, idx) -> list[str]:
        return [self.s.gaps[i].name for i in idx]

    def _rows_of_contacts(self, idx) -> list[int]:
        return [self.s.contact_row(i) for i in idx]

    def _bilateral_rows(self) -> list[int]:
        rows = list(self.s.model_rows)
        for j in sorted(self.fix_sel):
            rows += self.fix_sel[j]
        return rows

    def _select(self, t, q) -> None:
        """Active rows: model, fixations, closed contacts; dependent contact rows are opened."""
        cand = self._bilateral_rows() + self._rows_of_contacts([i for i, c in enumerate(self.closed) if c])
        sel = self.s.independent(t, q, cand)
        sel_set = set(sel)
        for i, c in enumerate(self.closed):
            if c and self.s.contact_row(i) not in sel_set:
                self.closed[i] = False
        self.active = [r for r in cand if r in sel_set]

    def _lam_closed(self, t, q, qd) -> dict[int, float]:
        _, lam = self.s.accel(t, q, qd, self.active)
        pos = {r: j for j, r in enumerate(self.active)}
        return {i: float(lam[pos[self.s.contact_row(i)]]) for i, c in enumerate(self.closed) if c}

    # ------------------------------------------------------------------ output
    def _sample(self, t: float, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Model multipliers and contact forces at a state, with the current active rows."""
        lam_out, force = np.zeros(self.s.m), np.zeros(self.s.k)
        if self.active:
            _, lam = self.s.accel(t, y[:self.n], y[self.n:], self.active)
            for j, r in enumerate(self.active):
                if r < self.s.m:
                    lam_out[r] = -lam[j]          # EOM convention: M q'' = bias - g_q^T lam
                elif r < self.s.m + self.s.k:
                    force[r - self.s.m] = lam[j]
        return lam_out, force

    def _store(self, gi: int, t: float, y: np.ndarray) -> None:
        self.out_y[gi] = y
        self.out_lam[gi], self.out_force[gi] = self._sample(t, y)

    def _event_rows(self, t: float, y_before: np.ndarray, pre, y_after: np.ndarray, count: int) -> None:
        """With output_events: the rows before and after the events recorded since `count`."""
        if self.output_events and len(self.events) > count:
            self.event_rows.append((t, -1, np.array(y_before, float), *pre))
            self.event_rows.append((t, 1, np.array(y_after, float), *self._sample(t, y_after)))

    def _state(self, q, qd) -> dict[str, float]:
        """A state as {coordinate: value, "der(coordinate)": value} (event records)."""
        names = self.s.eom.coords
        return {**{c: float(v) for c, v in zip(names, q)}, **{f"der({c})": float(v) for c, v in zip(names, qd)}}

    def emit(self, sol, t_hi: float, inclusive: bool) -> None:
        g = self.grid
        j = int(np.searchsorted(g, t_hi, side="right" if inclusive else "left"))
        if j - self.gi >= BATCH and self.active and self._store_many(sol, g[self.gi:j]):
            return
        while self.gi < len(g) and (g[self.gi] < t_hi or (inclusive and g[self.gi] <= t_hi)):
            self._store(self.gi, g[self.gi], sol(g[self.gi]))
            self.gi += 1

    def _store_many(self, sol, ts: np.ndarray) -> bool:
        """The output rows at the times ts of one step with active rows (a resting phase), the
        multipliers in one batched evaluation; False when that cannot be (friction: per row)."""
        Y = np.asarray(sol(ts), float).reshape(2 * self.n, -1)
        lam = self.s.multipliers_at(ts, Y, self.active)
        if lam is None:
            return False
        K, s = len(ts), self.s
        i = self.gi
        self.out_y[i:i + K] = Y.T
        self.out_lam[i:i + K] = 0.0
        self.out_force[i:i + K] = 0.0
        for j, r in enumerate(self.active):
            if r < s.m:
                self.out_lam[i:i + K, r] = -lam[:, j]      # EOM convention: M q'' = bias - g_q^T lam
            elif r < s.m + s.k:
                self.out_force[i:i + K, r - s.m] = lam[:, j]
        self.gi += K
        return True

    # ------------------------------------------------------------------ events
    def event_matrix(self, ts: np.ndarray, Y: np.ndarray):
        """Event components at the columns of Y: rows (kind, contact index) and values (m, K)."""
        labels, vals = [], []
        open_idx = [i for i, c in enumerate(self.closed) if not c]
        if open_idx:
            G = self.s.gaps_at(ts, Y[:self.n])
            vals.append(G[open_idx] + self.o.offset)
            labels += [("impact", i) for i in open_idx]
        closed_idx = [i for i, c in enumerate(self.closed) if c]
        if closed_idx:
            lam_all = self.s.multipliers_at(ts, Y, self.active) if len(ts) >= BATCH else None
            if lam_all is not None:            # one batched evaluation (no friction)
                pos = {r: j for j, r in enumerate(self.active)}
                L = lam_all[:, [pos[self.s.contact_row(i)] for i in closed_idx]].T
            else:
                L = np.zeros((len(closed_idx), len(ts)))
                for j, t in enumerate(ts):
                    lam = self._lam_closed(t, Y[:self.n, j], Y[self.n:, j])
                    L[:, j] = [lam[i] for i in closed_idx]
            vals.append(L)
            labels += [("release", i) for i in closed_idx]
        return labels, (np.vstack(vals) if vals else np.zeros((0, len(ts))))

    def find_event(self, sol, ta: float, tb: float):
        """Earliest event in (ta, tb]: (time, state, triggering labels) or None."""
        if self.s.k == 0:
            return None
        ts = np.linspace(ta, tb, self.o.samples + 1)
        Y = np.asarray(sol(ts), float).reshape(2 * self.n, -1)
        labels, V = self.event_matrix(ts, Y)
        if not labels:
            return None
        E = V.min(axis=0)
        if E[0] <= 0:                    # should not happen (see module doc): an event at the step start
            return ta, Y[:, 0], [lab for lab, v in zip(labels, V[:, 0]) if v <= 0]
        hit = np.nonzero(E[1:] <= 0)[0]
        if hit.size == 0:
            return None
        j = int(hit[0]) + 1

        def fun(t):
            y = np.asarray(sol(t), float).reshape(-1, 1)
            return float(self.event_matrix(np.array([t]), y)[1].min())

        xtol = 4e-16 * max(abs(ta), abs(tb)) + 1e-15 * (tb - ta)
        a, b, nev = bracket_root(fun, ts[j - 1], ts[j], E[j - 1], E[j], xtol)
        self.stats["root_evaluations"] += nev
        yb = np.asarray(sol(b), float).reshape(-1, 1)
        _, Vb = self.event_matrix(np.array([b]), yb)
        trig = [lab for lab, v in zip(labels, Vb[:, 0]) if v <= 0] or [labels[int(np.argmin(Vb[:, 0]))]]
        # the offset only makes detection robust; the impact itself is located where the gap
        # reaches zero (from the positive side), when that root is bracketed
        gaps = [i for kind, i in trig if kind == "impact"]
        if gaps and len(gaps) == len(trig):
            def raw(t):
                y = np.asarray(sol(t), float).reshape(-1, 1)
                return float(np.min(self.s.gaps_at(np.array([t]), y[:self.n])[gaps, 0]))

            lo = ts[j - 1]
            r_lo = raw(lo)
            if r_lo > 0:
                a, _, nev = bracket_root(raw, lo, b, r_lo, raw(b), xtol)
                self.stats["root_evaluations"] += nev + 2
        return a, np.asarray(sol(a), float).ravel(), trig

    def _count_event(self, t: float) -> None:
        self.stats["events"] = len(self.events)
        if len(self.events) > self.o.max_events:
            raise RunFailure(t, f"more than {self.o.max_events} events",
                             "Zeno behaviour? raise rest_speed or max_events")
        t0, cnt = self._burst
        if abs(t - t0) <= 1e-12 * max(1.0, abs(t)):
            cnt += 1
        else:
            t0, cnt = t, 1
        self._burst = (t0, cnt)
        if cnt > 200 * (self.s.k + len(self.s.fixations) + 1):
            raise RunFailure(t, "events do not settle at one instant",
                             f"{cnt} events at t = {t:.12g}; contacts may be contradictory")
        self._recent.append(t)
        span = t - self._recent[0]
        if len(self._recent) == ZENO_EVENTS and span < ZENO_SPAN * (self.grid[-1] - self.grid[0]):
            raise RunFailure(t, "events accumulate (Zeno behaviour)",
                             f"the last {ZENO_EVENTS} events fell within {span:.3g} s, and time hardly advances "
                             f"(each rebound stays faster than rest_speed = {self.o.rest_speed:g} m/s, so the "
                             "contact never comes to rest); raise rest_speed for the scale of this model's speeds")

    def _record(self, ev: dict) -> None:
        self.events.append(ev)
        self._count_event(ev["time"])

    # ------------------------------------------------------------------ event handling
    def handle(self, t: float, q: np.ndarray, qd: np.ndarray):
        """Impacts, closing and releasing of contacts at time t; returns the new (q, qd)."""
        s, o = self.s, self.o
        try:
            gap = s.gap(t, q)
            u = s.normal_speeds(t, q, qd)
            touching = [i for i in range(s.k) if self.closed[i] or gap[i] <= o.touch]
            if any(u[i] < -o.v_eps for i in touching):
                qd = self.impact(t, q, qd, touching)
            self._select(t, q)
            qd = self.settle(t, q, qd)
        except ImpactError as e:
            raise RunFailure(t, "impact could not be resolved", str(e)) from None
        open_rows = self._rows_of_contacts([i for i, c in enumerate(self.closed) if not c])
        q, qd = self.s.project(t, q, qd, self.active, tol=1e-3 * o.offset, one_sided=open_rows,
                               one_sided_tol=0.5 * o.offset)
        self.stats["projections"] += 1
        return q, qd

    def impact(self, t, q, qd, cands: list[int]):
        s, o = self.s, self.o
        M, _ = s.dyn(t, q, qd)
        _, A, ct, _ = s.cons(t, q, qd)
        B_rows = self._bilateral_rows()
        if B_rows:
            B_rows = s.independent(t, q, B_rows)
        B, bt = A[B_rows], ct[B_rows]
        if o.impact_order == "sequential":
            return self._sequential(t, q, qd, cands, M, A, ct, B, bt)
        rows = self._rows_of_contacts(cands)
        G, gt = A[rows], ct[rows]
        e = self._e_eff(cands, G @ qd + gt, self._rest_speeds(t, q, qd, cands))
        sol = solve_impact(M, qd, G, gt, e, B, bt)
        self._record_impact(t, q, qd, sol, cands)
        return sol.qd

    def _rest_speeds(self, t, q, qd, cands) -> np.ndarray:
        """Per candidate contact, the rebound speed below which it comes to rest: rest_speed, or
        the speed that falling through twice the event band (events fire at gap = -offset) gives
        at the contact's acceleration towards the surface, whichever is larger.  A rebound that
        rises less than that is below what the run resolves at its tolerance: counted as a bounce
        it would chatter for ever, each fall through the band restoring the speed the impact
        took (the falling rod at rtol 1e-6: 4587 impacts of a rod lying flat, 140 s)."""
        s, o = self.s, self.o
        base = np.full(len(cands), o.rest_speed)
        try:
            qdd, _ = s.accel(t, q, qd, self.active)
            _, A, _, gam = s.cons(t, q, qd)
            rows = self._rows_of_contacts(cands)
            towards = np.maximum(0.0, -(A[rows] @ qdd + gam[rows]))
        except Exception:  # noqa: BLE001 - no acceleration at this state: the plain rule
            return base
        return np.maximum(base, np.sqrt(2.0 * towards * REST_BAND * o.offset))

    def _e_eff(self, cands, u, rest=None):
        e = self.s.e[cands].copy()
        rest = self.o.rest_speed if rest is None else rest
        e[e * np.abs(np.minimum(u, 0.0)) < rest] = 0.0
        return e

    def _sequential(self, t, q, qd, cands, M, A, ct, B, bt):
        """Pairwise impacts one after another, the fastest approach first (ties: declaration order)."""
        o = self.o
        rows = self._rows_of_contacts(cands)
        limit = 100 * (len(cands) + 1)
        for _ in range(limit):
            u = A[rows] @ qd + ct[rows]
            j = int(np.argmin(u))
            if u[j] >= -o.v_eps:
                return qd
            i = cands[j]
            r = [self.s.contact_row(i)]
            sol = solve_impact(M, qd, A[r], ct[r], self._e_eff([i], u[j:j + 1], self._rest_speeds(t, q, qd, [i])), B, bt)
            self._record_impact(t, q, qd, sol, [i])
            qd = sol.qd
        # did not settle pairwise (e < 1 in a touching cluster): finish with one simultaneous impact
        G, gt = A[rows], ct[rows]
        sol = solve_impact(M, qd, G, gt, self._e_eff(cands, G @ qd + gt, self._rest_speeds(t, q, qd, cands)), B, bt)
        self._record_impact(t, q, qd, sol, cands, note="pairwise impacts did not settle; resolved simultaneously")
        return sol.qd

    def _record_impact(self, t, q, qd, sol, cands, note: str = "") -> None:
        s = self.s
        dT = s.kinetic(t, q, sol.qd) - s.kinetic(t, q, qd)
        tol = 1e-12 * max(1.0, float(np.max(np.abs(sol.impulses))) if sol.impulses.size else 1.0)
        inv = [j for j, i in enumerate(cands) if sol.impulses[j] > tol or sol.speeds_before[j] < -self.o.v_eps]
        ev = {"time": float(t), "kind": "impact", "contact": ", ".join(self.names([cands[j] for j in inv])),
              "impulse": _one([sol.impulses[j] for j in inv]), "energy_change": float(dT),
              "speed_before": _one([sol.speeds_before[j] for j in inv]),
              "speed_after": _one([sol.speeds_after[j] for j in inv]),
              "state_before": self._state(q, qd), "state_after": self._state(q, sol.qd)}
        if note:
            ev["note"] = note
        self._record(ev)

    def settle(self, t, q, qd):
        """Decide which touching contacts are persistent: closed iff their normal force pushes."""
        s, o = self.s, self.o
        gap = s.gap(t, q)
        u = s.normal_speeds(t, q, qd)
        before = list(self.closed)
        for i in range(s.k):
            if not self.closed[i] and gap[i] <= o.touch and abs(u[i]) <= o.v_eps:
                self.closed[i] = True
            elif self.closed[i] and u[i] > o.v_eps:
                self.closed[i] = False     # an impact separated it
        for _ in range(s.k + 1):
            self._select(t, q)
            closed = [i for i, c in enumerate(self.closed) if c]
            if not closed:
                break
            lam, W, afree = self._force_detail(t, q, qd)
            acc = {i: lam[i] * W[i] - o.acc_tol * max(1.0, abs(afree[i])) for i in closed}
            worst = min(closed, key=lambda i: (acc[i], i))
            if acc[worst] > 0:
                break
            self.closed[worst] = False
        self._select(t, q)
        for i in range(s.k):
            if self.closed[i] != before[i]:
                self._record({"time": float(t), "kind": "close" if self.closed[i] else "release",
                              "contact": s.gaps[i].name, "impulse": 0.0, "energy_change": 0.0,
                              "speed_before": float(u[i]), "speed_after": float(u[i]),
                              "state_before": self._state(q, qd), "state_after": self._state(q, qd)})
        return qd

    def _force_detail(self, t, q, qd):
        """Normal forces of closed contacts, W_ii = G_i M^-1 G_i^T and their free gap accelerations."""
        s = self.s
        import scipy.linalg as sla

        M, b = s.dyn(t, q, qd)
        _, A, _, gam = s.cons(t, q, qd)
        cf = sla.cho_factor(M, lower=True)
        a0 = sla.cho_solve(cf, b)
        _, lam = s.accel(t, q, qd, self.active)
        pos = {r: j for j, r in enumerate(self.active)}
        out_l, out_w, out_a = {}, {}, {}
        for i, c in enumerate(self.closed):
            if c:
                r = s.contact_row(i)
                out_l[i] = float(lam[pos[r]])
                out_w[i] = float(A[r] @ sla.cho_solve(cf, A[r]))
                out_a[i] = float(A[r] @ a0 + gam[r])
        return out_l, out_w, out_a

    def fixate(self, t, q, qd, j: int):
        """Fixation j: its point is anchored where it is; the velocity jump from the impact equations."""
        s = self.s
        rows = s.fix_rows(j)
        c, _, _ = s.pos(t, q)
        s.anchor[rows] = c[rows]
        base = self._bilateral_rows()
        sel = s.independent(t, q, base + rows)
        self.fix_sel[j] = [r for r in rows if r in sel]
        M, _ = s.dyn(t, q, qd)
        _, A, ct, _ = s.cons(t, q, qd)
        B_rows = [r for r in base + self.fix_sel[j] if r in sel]
        gap = s.gap(t, q)
        cands = [i for i in range(s.k) if self.closed[i] or gap[i] <= self.o.touch]
        cr = self._rows_of_contacts(cands)
        G, gt = A[cr], ct[cr]
        try:
            sol = solve_impact(M, qd, G, gt, self._e_eff(cands, G @ qd + gt), A[B_rows], ct[B_rows])
        except ImpactError as e:
            raise RunFailure(t, "fixation could not be applied", str(e)) from None
        dT = s.kinetic(t, q, sol.qd) - s.kinetic(t, q, qd)
        pos = {r: k for k, r in enumerate(B_rows)}
        imp = [float(sol.bilateral[pos[r]]) if r in pos else 0.0 for r in rows]
        f = s.fixations[j]
        self._record({"time": float(t), "kind": "fixation", "contact": f.label, "impulse": imp,
                      "energy_change": float(dT), "speed_before": _one(list(A[rows] @ qd + ct[rows])),
                      "speed_after": _one(list(A[rows] @ sol.qd + ct[rows])),
                      "state_before": self._state(q, qd), "state_after": self._state(q, sol.qd)})
        return self.handle(t, q, sol.qd)

    def consistent_start(self, t, q, qd):
        """Start values on the model's constraints: positions, then velocities, moving only the
        coordinates whose start values are not fixed (all of them if every one is fixed)."""
        s = self.s
        rows = s.independent(t, q, s.model_rows)
        if not rows:
            return q, qd
        eom = s.eom
        free_q = [i for i, f in enumerate(eom.fixed_q or (True,) * s.n) if not f] or list(range(s.n))
        free_v = [i for i, f in enumerate(eom.fixed_qd or (True,) * s.n) if not f] or list(range(s.n))
        q, qd = np.array(q, float), np.array(qd, float)
        for _ in range(50):
            c, A, _ = s.pos(t, q)
            c = c[rows]
            if np.max(np.abs(c)) <= 1e-3 * self.o.offset:
                break
            q[free_q] -= np.linalg.lstsq(A[rows][:, free_q], c, rcond=None)[0]
        else:
            raise RunFailure(t, "inconsistent start values", "the constraints cannot be satisfied by the "
                             "coordinates whose start values are not fixed")
        _, A, ct, _ = s.cons(t, q, qd)
        r = A[rows] @ qd + ct[rows]
        qd[free_v] -= np.linalg.lstsq(A[rows][:, free_v], r, rcond=None)[0]
        return q, qd

    def _at_event(self, t: float, y_ev: np.ndarray) -> np.ndarray:
        """Handle the events at t (state y_ev just before): the state after them."""
        n = self.n
        count, pre = len(self.events), self._sample(t, y_ev)
        q, qd = self.handle(t, y_ev[:n], y_ev[n:])
        y = np.concatenate([q, qd])
        self._event_rows(t, y_ev, pre, y, count)
        return y

    def _fixations_due(self, t: float, y: np.ndarray, pending, fixed: set) -> np.ndarray:
        """Apply the pending fixations whose time is t (the end of a segment): the state after them."""
        n = self.n
        for tf, j in pending:
            if tf <= t:
                count, y_pre, pre = len(self.events), y, self._sample(t, y)
                q, qd = self.fixate(t, y[:n], y[n:], j)
                y = np.concatenate([q, qd])
                self._event_rows(t, y_pre, pre, y, count)
                fixed.add(j)
        return y

    def _flight_segment(self, t: float, y: np.ndarray, t_stop: float, t_end: float):
        """Free flight from t to t_stop (or the first event) in the compiled loop: (time, state,
        stopped at an event) with the output rows before it stored, or None when the C loop
        failed or an event sits at t itself (the caller then steps this segment in Python)."""
        s, o, g = self.s, self.o, self.grid
        if not np.all(np.isfinite(y)) or not t_stop > t:
            return None
        while self.gi < len(g) and g[self.gi] <= t:      # points at an event time: the state after it
            self._store(self.gi, g[self.gi], y)
            self.gi += 1
        pts = g[self.gi:]
        pts = pts[pts < t_stop]
        tick = None if self.progress is None else (lambda tt: self._tick(tt, t_end))
        status, t_r, y_r, X, st = self.flight.segment(
            COMPILED_CLASSES[self.method_cls], np.concatenate([[t], pts, [t_stop]]), y, s.p, o.rtol, o.atol,
            o.step_limit - self.stats["steps"], s.k, o.offset, o.samples, tick, self._impacts_in_c())
        if status not in (OK, EVENT, CANCELLED):
            return None
        rows = min(len(X) - 1, len(pts))
        self.out_y[self.gi:self.gi + rows] = X[1:1 + rows]
        self.gi += rows
        self.stats["steps"] += st["steps"]
        self.stats["rejected_steps"] += st["rejected"]
        self.stats["root_evaluations"] += st["root"]
        self.stats["restarts"] += 1
        self.stats["compiled_segments"] += 1
        self.stats["compiled_calls"] += 1
        s.n_rhs += st["rhs"]
        self._decode_impacts(st["impacts"], tick)
        self.t_now = t_r
        if status == CANCELLED:          # Ctrl-C: the rows and impacts up to here are kept
            raise KeyboardInterrupt
        if tick is not None:
            tick(t_r)
        return (t_r, y_r.copy(), True) if status == EVENT else (t_stop, y_r.copy(), False)

    def _impacts_in_c(self):
        """What the compiled loop needs to apply the simple impacts itself (restitution,
        rest_speed, v_eps, touch, the rest band, record capacity), or None: with output events off the
        records stay within max_events (the last one allowed comes back to Python, which fails
        the run exactly as before)."""
        o = self.o
        cap = min(IMPACTS_PER_CALL, o.max_events - len(self.events))
        return (self.s.e, o.rest_speed, o.v_eps, o.touch, REST_BAND * o.offset, cap) if cap > 0 else None

    def _tick(self, t: float, t_end: float) -> None:
        """Progress from the compiled loop: never backwards (the worker thread reports the rows
        written, the decoded impacts come after)."""
        if t >= self._progress_t:
            self._progress_t = t
            self.progress(t, t_end)

    def _decode_impacts(self, recs: np.ndarray, tick=None) -> None:
        """The impacts the compiled loop applied (crk.c impact_in_c), recorded as Run.handle
        records them: rows (time, contact, impulse, speed before, speed after, state at the
        event, state after the impact and the projection)."""
        n = self.n
        for r in recs:
            t, i, y_ev, y = float(r[0]), int(r[1]), r[5:5 + 2 * n], r[5 + 2 * n:]
            count, pre = len(self.events), self._sample(t, y_ev)
            sol = ImpactSolution(qd=y[n:].copy(), impulses=r[2:3].copy(), bilateral=np.zeros(0),
                                 speeds_before=r[3:4].copy(), speeds_after=r[4:5].copy())
            self._record_impact(t, y_ev[:n], y_ev[n:], sol, [i])
            self._event_rows(t, y_ev, pre, y, count)
            self.stats["projections"] += 1
            self.stats["restarts"] += 1
            self.stats["compiled_segments"] += 1
            self.stats["compiled_impacts"] += 1
            if tick is not None:
                tick(t)

    def _check_work(self, t0: float, t_end: float, y: np.ndarray) -> None:
        """A run that would need more steps than the budget fails at once, with the time scale
        named, instead of stepping for minutes in Python (a rod of 1e-12 m swings at 2e6 rad/s).
        The estimate: the fastest motion at the start (the largest eigenvalue modulus rho of the
        free-flight Jacobian; for the implicit solvers the largest imaginary part, since they
        step over decaying stiff modes) makes rho (t_end - t0) / (2 pi) periods, and the solver
        takes at least stepper.steps_per_period(method, rtol) steps a period (measured; 23 for
        dop853 at rtol 1e-10): a lower bound of the work, so a run it refuses could not finish."""
        jac = self.s.jacobian([])
        if jac is None:
            return
        J = np.asarray(jac(t0, y), float)
        if not np.all(np.isfinite(J)):
            return
        lam = np.linalg.eigvals(J)
        rho = float(np.max(np.abs(lam.imag if self.method_cls in IMPLICIT else lam), initial=0.0))
        per_period = steps_per_period(self.method_cls, self.o.rtol)
        need = rho * (t_end - t0) / (2 * np.pi) * per_period
        if need > self.o.step_limit:
            raise RunFailure(t0, "too many steps needed",
                             f"the model's fastest motion at the start has a time scale of {1 / rho:.3g} s "
                             f"(spectral radius {rho:.3g} 1/s): following it to t = {t_end:g} takes about "
                             f"{need:.3g} steps ({per_period:.3g} a period at rtol {self.o.rtol:g}), over the "
                             f"budget of {self.o.step_limit} steps (step_limit); check the sizes and stiffnesses "
                             "(a tiny length or a huge spring), or shorten the run")

    # ------------------------------------------------------------------ the loop
    def run(self, t0: float, t_end: float, q: np.ndarray, qd: np.ndarray):
        s, o = self.s, self.o
        n = self.n
        fix_times = sorted((f.time, j) for j, f in enumerate(s.fixations))
        fixed = set()
        t = t0
        self.t_now = t0
        for tf, j in fix_times:
            if tf <= t0:
                q, qd = self.fixate(t0, q, qd, j)
                fixed.add(j)
        q, qd = self.consistent_start(t, q, qd)
        q, qd = self.handle(t, q, qd)
        y = np.concatenate([q, qd])
        self._check_work(t, t_end, y)
        while t < t_end:
            pending = [(tf, j) for tf, j in fix_times if j not in fixed]
            t_stop = min([t_end] + [tf for tf, _ in pending])
            pending_times = {tf for tf, _ in pending}
            if self.flight is not None and not self.active:
                seg = self._flight_segment(t, y, t_stop, t_end)
                if seg is not None:
                    t, y, event = seg
                    y = self._at_event(t, y) if event else self._fixations_due(t, y, pending, fixed)
                    continue
            if self.flight is not None:
                self.stats["python_segments"] += 1
            rows = list(self.active)
            jac = s.jacobian(rows) if self.method_cls in ("Radau", "BDF", "LSODA") else None
            if not np.all(np.isfinite(y)):
                raise RunFailure(t, "non-finite state", _first_bad(s.eom.coords, y))
            solver = make_solver(self.method_cls, _finite(s.rhs(rows), s.eom.coords), t, y, t_stop, o.rtol,
                                 o.atol, o.max_step, jac=jac)
            self.stats["restarts"] += 1
            restart = False
            while solver.status == "running":
                msg = solver.step()
                if solver.status == "failed":
                    where = ", ".join(f"{c} = {v:.6g}" for c, v in zip(s.eom.coords, solver.y[:n]))
                    raise RunFailure(solver.t, "integrator failed", f"{msg}; at {where}")
                self.stats["steps"] += 1
                if self.stats["steps"] > o.step_limit:
                    raise RunFailure(solver.t, f"more than {o.step_limit} steps",
                                     "the step size collapsed (a very stiff or singular model?); raise step_limit "
                                     "if the run really needs them")
                ta, tb = solver.t_old, solver.t
                self.t_now = ta
                if self.progress is not None:
                    self.progress(tb, t_end)
                sol = solver.dense_output()
                ev = self.find_event(sol, ta, tb)
                if ev is not None:
                    t_ev, y_ev, _ = ev
                    self.emit(sol, t_ev, inclusive=False)
                    t = t_ev
                    y = self._at_event(t, y_ev)
                    restart = True
                    break
                # a grid point at a fixation time shows the state after it (as at impacts)
                self.emit(sol, tb, inclusive=not (tb >= t_stop and t_stop in pending_times))
                t, y = tb, solver.y.copy()
                if self.active:
                    dq, dv = s.drift(t, y[:n], y[n:], self.active)
                    if max(dq, dv) > o.drift_tol:
                        q, qd = s.project(t, y[:n], y[n:], self.active, tol=1e-3 * o.offset)
                        self.stats["projections"] += 1
                        y = np.concatenate([q, qd])
                        restart = True
                        break
            if restart:
                continue
            t = t_stop
            y = self._fixations_due(t, y, pending, fixed)
        # grid points at the final time (after an event there)
        while self.gi < len(self.grid) and self.grid[self.gi] <= t + 1e-12 * max(1.0, abs(t)):
            self._store(self.gi, self.grid[self.gi], y)
            self.gi += 1
        return y


def _first_bad(coords, y) -> str:
    """Which state component is not finite first (coordinates, then speeds)."""
    names = list(coords) + [f"der({c})" for c in coords]
    i = int(np.flatnonzero(~np.isfinite(y))[0])
    return f"{names[i] if i < len(names) else f'component {i}'} = {y[i]}"


def _finite(f, coords):
    """The right-hand side, failing the run (with the time and the first bad coordinate) when it is
    not finite, instead of letting a one-step solver shrink its step for ever on NaN."""
    n = len(coords)

    def g(t, y):
        d = f(t, y)
        if not np.all(np.isfinite(d)):
            names = [f"der({c})" for c in coords] + [f"der(der({c}))" for c in coords]
            i = int(np.flatnonzero(~np.isfinite(d))[0])
            raise RunFailure(t, "non-finite right-hand side",
                             f"{names[i] if i < 2 * n else i} = {d[i]} at the state "
                             + ", ".join(f"{c} = {v:.6g}" for c, v in zip(coords, y[:n]))
                             + " (an overflow: parameter values near the floating-point limit?)")
        return d

    return g


def _one(xs):
    xs = [float(x) for x in xs]
    return xs[0] if len(xs) == 1 else xs
