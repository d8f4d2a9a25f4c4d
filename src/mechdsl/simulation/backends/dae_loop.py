"""The DAE back end's segment loop (``SegmentLoop``): one integrator call per segment, then the
formulation's projection, the conditioning check of G and the drift measurement at each state
the call returned (mechdsl.simulation.backends.dae's docstring: chunks, retries, singular
configurations).  The loop's state lives on the object, one method per step of a segment:
``plan`` (the segment's times), ``advance`` (the call, its failure handling) and ``accept``
(the states of a successful call)."""
from __future__ import annotations

import numpy as np

from ...dae.dae_run import DaeRun
from ...dae.dof import singular_ratio, singular_ratios
from ...dae.segments import NonFiniteError, SegmentInterrupted, StepError, locate_nonfinite
from ...output.result import INTERRUPTED, Failure

SINGULAR_WATCH = 1e-3      # start shortening segments once sigma ratio is below this
MONITOR_POINTS = 61       # the monitoring grid (drift, conditioning, projection), whatever the output points
MAX_RETRIES = 12           # halvings of a failing segment before giving up
FIRST_CHUNK = 8            # intervals of the first segment (ggl, partitioning: doubled after each full one)
BUDGET_MARGIN = 8.0        # a call may take this many times the steps per unit time seen before
MAX_CALLS = 100_000        # integrator calls per run: a bound on every loop of the driver
CHUNK = 64                 # most output intervals per integrator call (one integrator is built
                           # per segment length and kept with the system, so reruns reuse it)
FIRST_PERIODS = 50         # the first segment of an ODE formulation spans at most this many periods

CODE_INTEGRATOR = "E824"    # the integrator gave up (step budget, step size collapse, Newton)
CODE_NONFINITE = "E825"     # the equations or the state became inf/nan


def first_chunk(system, stepper, grid) -> int:
    """Monitoring intervals of the first segment of the ODE formulations: all (CHUNK) unless
    the run is long against the model's time scale 2 pi / rate, rate = sqrt(|q''| / |q|) at
    the start (no Jacobian: it can take seconds to build); then about FIRST_PERIODS periods.  A segment is
    integrated to its end before the drift check cuts it, so a first segment through a whole
    long run (IFToMM A01: 2000 s, cut after ~100 s) doubled the work."""
    q, qd, t = stepper.q, stepper.qd, stepper.t
    try:
        qdd, _ = system.accel(q, qd, t)
        with np.errstate(all="ignore"):     # q = 0: an infinite rate (no warning on stderr), the default
            rate = float(np.sqrt(np.linalg.norm(qdd) / max(np.linalg.norm(q), 1e-300)))
    except Exception:  # noqa: BLE001 -- no estimate: the default
        return CHUNK
    if not np.isfinite(rate) or rate <= 0:
        return CHUNK
    dt = float(grid[1] - grid[0])
    return int(max(1, min(CHUNK, np.ceil(FIRST_PERIODS * 2 * np.pi / rate / dt))))


def with_outputs(times, outs, t_now: float, tiny: float):
    """The segment's times with the output times strictly inside it added, and a flag per time:
    True for the segment's own (monitoring) times."""
    times = np.atleast_1d(np.asarray(times, float))
    inner = outs[(outs > t_now + tiny) & (outs < times[-1] - tiny)]
    if inner.size:
        inner = inner[np.min(np.abs(inner[:, None] - times[None, :]), axis=1) > tiny]
    if not inner.size:
        return times, np.ones(len(times), bool)
    allt = np.concatenate([times, inner])
    mon = np.concatenate([np.ones(len(times), bool), np.zeros(len(inner), bool)])
    order = np.argsort(allt, kind="stable")
    return allt[order], mon[order]


def integrator_failure(system, opts: DaeRun, saved, h: float, e: StepError):
    """The Failure (and its code) of a segment that failed for good, from the last good state
    ``saved`` = (t, q, q'): a non-finite state or right-hand side is named with its time and
    coordinate; otherwise the integrator's own message and the work it did."""
    t, q, qd = saved
    where = (e.t, e.name) if isinstance(e, NonFiniteError) else locate_nonfinite(system, t, q, qd, h)
    if where is not None:
        tw, name = where
        return Failure(t, "non-finite state",
                       f"[{CODE_NONFINITE}] {name} is inf or nan at t = {tw:.10g} (after the last good state at "
                       f"t = {t:.10g}); the model's equations are not defined there"), CODE_NONFINITE
    return Failure(t, f"{opts.formulation} integrator failed",
                   f"[{CODE_INTEGRATOR}] {e}; the step budget is max_steps = {opts.steps} steps per interval until "
                   "a segment succeeded, then 8 times the steps per unit time seen; failing intervals were halved "
                   f"up to {MAX_RETRIES} times; a model with time scales far shorter than the run (check its masses "
                   "and lengths) or a stiff one (method = \"bdf\") ends here"), CODE_INTEGRATOR


