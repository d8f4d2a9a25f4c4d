"""The DAE back end: the segment loop shared by every formulation (``SegmentRun``).

    initialize (consistent start, changes reported)
    -> count degrees of freedom, drop redundant constraints (independent subset)
    -> build the formulation's stepper
    -> advance segment by segment to each output time, after each segment:
         projection / re-partitioning (the formulation's hook),
         conditioning check of G (singular configuration -> stop, report the time),
         drift measurement (||g||, ||G q' + g_t||)
    -> outputs, multipliers and reactions at the output times -> Result

Chunks (the loop: dae_loop.SegmentLoop).  One integrator call covers up to CHUNK monitoring intervals (the integrator returns
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
from ...dae.dof import dof_report, short_list
from ...dae.ggl import GGLStepper
from ...dae.init import initialize, start_jacobian
from ...dae.partitioning import PartitioningStepper
from ...dae.projection import ProjectionStepper
from ...diagnostics import UsageError
from ...eom import parameter_vector
from ...eom.start import fixed_start
from ...output.result import Failure, Result
from ..accuracy import DRIFT_CAP, DRIFT_FACTOR, drift_limit
from ..choose import choose_method
from ..functions import problem_functions
from ..monitors import energy_drift_stats, is_conservative
from ..record_dae import constrained_signals, multipliers, select_signals
from ..registry import dae_method
from ..settings import DEFAULT_POINTS
from . import Backend, compiled_setting
from .dae_loop import CODE_INTEGRATOR, MONITOR_POINTS, SegmentLoop


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
        """Advance segment by segment to each output time (``SegmentLoop``); keeps what it recorded."""
        lp = SegmentLoop(self.opts, self.system, self.stepper, self.grid, self.out_t, self.t0, self.t_end,
                         self.span, self.too_much, self.progress)
        lp.run()
        self.T, self.Qs, self.QDs, self.D, self.VD = lp.T, lp.Qs, lp.QDs, lp.D, lp.VD   # the recorded states and drift
        self.events, self.failure, self.failure_code, self.interrupted = lp.events, lp.failure, lp.failure_code, lp.interrupted
        self.min_ratio, self.seen_d, self.seen_v = lp.min_ratio, lp.seen_d, lp.seen_v

    def finish(self) -> Result:
        """Outputs, multipliers and reactions at the output times, drift and energy checks,
        statistics and metadata: the Result (after Ctrl-C the rows recorded, metadata["interrupted"])."""
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
                   f"max ||G q' + g_t|| = {max_v:.2e} (formulation {opts.formulation}); tighten atol"
                   + ("" if opts.formulation == "projection" else " or use formulation = \"projection\""))
            metadata["drift_warning"] = msg
            metadata["warnings"].append(msg)
        if energy.get("energy_warning"):           # warned once, by the run's accuracy warning
            metadata["energy_warning"] = energy["energy_warning"]
        metadata["conservative"] = energy.get("conservative")
        events = sorted(getattr(stepper, "events", []) + events, key=lambda e: e["time"])
        result = Result(t=t, q=Q, qd=QD, coordinates=tuple(eom.coords), signals=signals, stats=stats,
                        metadata=metadata, events=events, failure=failure)
        if interrupted:
            metadata["interrupted"] = True      # (the template raises RunInterrupted with it)
        return result


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
        limit = drift_limit(opts.rtol)          # the one rule of every run (simulation/accuracy.py)
        out["energy_bound_relative"] = limit
        if out["energy_drift_relative"] > limit and out["energy_drift"] > DRIFT_FACTOR * opts.atol:
            out["energy_warning"] = (
                f"the model is conservative but its energy changed by {out['energy_drift']:.3g} "
                f"(relative {out['energy_drift_relative']:.2e}, more than {limit:.1e} = "
                f"min({DRIFT_CAP:g}, {DRIFT_FACTOR:g} rtol)); tighten rtol/atol"
                + ("" if opts.formulation == "projection" else
                   f" or use formulation = \"projection\" (formulation {opts.formulation})"))
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
