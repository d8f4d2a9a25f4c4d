"""The DAE back end: the segment loop shared by every formulation (``SegmentRun``).

    initialize (consistent start, changes reported)
    -> count degrees of freedom, drop redundant constraints (independent subset)
    -> build the formulation's stepper
    -> advance segment by segment to each output time, after each segment:
         projection / re-partitioning (the formulation's hook),
         conditioning check of G (singular configuration -> stop, report the time),
         drift measurement (||g||, ||G q' + g_t||)
    -> outputs, multipliers and reactions at the output times -> Result

Chunks.  One integrator call covers up to CHUNK monitoring intervals (the integrator returns
the states at each monitoring and output time); a formulation may accept only a prefix
(projection does when the drift grows).  A chunk that fails is retried one monitoring interval at a time, and
a failing interval is halved up to MAX_RETRIES times before the run stops with a Failure.

Singular configurations.  At every accepted state the ratio sigma_min / sigma_max of the
scaled G is computed (at the MONITOR_POINTS equally spaced monitoring times, refined near
trouble; output times in between are only extra output times of the integrator calls, so
they change no number).  Once the ratio falls below SINGULAR_WATCH and
keeps falling, or its linear extrapolation reaches zero within two grid steps, the run
rewinds to that state and continues in single segments, each ending halfway to the time
at which the ratio, extrapolated linearly, would reach zero; so a singular configuration
is approached in geometrically shrinking steps and detected (ratio < singular_tol)
rather than stepped over.
"""
from __future__ import annotations

import time as _time

import numpy as np

from ...dae.augmented import AugmentedStepper, ode_eigenvalues
from ...dae.baumgarte import BaumgarteStepper
from ...dae.constrained_system import ConstrainedSystem
from ...dae.dae_run import FORMULATIONS, DaeRun, resolve_formulation
from ...dae.dof import dof_report, short_list, singular_ratio, singular_ratios
from ...dae.ggl import GGLStepper
from ...dae.init import initialize, start_jacobian
from ...dae.partitioning import PartitioningStepper
from ...dae.projection import ProjectionStepper
from ...dae.segments import NonFiniteError, StepError, interrupt_guard, locate_nonfinite
from ...diagnostics import UsageError
from ...eom import parameter_vector
from ...eom.start import fixed_start
from ...output.result import Failure, Result, RunInterrupted
from ..choose import choose_method
from ..functions import problem_functions
from ..monitors import energy_drift_stats, is_conservative
from ..record_dae import constrained_signals, multipliers, select_signals
from ..registry import dae_method
from ..settings import DEFAULT_POINTS
from . import Backend, compiled_setting


SINGULAR_WATCH = 1e-3      # start shortening segments once sigma ratio is below this
MONITOR_POINTS = 61       # the monitoring grid (drift, conditioning, projection), whatever the output points
MAX_RETRIES = 12           # halvings of a failing segment before giving up
FIRST_CHUNK = 8            # intervals of the first segment (ggl, partitioning: doubled after each full one)
BUDGET_MARGIN = 8.0        # a call may take this many times the steps per unit time seen before
MAX_CALLS = 100_000        # integrator calls per run: a bound on every loop of the driver
CHUNK = 64                 # most output intervals per integrator call (one integrator is built
                           # per segment length and kept with the system, so reruns reuse it)


FIRST_PERIODS = 50         # the first segment of an ODE formulation spans at most this many periods


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


def make_stepper(system, opts: DaeRun, t0, q0, qd0, span):
    f = opts.formulation
    if f == "baumgarte":
        return BaumgarteStepper(system, opts, span)
    if f == "projection":
        return ProjectionStepper(system, opts, span)
    if f == "ggl":
        return GGLStepper(system, opts, t0, q0, qd0)
    if f == "partitioning":
        return PartitioningStepper(system, opts)
    if f == "augmented":
        return AugmentedStepper(system, opts, span, t0, q0)
    raise UsageError(f"unknown formulation {f!r}")  # pragma: no cover (SegmentRun checks)