class SegmentLoop:
    """The segments of one constrained run.  After ``run``: the recorded states ``T, Qs, QDs``
    and drift ``D, VD`` (output times), ``events``, ``failure`` (and ``failure_code``),
    ``interrupted``, and the extremes over every checked state ``min_ratio, seen_d, seen_v``."""

    def __init__(self, opts: DaeRun, system, stepper, grid, out_t, t0, t_end, span, too_much, progress):
        self.opts, self.system, self.stepper, self.progress = opts, system, stepper, progress
        self.grid, self.out_t, self.t0, self.t_end, self.span = grid, out_t, t0, t_end, span
        self.T, self.Qs, self.QDs, self.D, self.VD = [], [], [], [], []
        self.events: list[dict] = []
        self.failure, self.failure_code = (too_much, CODE_INTEGRATOR) if too_much is not None else (None, None)
        self.interrupted = False
        self.rank = system.m
        self.tiny = 1e-13 * max(abs(t_end), span)
        # IDAS (ggl) and the partitioned CVODES with its Newton solves grind for minutes when a segment
        # runs into a singular configuration before they fail; they start with short segments and stop
        # each well before an extrapolated loss of rank. The explicit index-1 ODE fails fast there.
        self.cautious = opts.formulation in ("ggl", "partitioning")
        self.crossing = getattr(stepper, "crosses_singular", False)   # augmented: passes through singular configurations

    def ratio_at(self, q, t):
        return singular_ratio(self.system.scaled_G(q, t), self.rank)

    def record(self, t, q, qd, dv=None):
        d, v = dv if dv is not None else self.system.drift(q, qd, t)
        self.T.append(t)
        self.Qs.append(q.copy())
        self.QDs.append(qd.copy())
        self.D.append(d)
        self.VD.append(v)

    def run(self) -> None:
        stepper, grid = self.stepper, self.grid
        self.record(self.t0, stepper.q, stepper.qd)
        self.j_out = 1              # next output time to record
        self.ratio_prev, self.t_prev = self.ratio_at(stepper.q, self.t0), self.t0
        self.min_ratio = self.ratio_prev
        self.seen_d, self.seen_v = 0.0, 0.0
        self.h_sing = np.inf
        self.k = 1
        self.retries = 0
        self.h_fail = np.inf
        # step budget per integrator output interval (CasADi's max_num_steps): max_steps until a segment
        # succeeded (a model with absurd time scales then fails within seconds), afterwards also up to
        # BUDGET_MARGIN times the steps per unit time seen there (long monitoring intervals of long runs)
        self.chunk = FIRST_CHUNK if self.cautious else first_chunk(self.system, stepper, grid)
        self.density = None         # integrator steps per unit time of the last successful segment
        self.tau_pred = np.inf      # time until the singular ratio reaches 0, extrapolated from the last decrease
        try:           # (Ctrl-C: the template's interrupt_guard notes what CasADi swallows; segments.call_integrator)
            calls = 0
            while self.k < len(grid) and self.failure is None:
                calls += 1
                if calls > MAX_CALLS:
                    self.too_many_calls()
                    break
                times, single = self.plan()
                accepted = self.advance(times)
                if accepted is not None:
                    self.accept(*accepted, single)
        except KeyboardInterrupt as stop:     # Ctrl-C: stop now, keep what was recorded (the template raises it)
            self.stop(stop)

    def too_many_calls(self) -> None:
        stepper = self.stepper
        self.failure, self.failure_code = Failure(
            stepper.t, f"{self.opts.formulation} integrator failed",
            f"[{CODE_INTEGRATOR}] the run needed more than {MAX_CALLS} integrator calls (segments shortened near "
            "a singular configuration or after failures without end)"), CODE_INTEGRATOR
        if stepper.t > self.T[-1]:
            self.record(stepper.t, stepper.q, stepper.qd)

    def plan(self):
        """The next segment's monitoring times and whether it is a single interval."""
        opts, stepper, grid, k, tiny = self.opts, self.stepper, self.grid, self.k, self.tiny
        single = np.isfinite(self.h_sing) or np.isfinite(self.h_fail) or self.chunk == 1
        if single:
            target = grid[k]
            h = min(target - stepper.t, opts.max_interval or np.inf, self.h_sing, self.h_fail)
            return np.array([target if stepper.t + h >= target - tiny else stepper.t + h]), single
        K = min(self.chunk, len(grid) - k)     # the tail in one segment (integrators are cached per K)
        # a segment stops well before an extrapolated loss of rank: an integrator driven into a
        # singular configuration grinds (IDAS: minutes) before it fails
        if self.cautious and np.isfinite(self.tau_pred):
            K = max(1, min(K, int(0.5 * self.tau_pred / (grid[1] - grid[0]))))
        if opts.max_interval:
            K = max(1, min(K, int((opts.max_interval + tiny) // (grid[1] - grid[0]))))
        times = grid[k:k + K]
        if opts.max_interval and times[-1] - stepper.t > opts.max_interval + tiny:
            times = np.array([stepper.t + opts.max_interval])
        return times, single

    def advance(self, times):
        """One integrator call over the segment (output times inside it added): its states and
        monitoring flags, or None after a failed call (the segment is retried shorter, or the
        run fails)."""
        opts, stepper = self.opts, self.stepper
        saved = (stepper.t, stepper.q.copy(), stepper.qd.copy())
        times, is_mon = with_outputs(times, self.out_t[self.j_out:], stepper.t, self.tiny)
        H = float(times[-1] - stepper.t)
        budget = opts.steps
        if self.density is not None:
            budget = max(budget, int(np.ceil(BUDGET_MARGIN * self.density * H / max(1, int(np.sum(is_mon))))))
        stepper.step_budget = budget if budget > opts.steps else None     # None: max_steps exactly
        steps_before = stepper.stats.get("nsteps", 0)
        try:
            try:
                T_acc, Q_acc, QD_acc = stepper.advance(times, is_mon)
            except np.linalg.LinAlgError as la:   # degenerate linear algebra: a failed segment, retried
                raise StepError(f"linear algebra failed in the {opts.formulation} step ({la})") from None
        except StepError as e:
            self.failed(e, saved, times, is_mon)
            return None
        self.retries = 0
        self.h_fail = np.inf
        self.density = (stepper.stats.get("nsteps", 0) - steps_before) / H
        if self.progress is not None:
            self.progress(float(T_acc[-1]), self.t_end)
        return T_acc, Q_acc, QD_acc, is_mon

    def failed(self, e: StepError, saved, times, is_mon) -> None:
        """A failed call: back to the saved state; retry one monitoring interval at a time, then
        the formulation's recovery, then halving; past MAX_RETRIES (or near a singular
        configuration) the run's Failure."""
        opts, stepper = self.opts, self.stepper
        stepper.reset(*saved)
        if getattr(e, "stats", None):     # a failed call's work counts too
            stepper.count_stats(e.stats)
        if int(np.sum(is_mon)) > 1:     # retry the chunk one monitoring interval at a time
            self.chunk = 1
            return
        if hasattr(stepper, "recover_from_failure") and self.retries == 0 and stepper.recover_from_failure():
            self.retries += 1
            return
        self.retries += 1
        self.h_fail = (times[-1] - saved[0]) / 2
        r_now = self.ratio_at(saved[1], saved[0])
        near_singular = r_now < 100 * opts.singular_tol
        if self.retries > MAX_RETRIES or self.h_fail < self.tiny or near_singular:
            # (near a singular configuration, halving the step only makes the solver retry
            # ever more ill-conditioned systems: stop at once)
            if near_singular or (r_now < self.ratio_prev and r_now < 10 * SINGULAR_WATCH):
                self.failure = Failure(saved[0], "singular configuration",
                                       f"the constraint Jacobian is losing rank (sigma_min/sigma_max = {r_now:.2e}) "
                                       f"and the {opts.formulation} integrator failed: {e}")
            else:
                self.failure, self.failure_code = integrator_failure(self.system, opts, saved,
                                                                     times[-1] - saved[0], e)
            if saved[0] > self.T[-1]:        # keep the last good state (between output times)
                self.record(*saved)

    def accept(self, T_acc, Q_acc, QD_acc, is_mon, single) -> None:
        """The states of a successful call: the next chunk length; at each monitoring time the
        conditioning (a singular configuration stops the run; an approaching one rewinds to
        here and shortens the segments) and the drift; the output times recorded."""
        opts, stepper, grid, out_t, tiny = self.opts, self.stepper, self.grid, self.out_t, self.tiny
        n_mon = int(np.sum(is_mon[:len(T_acc)]))
        if not single:
            self.chunk = min(CHUNK, 2 * self.chunk) if len(T_acc) == len(is_mon) else max(1, n_mon)
        elif self.chunk == 1 and not np.isfinite(self.h_sing):
            self.chunk = 2
        d_all, v_all, Gs_all = self.system.monitor_many(Q_acc, QD_acc, T_acc)   # one call per segment
        ratios = singular_ratios(Gs_all, self.rank)
        for i in range(len(T_acc)):
            t_now, q_now, qd_now = float(T_acc[i]), Q_acc[i], QD_acc[i]
            d_now, v_now, ratio = float(d_all[i]), float(v_all[i]), float(ratios[i])
            is_output = self.j_out < len(out_t) and abs(t_now - out_t[self.j_out]) <= tiny
            if not is_mon[i]:       # an output time between checks: recorded, never acted upon
                self.min_ratio = min(self.min_ratio, ratio)
                if self.crossing:   # (augmented: passages are reported from every state seen)
                    stepper.watch(t_now, ratio)
                if is_output:
                    self.record(t_now, *stepper.for_record(t_now, q_now, qd_now))
                    self.j_out += 1
                continue
            self.min_ratio = min(self.min_ratio, ratio)
            self.seen_d, self.seen_v = max(self.seen_d, d_now), max(self.seen_v, v_now)
            on_grid = abs(t_now - grid[self.k]) <= tiny
            if ratio < opts.singular_tol and not self.crossing:
                self.events.append({"time": t_now, "kind": "singular", "contact": "-",
                                    "detail": f"sigma_min/sigma_max of the scaled constraint Jacobian = {ratio:.2e}"})
                self.failure = Failure(t_now, "singular configuration",
                                       f"the constraint Jacobian lost rank (sigma_min/sigma_max = {ratio:.2e} < "
                                       f"singular_tol = {opts.singular_tol:g}); the motion past this point is not "
                                       "determined by the equations (a dead point or change point of the mechanism)")
                self.record(t_now, q_now, qd_now, (d_now, v_now))
                return
            self.h_sing = np.inf
            if t_now > self.t_prev:
                self.tau_pred = np.inf
            if ratio < self.ratio_prev and t_now > self.t_prev and not self.crossing:
                tau = ratio / ((self.ratio_prev - ratio) / (t_now - self.t_prev))   # linear extrapolation to 0
                self.tau_pred = tau
                if ratio < SINGULAR_WATCH or tau < 2 * (grid[1] - grid[0]):
                    self.h_sing = max(0.5 * tau, 1e3 * tiny)
            self.ratio_prev, self.t_prev = ratio, t_now
            if self.crossing:
                stepper.watch(t_now, ratio)
            if is_output:
                self.record(t_now, q_now, qd_now, (d_now, v_now))
                self.j_out += 1
            if on_grid:
                self.k += 1
            if np.isfinite(self.h_sing) and i < len(T_acc) - 1:
                # approaching a singular configuration: rewind to here, continue in short segments
                stepper.reset(t_now, q_now, qd_now)
                return

    def stop(self, stop: KeyboardInterrupt) -> None:
        """Ctrl-C: what was recorded stays (a record cut short in the middle is dropped), plus the
        output times the interrupted segment reached; the Failure says 'interrupted'."""
        T, Qs, QDs, D, VD = self.T, self.Qs, self.QDs, self.D, self.VD
        self.interrupted = True
        n_rec = min(map(len, (T, Qs, QDs, D, VD)))      # a record() cut short in the middle
        del T[n_rec:], Qs[n_rec:], QDs[n_rec:], D[n_rec:], VD[n_rec:]
        if isinstance(stop, SegmentInterrupted):        # the output times the interrupted segment reached
            try:
                for t_now, q_now, qd_now in zip(stop.times, stop.Q, stop.QD):
                    if self.j_out < len(self.out_t) and abs(float(t_now) - self.out_t[self.j_out]) <= self.tiny \
                            and t_now > T[-1]:
                        self.record(float(t_now), np.asarray(q_now, float), np.asarray(qd_now, float))
                        self.j_out += 1
            except KeyboardInterrupt:                   # (a second Ctrl-C: what is recorded stays)
                n_rec = min(map(len, (T, Qs, QDs, D, VD)))
                del T[n_rec:], Qs[n_rec:], QDs[n_rec:], D[n_rec:], VD[n_rec:]
        self.failure = Failure(T[-1], "interrupted", INTERRUPTED)