class DaeBackend(Backend):
    name = "dae"
    noun = "a DAE"
    groups = ("dae",)
    ignores = ("integrator_options",)

    def run(self, problem, progress, setup=None):
        compiled, note = compiled_setting(problem)
        r = SegmentRun(problem.eom, problem.settings, progress, compiled).run()
        if note:
            r.metadata.setdefault("notes", []).append(note)
        return r

    def integration(self, problem, setup, pv, xs):
        """The formulated problem's index-1 ODE (the multipliers solved: mechdsl.dae.functions)
        with the CasADi method the formulation's integrator runs the method as (auto: chosen from
        that ODE's Jacobian at the start, as for an ODE run)."""
        s, eom = problem.settings, problem.eom
        formulation = resolve_formulation(s.dae.formulation)
        funcs = problem_functions(eom, names=("ode", "ode_jacobian", "multipliers"))
        m = dae_method(s.method, formulation)
        if m == "auto":
            m, why, _ = choose_method(eom, funcs, xs, pv, s.t_start, s.t_end, s.rtol)
        else:
            m, why = DAE_AS_ODE[m], "requested"
        return m, funcs, f"the {formulation} formulation's index-1 ODE (multipliers solved), {m}: {why}"

    def start(self, problem, xs, pv, x0):
        """The consistent start (mechdsl.dae.init) and its linearization (``start_jacobian``)."""
        eom, t0 = problem.eom, problem.settings.t_start
        n = eom.n
        _, _, fq, fqd = fixed_start(eom, x0, pv)
        init = initialize(eom, xs[:n], xs[n:], t0, pv, fixed_q=fq, fixed_qd=fqd)
        Jx, Jp = start_jacobian(eom, init.q, init.qd, xs[n:], t0, pv, fq, fqd)
        return np.r_[init.q, init.qd], Jx, Jp

    def describe(self, r):
        f = r.metadata.get("formulation")
        m = (r.metadata.get("options") or {}).get("method")
        plugin = "casadi:idas" if f == "ggl" else ("casadi:erk" if m == "erk" else "casadi:cvodes")
        return {"formulation": f, "integrator": plugin, "method": m}


class SegmentRun:
    """One constrained run, in three steps: ``setup`` (consistent start, system, formulation,
    method), ``loop`` (the segments) and ``finish`` (signals, checks, Result).  Reads the
    validated settings: the common fields and the ``dae`` group (formulation, reactions,
    baumgarte, singular_tol, max_interval, drift_bound, ...)."""

    def __init__(self, eom, settings, progress=None, compiled: bool = False):
        self.eom, self.settings, self.progress = eom, settings, progress if callable(progress) else None
        formulation = resolve_formulation(settings.dae.formulation)
        if formulation not in FORMULATIONS:
            raise UsageError(f"unknown formulation {settings.dae.formulation!r} for a constrained model; choose one "
                             "of: auto, " + ", ".join(FORMULATIONS))
        self.opts = DaeRun(formulation=formulation, method=dae_method(settings.method, formulation),
                           rtol=settings.rtol, atol=settings.atol, max_steps=settings.max_steps,
                           compiled=bool(compiled), options=settings.dae)

    def run(self) -> Result:
        self.setup()
        self.loop()
        return self.finish()

    def setup(self) -> None:
        """Consistent start, degrees of freedom (redundant constraints dropped), the constrained
        system, the formulation's stepper and the method; the work estimate."""
        eom, s, opts = self.eom, self.settings, self.opts
        wall0 = _time.perf_counter()
        pv = parameter_vector(eom, s.p)
        t0, t_end = s.t_start, s.t_end
        points = s.points or DEFAULT_POINTS
        # the monitoring grid (drift, conditioning, projection, segment ends) does not depend on the
        # output grid: output times between its points are extra integrator output times only, so the
        # numbers at a time do not depend on how many points were asked for
        grid = np.linspace(t0, t_end, MONITOR_POINTS)
        out_t = np.linspace(t0, t_end, points)
        span = t_end - t0
        chosen, need_lam = select_signals(eom, s.outputs, s.dae.reactions)

        q0, qd0, fixed_q, fixed_qd = fixed_start(eom, s.x0, pv)
        init = initialize(eom, q0, qd0, t0, pv, fixed_q=fixed_q, fixed_qd=fixed_qd)
        dof = dof_report(eom, init.q, t0, pv)
        notes: list[str] = []
        if dof.redundant:
            notes.append(f"{dof.redundant} redundant constraint(s) dropped: {short_list(dof.redundant_names)} "
                         f"(rank of G is {dof.rank} of {dof.constraints}); their multipliers are reported as 0")
        system = ConstrainedSystem.build(eom, pv, dof.independent)
        system.fix_row_scale(init.q, t0)
        if opts.formulation == "partitioning" and dof.dof == 0:
            notes.append("no degrees of freedom: partitioning has nothing to integrate; using projection")
            opts.formulation = "projection"
        method_reason, ev = choose_dae_method(opts, system, init.q, init.qd, t0, span)
        too_much = work_failure(opts, system, ev, t0, span)
        stepper = make_stepper(system, opts, t0, init.q, init.qd, span)
        stepper.reset(t0, init.q, init.qd)
        setup_wall = _time.perf_counter() - wall0
        cpu0 = _time.process_time()
        self.wall0, self.setup_wall, self.cpu0, self.pv, self.points = wall0, setup_wall, cpu0, pv, points
        self.t0, self.t_end, self.span, self.grid, self.out_t = t0, t_end, span, grid, out_t
        self.chosen, self.need_lam, self.init, self.dof, self.notes = chosen, need_lam, init, dof, notes
        self.system, self.stepper, self.method_reason, self.too_much = system, stepper, method_reason, too_much

    def loop(self) -> None:
        """Advance segment by segment to each output time; after each segment the formulation's
        projection, the conditioning check of G and the drift measurement (module docstring)."""
        opts = self.opts
        system, stepper, too_much = self.system, self.stepper, self.too_much
        grid, out_t, t0, t_end, span = self.grid, self.out_t, self.t0, self.t_end, self.span
        T, Qs, QDs, D, VD = [], [], [], [], []
        events: list[dict] = []
        failure, failure_code = (too_much, CODE_INTEGRATOR) if too_much is not None else (None, None)
        rank = system.m

        def ratio_at(q, t):
            return singular_ratio(system.scaled_G(q, t), rank)

        def record(t, q, qd, dv=None):
            d, v = dv if dv is not None else system.drift(q, qd, t)
            T.append(t)
            Qs.append(q.copy())
            QDs.append(qd.copy())
            D.append(d)
            VD.append(v)

        record(t0, stepper.q, stepper.qd)
        j_out = 1              # next output time to record
        ratio_prev, t_prev = ratio_at(stepper.q, t0), t0
        min_ratio = ratio_prev
        seen_d, seen_v = 0.0, 0.0
        h_sing = np.inf
        k = 1
        retries = 0
        h_fail = np.inf
        # IDAS (ggl) and the partitioned CVODES with its Newton solves grind for minutes when a segment
        # runs into a singular configuration before they fail; they start with short segments and stop
        # each well before an extrapolated loss of rank. The explicit index-1 ODE fails fast there.
        cautious = opts.formulation in ("ggl", "partitioning")
        crossing = getattr(stepper, "crosses_singular", False)   # augmented: passes through singular configurations
        # step budget per integrator output interval (CasADi's max_num_steps): max_steps until a segment
        # succeeded (a model with absurd time scales then fails within seconds), afterwards also up to
        # BUDGET_MARGIN times the steps per unit time seen there (long monitoring intervals of long runs)
        chunk = FIRST_CHUNK if cautious else first_chunk(system, stepper, grid)
        density = None         # integrator steps per unit time of the last successful segment
        tau_pred = np.inf      # time until the singular ratio reaches 0, extrapolated from the last decrease
        tiny = 1e-13 * max(abs(t_end), span)
        interrupted = False
        guard = interrupt_guard()
        guard.__enter__()
        try:
            calls = 0
            while k < len(grid) and failure is None:
                calls += 1
                if calls > MAX_CALLS:
                    failure, failure_code = Failure(stepper.t, f"{opts.formulation} integrator failed",
                                                    f"[{CODE_INTEGRATOR}] the run needed more than {MAX_CALLS} integrator "
                                                    "calls (segments shortened near a singular configuration or after "
                                                    "failures without end)"), CODE_INTEGRATOR
                    if stepper.t > T[-1]:
                        record(stepper.t, stepper.q, stepper.qd)
                    break
                single = np.isfinite(h_sing) or np.isfinite(h_fail) or chunk == 1
                if single:
                    target = grid[k]
                    h = min(target - stepper.t, opts.max_interval or np.inf, h_sing, h_fail)
                    times = np.array([target if stepper.t + h >= target - tiny else stepper.t + h])
                else:
                    K = min(chunk, len(grid) - k)     # the tail in one segment (integrators are cached per K)
                    # a segment stops well before an extrapolated loss of rank: an integrator driven into a
                    # singular configuration grinds (IDAS: minutes) before it fails
                    if cautious and np.isfinite(tau_pred):
                        K = max(1, min(K, int(0.5 * tau_pred / (grid[1] - grid[0]))))
                    if opts.max_interval:
                        K = max(1, min(K, int((opts.max_interval + tiny) // (grid[1] - grid[0]))))
                    times = grid[k:k + K]
                    if opts.max_interval and times[-1] - stepper.t > opts.max_interval + tiny:
                        times = np.array([stepper.t + opts.max_interval])
                saved = (stepper.t, stepper.q.copy(), stepper.qd.copy())
                times, is_mon = with_outputs(times, out_t[j_out:], stepper.t, tiny)
                H = float(times[-1] - stepper.t)
                budget = opts.steps
                if density is not None:
                    budget = max(budget, int(np.ceil(BUDGET_MARGIN * density * H / max(1, int(np.sum(is_mon))))))
                stepper.step_budget = budget if budget > opts.steps else None     # None: max_steps exactly
                steps_before = stepper.stats.get("nsteps", 0)
                try:
                    try:
                        T_acc, Q_acc, QD_acc = stepper.advance(times, is_mon)
                    except np.linalg.LinAlgError as la:   # degenerate linear algebra: a failed segment, retried
                        raise StepError(f"linear algebra failed in the {opts.formulation} step ({la})") from None
                except StepError as e:
                    stepper.reset(*saved)
                    if getattr(e, "stats", None):     # a failed call's work counts too
                        stepper.count_stats(e.stats)
                    if int(np.sum(is_mon)) > 1:     # retry the chunk one monitoring interval at a time
                        chunk = 1
                        continue
                    if hasattr(stepper, "recover_from_failure") and retries == 0 and stepper.recover_from_failure():
                        retries += 1
                        continue
                    retries += 1
                    h_fail = (times[-1] - saved[0]) / 2
                    r_now = ratio_at(saved[1], saved[0])
                    near_singular = r_now < 100 * opts.singular_tol
                    if retries > MAX_RETRIES or h_fail < tiny or near_singular:
                        # (near a singular configuration, halving the step only makes the solver retry
                        # ever more ill-conditioned systems: stop at once)
                        if near_singular or (r_now < ratio_prev and r_now < 10 * SINGULAR_WATCH):
                            failure = Failure(saved[0], "singular configuration",
                                              f"the constraint Jacobian is losing rank (sigma_min/sigma_max = {r_now:.2e}) "
                                              f"and the {opts.formulation} integrator failed: {e}")
                        else:
                            failure, failure_code = integrator_failure(system, opts, saved, times[-1] - saved[0], e)
                        if saved[0] > T[-1]:        # keep the last good state (between output times)
                            record(*saved)
                    continue
                retries = 0
                h_fail = np.inf
                density = (stepper.stats.get("nsteps", 0) - steps_before) / H
                if self.progress is not None:
                    self.progress(float(T_acc[-1]), t_end)
                n_mon = int(np.sum(is_mon[:len(T_acc)]))
                if not single:
                    chunk = min(CHUNK, 2 * chunk) if len(T_acc) == len(times) else max(1, n_mon)
                elif chunk == 1 and not np.isfinite(h_sing):
                    chunk = 2
                d_all, v_all, Gs_all = system.monitor_many(Q_acc, QD_acc, T_acc)   # one call per segment
                ratios = singular_ratios(Gs_all, rank)
                for i in range(len(T_acc)):
                    t_now, q_now, qd_now = float(T_acc[i]), Q_acc[i], QD_acc[i]
                    d_now, v_now, ratio = float(d_all[i]), float(v_all[i]), float(ratios[i])
                    is_output = j_out < len(out_t) and abs(t_now - out_t[j_out]) <= tiny
                    if not is_mon[i]:       # an output time between checks: recorded, never acted upon
                        min_ratio = min(min_ratio, ratio)
                        if crossing:        # (augmented: passages are reported from every state seen)
                            stepper.watch(t_now, ratio)
                        if is_output:
                            record(t_now, *stepper.for_record(t_now, q_now, qd_now))
                            j_out += 1
                        continue
                    min_ratio = min(min_ratio, ratio)
                    seen_d, seen_v = max(seen_d, d_now), max(seen_v, v_now)
                    on_grid = abs(t_now - grid[k]) <= tiny
                    if ratio < opts.singular_tol and not crossing:
                        events.append({"time": t_now, "kind": "singular", "contact": "-",
                                       "detail": f"sigma_min/sigma_max of the scaled constraint Jacobian = {ratio:.2e}"})
                        failure = Failure(t_now, "singular configuration",
                                          f"the constraint Jacobian lost rank (sigma_min/sigma_max = {ratio:.2e} < "
                                          f"singular_tol = {opts.singular_tol:g}); the motion past this point is not "
                                          "determined by the equations (a dead point or change point of the mechanism)")
                        record(t_now, q_now, qd_now, (d_now, v_now))
                        break
                    h_sing = np.inf
                    if t_now > t_prev:
                        tau_pred = np.inf
                    if ratio < ratio_prev and t_now > t_prev and not crossing:
                        tau = ratio / ((ratio_prev - ratio) / (t_now - t_prev))   # linear extrapolation to 0
                        tau_pred = tau
                        if ratio < SINGULAR_WATCH or tau < 2 * (grid[1] - grid[0]):
                            h_sing = max(0.5 * tau, 1e3 * tiny)
                    ratio_prev, t_prev = ratio, t_now
                    if crossing:
                        stepper.watch(t_now, ratio)
                    if is_output:
                        record(t_now, q_now, qd_now, (d_now, v_now))
                        j_out += 1
                    if on_grid:
                        k += 1
                    if np.isfinite(h_sing) and i < len(T_acc) - 1:
                        # approaching a singular configuration: rewind to here, continue in short segments
                        stepper.reset(t_now, q_now, qd_now)
                        break
        except KeyboardInterrupt:      # Ctrl-C: stop now, keep what was recorded, raise it below
            interrupted = True
            n_rec = min(map(len, (T, Qs, QDs, D, VD)))      # a record() cut short in the middle
            del T[n_rec:], Qs[n_rec:], QDs[n_rec:], D[n_rec:], VD[n_rec:]
            failure = Failure(T[-1], "interrupted", "the run was interrupted (Ctrl-C); results up to here are kept")
        finally:
            guard.__exit__(None, None, None)
        self.T, self.Qs, self.QDs, self.D, self.VD = T, Qs, QDs, D, VD      # the recorded states and drift
        self.events, self.failure, self.failure_code, self.interrupted = events, failure, failure_code, interrupted
        self.min_ratio, self.seen_d, self.seen_v = min_ratio, seen_d, seen_v

    def finish(self) -> Result:
        """Outputs, multipliers and reactions at the output times, drift and energy checks,
        statistics and metadata: the Result (RunInterrupted after Ctrl-C, carrying it)."""
        eom, s, opts = self.eom, self.settings, self.opts
        wall0, setup_wall, cpu0, pv, points = self.wall0, self.setup_wall, self.cpu0, self.pv, self.points
        t0, t_end, chosen, need_lam, init, dof = self.t0, self.t_end, self.chosen, self.need_lam, self.init, self.dof
        notes, system, stepper, method_reason = self.notes, self.system, self.stepper, self.method_reason
        T, Qs, QDs, D, VD = self.T, self.Qs, self.QDs, self.D, self.VD
        events, failure, failure_code, interrupted = self.events, self.failure, self.failure_code, self.interrupted
        min_ratio, seen_d, seen_v = self.min_ratio, self.seen_d, self.seen_v
        solve_cpu = _time.process_time() - cpu0 - stepper.stats.get("build_cpu_time", 0.0)
        t = np.array(T)
        Q = np.array(Qs).reshape(len(T), eom.n)
        QD = np.array(QDs).reshape(len(T), eom.n)
        LAM = multipliers(system, t, Q, QD) if need_lam else None
        signals = constrained_signals(eom, chosen, t, Q, QD, LAM, pv, drift=(D, VD))

        energy = energy_check(eom, signals, opts, failure is None)
        bound = opts.bound
        # maxima over every checked state (the monitoring grid), not only the recorded ones
        max_d = max(float(np.max(D)) if D else 0.0, seen_d)
        max_v = max(float(np.max(VD)) if VD else 0.0, seen_v)
        drift_ok = max_d <= bound and max_v <= bound
        stats = dict(stepper.stats)
        stats.update({"max_constraint_drift": max_d, "max_velocity_drift": max_v, "drift_bound": bound,
                      "drift_ok": drift_ok, "min_singular_ratio": float(min_ratio),
                      "wall_time": _time.perf_counter() - wall0, "setup_wall_time": setup_wall,
                      "solve_cpu_time": solve_cpu})
        stats.update(common_stats(stats, energy))
        metadata = {"model": eom.name, "formulation": opts.formulation,
                    "formulation_reason": "requested" if s.dae.formulation != "auto" else
                    "default: index-1 ODE with Baumgarte terms and projection onto both constraint manifolds "
                    "after every segment",
                    "method": _method_name(opts), "method_reason": method_reason, "rtol": opts.rtol, "atol": opts.atol, "points": points,
                    "t_start": t0, "t_end": t_end, "initialization": init.as_dict(), "dof": dof.as_dict(),
                    "constraints": list(eom.constraint_names), "active_constraints": list(system.names),
                    "notes": notes + stepper.notes,
                    "compiled": bool(getattr(getattr(stepper, "F", None), "compiled", False)),
                    "kkt_route": system.route}
        if opts.compiled and not metadata["compiled"] and not any("compiled" in n for n in metadata["notes"]):
            metadata["notes"].append(f"compiled code is not available for formulation {opts.formulation!r}; "
                                     "it runs in the virtual machine")
        metadata["options"] = {"t_start": t0, "t_end": t_end, "rtol": opts.rtol, "atol": opts.atol, "points": points,
                               "formulation": opts.formulation, "method": opts.method, "reactions": s.dae.reactions,
                               "outputs": list(s.outputs) if s.outputs is not None else None,
                               "parameters": dict(zip(eom.params, map(float, pv))),
                               "start": {**dict(zip(eom.coords, map(float, init.q))),
                                         **{f"der({c})": float(v) for c, v in zip(eom.coords, init.qd)}}}
        metadata["warnings"] = []
        if failure_code:
            metadata["failure_code"] = failure_code
        if not drift_ok:
            msg = (f"constraint drift exceeded the bound {bound:.1e}: max ||g|| = {max_d:.2e}, "
                   f"max ||G q' + g_t|| = {max_v:.2e} (formulation {opts.formulation}); "
                   "tighten atol or use formulation = \"projection\"")
            metadata["drift_warning"] = msg
            metadata["warnings"].append(msg)
        if energy.get("energy_warning"):
            msg = energy["energy_warning"]
            metadata["energy_warning"] = msg
            metadata["warnings"].append(msg)
        metadata["conservative"] = energy.get("conservative")
        events = sorted(getattr(stepper, "events", []) + events, key=lambda e: e["time"])
        result = Result(t=t, q=Q, qd=QD, coordinates=tuple(eom.coords), signals=signals, stats=stats,
                        metadata=metadata, events=events, failure=failure)
        if interrupted:
            metadata["interrupted"] = True
            raise RunInterrupted(result)
        return result


CODE_INTEGRATOR = "E824"    # the integrator gave up (step budget, step size collapse, Newton)
CODE_NONFINITE = "E825"     # the equations or the state became inf/nan


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


ENERGY_FACTOR = 1e4     # a conservative model whose relative energy drift exceeds this many rtol warns
ENERGY_FLOOR = 1e-6      # ... and never below this relative drift
ENERGY_CAP = 0.05        # ... and always above this one (a loose tolerance does not excuse 80 %)


def energy_check(eom, signals, opts: DaeRun, complete: bool) -> dict:
    """Energy drift of the recorded states; for a conservative model (no damping, no other
    generalized forces, no explicit time in T, V or the constraints) a drift far above the
    tolerance means a wrong answer (e.g. a jump to another assembly branch), so it warns."""
    import casadi as ca

    out = dict(energy_drift_stats(signals))

    def conservative():
        try:
            return bool(is_conservative(eom)) and not ca.depends_on(ca.SX(eom.g), eom.t)
        except Exception:  # noqa: BLE001 -- a non-SX model: make no claim
            return None

    cons = eom.workspace.memo("dae_conservative", conservative)
    out["conservative"] = cons
    if cons and "energy_drift_relative" in out:
        limit = min(ENERGY_CAP, max(ENERGY_FLOOR, ENERGY_FACTOR * opts.rtol))
        out["energy_bound_relative"] = limit
        if out["energy_drift_relative"] > limit:
            out["energy_warning"] = (
                f"the model is conservative but its energy changed by {out['energy_drift']:.3g} "
                f"(relative {out['energy_drift_relative']:.2e}, more than {limit:.1e} = "
                f"min({ENERGY_CAP:g}, max({ENERGY_FLOOR:g}, {ENERGY_FACTOR:g} rtol))): the results are not to be "
                "trusted; "
                f"tighten rtol/atol or use formulation = \"projection\" (formulation {opts.formulation})")
    return out


def common_stats(st: dict, energy: dict) -> dict:
    """The statistics under the names every simulator uses (steps, rhs_evals, jacobian_evals,
    rejected_steps, cpu_time, energy_drift, constraint_drift)."""
    out = {"steps": int(st.get("nsteps", 0)), "rhs_evals": int(st.get("nfevals", 0)),
           # CVODES/IDAS: linear-solver setups (each evaluates the Jacobian); erk: none
           "jacobian_evals": int(st.get("nlinsetups", 0)),
           "jac_evals": int(st.get("nlinsetups", 0)),          # the simulation layer's name (SCHEMA)
           "rejected_steps": int(st.get("netfails", 0)) + int(st.get("nncfails", 0)),
           "cpu_time": float(st.get("solve_cpu_time", 0.0)),
           "constraint_drift": float(st.get("max_constraint_drift", 0.0))}
    for k in ("energy_drift", "energy_drift_relative", "energy_bound_relative"):
        if k in energy:
            out[k] = energy[k]
    out["energy_ok"] = "energy_warning" not in energy
    return out


# the ODE method a constrained run's method name runs as (registry.dae_method's names)
DAE_AS_ODE = {"bdf": "cvodes-bdf", "adams": "cvodes-adams", "erk": "erk", "idas": "idas"}
STIFF = 1e4   # an overdamped mode decaying this many times within the run makes 'auto' pick BDF


def choose_dae_method(opts: DaeRun, system, q, qd, t0, span) -> tuple[str, np.ndarray | None]:
    """Replace method 'auto' by a concrete one; return why, and the eigenvalues of the
    ODE's Jacobian at the start when the choice computed them (None otherwise)."""
    if opts.formulation == "ggl":
        opts.method = "idas"
        return "IDAS is the solver of the GGL formulation", None
    if opts.method == "cvodes":
        opts.method = "bdf"
    if opts.method != "auto":
        return "requested", None
    if opts.formulation == "partitioning":
        opts.method = "bdf"
        return ("auto: the partitioned ODE solves for the dependent coordinates by Newton's method inside its "
                "right-hand side; CVODES BDF takes the fewest right-hand-side evaluations there"), None
    if opts.formulation == "augmented":      # its own ODE (the KKT route's Jacobian can take seconds to build)

        ev = ode_eigenvalues(system, q, qd, t0)
    else:
        ev = system.eigenvalues(q, qd, t0)
    damped = [-z.real for z in ev if z.real < 0 and -z.real > abs(z.imag)]
    rate = max(damped, default=0.0)
    if rate * span > STIFF:
        opts.method = "bdf"
        return (f"auto: stiff (an overdamped mode decays at {rate:.3g}/s, {rate * span:.3g} times the run "
                "length); BDF"), ev
    opts.method = "erk"
    return (f"auto: not stiff (fastest overdamped rate {rate:.3g}/s over a {span:g} s run); the explicit "
            "Runge-Kutta 5(4) needs no Jacobian and was 2-10x faster than Adams on the shipped constrained "
            "models (docs/performance.md)"), ev


WORK_BUDGET = 1e7     # coordinate-steps (steps x (n + m)) a constrained run may be estimated to need
# steps a period of an oscillation take at rtol: c rtol^(-1/order), lower bounds as in impacts/one_step.py
PERIOD_STEPS = {"erk": (5, 1.0), "bdf": (5, 2.0), "adams": (12, 5.0)}


def work_failure(opts: DaeRun, system, ev, t0: float, span: float) -> Failure | None:
    """A run that must take more integrator steps than WORK_BUDGET / (n + m) fails at its start,
    naming the time scale, instead of grinding (nfourbar's A02 scene with rods of 1e-12 m and
    1e-12 kg did not return in 300 s for 0.0001 s: CVODES BDF on 41 coordinates and 200
    constraints, each step with a Jacobian).  The estimate uses the eigenvalues the method choice
    computed (method auto; none otherwise): the fastest oscillation (largest imaginary part;
    for the explicit erk also the largest modulus, its stability limit) makes rho span / (2 pi)
    periods of at least c rtol^(-1/order) steps each (PERIOD_STEPS, measured lower bounds)."""
    if ev is None or not len(ev):
        return None
    order, c = PERIOD_STEPS.get(opts.method, (5, 1.0))
    rho = float(np.max(np.abs(ev if opts.method == "erk" else ev.imag), initial=0.0))
    per_period = max(1.0, c * opts.rtol ** (-1.0 / order))
    need = rho * span / (2 * np.pi) * per_period
    size = system.n + system.m
    budget = WORK_BUDGET / max(1, size)
    if need <= budget:
        return None
    return Failure(t0, "too many steps needed",
                   f"[{CODE_INTEGRATOR}] the model's fastest motion at the start has a time scale of {1 / rho:.3g} s "
                   f"(rate {rho:.3g} 1/s): following it for {span:g} s takes about {need:.3g} steps ({per_period:.3g} "
                   f"a period with {opts.method} at rtol {opts.rtol:g}), over the budget of {budget:.3g} steps for "
                   f"{system.n} coordinates and {system.m} constraints ({WORK_BUDGET:g} / (n + m)); check the "
                   "sizes and stiffnesses (a tiny length or a huge spring), or shorten the run")


def _method_name(opts: DaeRun) -> str:
    if opts.formulation == "ggl":
        return "IDAS (variable-order BDF), algebraic variables excluded from the error test"
    if opts.method == "erk":
        return "CasADi erk (explicit Runge-Kutta 5(4))"
    return "CVODES " + ("Adams" if opts.method == "adams" else "BDF")
