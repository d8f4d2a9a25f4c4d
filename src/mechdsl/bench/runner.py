"""The benchmark loop: every variant over the tolerance sweep, measured against a reference.

    setup = Setup.from_model(mechdsl.load(path, scene=...), t_end=..., points=...)
    res = run_bench(setup, variants=parse_variants("erk,cvodes-bdf"), tolerances=[1e-4, 1e-8])

Each (variant, tolerance) is one Row.  A run that fails is a Row with status "failed" (its
cause and time in ``message``), a combination the simulator refuses (e.g. a formulation on
an ODE model) a Row with status "n/a", an exception a Row with status "error", and a
tolerance left out because the previous one of the same variant exceeded the time budget a
Row with status "skipped": nothing is dropped.
"""
from __future__ import annotations

import math
import platform
import warnings
from dataclasses import dataclass, field
from typing import Any, Callable

import numpy as np

from ..diagnostics import MechError, Span, UsageError
from . import measure, reference as R
from .index1 import FORMULATION as INDEX1
from .spec import SYMPLECTIC_ORDER, Variant, parse_variant
from .timing import LONG, TIMER, OverBudget, cpu_call, timed

DEFAULT_POINTS = 101
DEFAULT_BUDGET = 30.0      # CPU seconds: a run longer than this ends the variant's sweep
DEFAULT_T_END = 10.0       # s: without a scene stop time, as mech simulate


@dataclass(kw_only=True)
class Setup:
    """The model and everything fixed across the runs of a benchmark."""

    eom: Any
    t_end: float
    t_start: float = 0.0
    points: int = DEFAULT_POINTS
    p: Any = None                      # parameter vector or {name: value}
    x0: Any = None                     # start overrides ({name: value}) or full state
    compiled: bool = False
    name: str = ""
    scene: str | None = None
    source: str | None = None
    default_formulation: str | None = None     # the scene's formulation (constrained models)
    span: Span | None = None                   # the scene's (else the model's) declaration: where errors point
    notes: list[str] = field(default_factory=list)     # how the settings were chosen (printed, kept in the JSON)

    @classmethod
    def from_model(cls, model, *, t_end=None, t_start=None, points=None, x0=None, compiled=False,
                   source=None) -> "Setup":
        """From a mechdsl.api.Model (scene settings fill what is not given).  The end time
        follows mech simulate: the given one, else the scene's stop time, else DEFAULT_T_END."""
        s = dict(getattr(model, "scene_settings", None) or {})
        notes = []
        t_end = t_end if t_end is not None else s.get("stop_time")
        if t_end is None:
            t_end = DEFAULT_T_END
            notes.append(f"no --t-end and no scene stop_time: t_end = {DEFAULT_T_END:g} s, as for mech simulate")
        scene = getattr(model, "scene", None)
        span = getattr(scene, "span", None) or getattr(getattr(model, "model", None), "span", None)
        return cls(eom=model.eom, t_end=float(t_end),
                   t_start=float(t_start if t_start is not None else s.get("start_time", 0.0)),
                   points=int(points or s.get("points") or DEFAULT_POINTS), p=model.parameter_values, x0=x0,
                   compiled=bool(compiled or s.get("compiled", False)), name=model.name,
                   scene=getattr(scene, "name", None), source=source,
                   default_formulation=s.get("formulation"), span=span, notes=notes)

    @property
    def constrained(self) -> bool:
        return self.eom.g is not None


@dataclass(kw_only=True)
class Row:
    label: str
    method: str
    formulation: str | None = None
    tolerance: float | None = None
    dt: float | None = None
    status: str = "ok"                 # ok | failed | n/a | error | skipped
    message: str = ""
    cpu: float | None = None           # best CPU time [s]
    cpu_runs: tuple[float, ...] = ()
    cpu_warmup: float | None = None
    err_final: float | None = None
    err_l2: float | None = None
    invariants: dict[str, float] = field(default_factory=dict)
    steps: int | None = None
    rhs_evals: int | None = None
    t_reached: float | None = None
    ran: str | None = None             # the method that ran (what auto chose)

    @property
    def ok(self) -> bool:
        return self.status == "ok"


@dataclass(kw_only=True)
class BenchResult:
    setup: Setup
    columns: tuple[str, ...]
    reference: R.Reference
    rows: list[Row]
    tolerances: tuple[float, ...]
    repeats: int
    kind: str                          # ode | stiff | dae
    timer: str = TIMER
    machine: dict[str, Any] = field(default_factory=dict)
    interrupted: bool = False          # Ctrl-C: the rows not measured are 'skipped'

    def variants(self) -> list[str]:
        seen: list[str] = []
        for r in self.rows:
            if r.label not in seen:
                seen.append(r.label)
        return seen

    def rows_of(self, label: str) -> list[Row]:
        return [r for r in self.rows if r.label == label]


# --------------------------------------------------------------------------- columns


def compare_columns(eom, compare) -> tuple[str, ...]:
    """'positions' (the coordinates), 'states' (and their speeds) or a list of names."""
    if compare in (None, "positions"):
        return tuple(eom.coords)
    if compare == "states":
        return tuple(eom.coords) + tuple(f"der({c})" for c in eom.coords)
    names = [c.strip() for c in (compare.split(",") if isinstance(compare, str) else compare) if c.strip()]
    if not names:
        raise UsageError("--compare needs 'positions', 'states' or a list of names")
    known = (list(eom.coords) + [f"der({c})" for c in eom.coords] + list(eom.outputs)
             + ["kinetic_energy", "potential_energy", "energy"])
    for n in names:
        if n not in known:
            from ..diagnostics import did_you_mean

            hint = did_you_mean(n, known)
            raise UsageError(f"cannot compare {n!r}: not a coordinate, speed or output of {eom.name}"
                             + (f"; {hint}" if hint else ""))
    return tuple(names)


def _outputs_for(eom, columns) -> tuple[str, ...]:
    return tuple(c for c in columns if c in eom.outputs)


# --------------------------------------------------------------------------- one run


def classify_setup(setup: Setup) -> str:
    eom = setup.eom
    if eom.g is not None:
        return "dae"
    if eom.n == 0:
        return "ode"
    from ..eom.codegen import casadi_functions
    from ..eom import parameter_vector
    from ..simulation.choose import choose_method
    from ..eom.start import start_vector

    pv = parameter_vector(eom, setup.p)
    xs = start_vector(eom, setup.x0, pv)
    method, _, _ = choose_method(eom, casadi_functions(eom, names=("ode", "ode_jacobian")), xs, pv,
                                 setup.t_start, setup.t_end, 1e-8)
    return "stiff" if method == "cvodes-bdf" else "ode"


def symplectic_dt(setup: Setup, method: str, tol: float, points: int) -> float:
    """Fixed step of a symplectic method at tolerance ``tol``: the rule the simulator uses for
    its fixed-step methods, h omega = 0.5 tol^(1/order) (docs/simulate.md), with the
    method's order; then shortened so that a whole number of steps falls in every output
    interval (the recorded times are then the output grid)."""
    from ..eom.codegen import casadi_functions
    from ..eom import parameter_vector
    from ..simulation.choose import fixed_step_count
    from ..eom.start import start_vector

    order = SYMPLECTIC_ORDER[method]
    eom = setup.eom
    pv = parameter_vector(eom, setup.p)
    xs = start_vector(eom, setup.x0, pv)
    # fixed_step_count's rule is for order 4 ("rk"): tol^(4/order) gives h omega = 0.5 tol^(1/order)
    steps, _ = fixed_step_count("rk", casadi_functions(eom, names=("ode", "ode_jacobian")), xs, pv,
                                setup.t_start, setup.t_end, tol ** (4.0 / order), None)
    per = max(1, math.ceil(steps / (points - 1)))
    return (setup.t_end - setup.t_start) / (per * (points - 1))


def simulate_variant(setup: Setup, variant: Variant, tol: float | None, points: int, outputs, dt=None,
                     stop_after: float | None = None):
    """One run; ``stop_after``: CPU seconds after which it is stopped (timing.OverBudget)
    where the simulator reports progress."""
    from ..simulate import simulate
    from .timing import cpu_cap

    kw = variant.kwargs
    if stop_after is not None:
        kw["progress"] = cpu_cap(stop_after)
    if variant.formulation is None and setup.constrained and setup.default_formulation:
        kw["formulation"] = setup.default_formulation
    if dt is not None:
        kw["dt"] = dt
    if setup.compiled:
        kw["compiled"] = True
    tol = 1e-8 if tol is None else tol
    common = dict(t_start=setup.t_start, rtol=tol, atol=tol, method=variant.method, points=points, outputs=outputs,
                  x0=setup.x0, p=setup.p, error_estimate="off", warn=False)   # timed: the run alone
    with warnings.catch_warnings():        # the Result's metadata keeps the simulator's warnings
        warnings.simplefilter("ignore")
        if kw.get("formulation") == INDEX1:
            from .index1 import simulate_index1

            kw.pop("formulation")
            return simulate_index1(setup.eom, setup.t_end, **common, **kw)
        return simulate(setup.eom, setup.t_end, **common, **kw)


def _stat(st: dict, *keys):
    for k in keys:
        v = st.get(k)
        if v is not None:
            try:
                return int(v)
            except (TypeError, ValueError):
                return None
    return None


def measure_run(setup: Setup, variant: Variant, tol, points, rows_idx, ref: R.Reference, columns,
                repeats: int, conservative, stop_after: float | None = None, *, rerun: list | None = None) -> Row:
    """One row: a warm-up run, ``repeats`` timed runs, the error against the reference.
    ``rerun``: a list that gets (row, the timed run) of a successful row, for more timed runs
    interleaved with the other variants' (run_bench)."""
    row = Row(label=variant.label, method=variant.method, formulation=variant.formulation, tolerance=tol)
    outputs = _outputs_for(setup.eom, columns)
    dt = variant.fixed_dt
    if variant.formulation is not None and not setup.constrained:
        row.status = "n/a"
        row.message = f"formulation {variant.formulation!r}: the model has no constraints (formulations apply to DAEs)"
        return row
    try:
        if dt is None and variant.method in SYMPLECTIC_ORDER:
            dt = symplectic_dt(setup, variant.method, tol, points)
        row.dt = dt

        def once():
            return simulate_variant(setup, variant, tol, points, outputs, dt, stop_after)

        tm = timed(once, repeats, ok=lambda r: r.success)
    except OverBudget as e:
        row.status, row.message = "skipped", f"{e} (a run is stopped after {stop_after:g} s)"
        row.cpu, row.t_reached = e.cpu, e.t
        return row
    except UsageError as e:
        row.status, row.message = "n/a", str(e)
        return row
    except MechError as e:
        row.status, row.message = "error", str(e)
        return row
    except Exception as e:  # noqa: BLE001 - a benchmark reports, it does not crash
        row.status, row.message = "error", f"{type(e).__name__}: {e}"
        return row
    r = tm.result
    row.cpu, row.cpu_runs, row.cpu_warmup = tm.best, tm.runs, tm.warmup
    row.ran = (r.metadata or {}).get("method")
    st = r.stats or {}
    row.steps = _stat(st, "steps", "nsteps")
    row.rhs_evals = _stat(st, "rhs_evals", "rhs_evaluations", "nfevals")
    if (r.metadata or {}).get("fixed_steps"):
        # rk/collocation: the plan, not the back end's counter (which CasADi accumulates over
        # calls of a cached integrator)
        n = r.metadata["fixed_steps"].get("target_steps")
        if n:
            row.steps = int(n)
            row.dt = row.dt or (setup.t_end - setup.t_start) / n
    row.t_reached = float(r.t[-1]) if len(r.t) else None
    row.invariants = measure.invariants(r, conservative)
    if not r.success:
        row.status = "failed"
        row.message = f"t = {r.failure.time:.6g}: {r.failure.cause}" + (f" ({r.failure.detail})" if r.failure.detail
                                                                        else "")
        return row
    if len(r.t) != points:
        row.status, row.message = "error", f"the run returned {len(r.t)} output points, not {points}"
        return row
    try:
        Y = measure.extract(r, columns, rows_idx)
    except KeyError as e:
        row.status, row.message = "error", str(e)
        return row
    Rv = np.column_stack([ref.values[c] for c in columns])
    e = measure.errors(Y, Rv, measure.component_scales(ref.values, columns))
    row.err_final, row.err_l2 = e["final"], e["l2"]
    if rerun is not None and tm.warmup <= LONG:
        rerun.append((row, once))
    return row


# --------------------------------------------------------------------------- the sweep


def make_reference(setup: Setup, reference, columns, tolerances, kind, reference_methods=None,
                   log: Callable[[str], None] | None = None) -> tuple[R.Reference, int, np.ndarray]:
    """The reference, the number of output points and the reference rows' grid indices."""
    if reference not in (None, "auto"):
        ref = reference if isinstance(reference, R.Reference) else R.read_csv(reference)
        R.check_columns(ref, columns)
        T = float(ref.t[-1])
        if abs(T - setup.t_end) > 1e-9 * max(1.0, abs(T)):
            raise UsageError(f"the reference ends at t = {T:g}, the benchmark at {setup.t_end:g} (set --t-end {T:g})")
        points, idx = ref.grid_points(setup.t_start)
        return ref, points, idx
    if reference_methods is not None and len(reference_methods) != 2:
        raise UsageError("--reference-methods takes two methods: the reference and its check")
    tol = R.reference_tolerance(tolerances)
    points = setup.points
    idx = np.arange(points)
    outputs = _outputs_for(setup.eom, columns)
    given = reference_methods is not None

    def attempt(lab, t):
        v = parse_variant(lab)
        if log:
            log(f"reference: {lab} at tolerance {t:g}")
        dt = v.fixed_dt
        if dt is None and v.method in SYMPLECTIC_ORDER:
            dt = symplectic_dt(setup, v.method, t, points)
        try:
            return cpu_call(lambda: simulate_variant(setup, v, t, points, outputs, dt))
        except (MechError, UsageError) as e:      # a method that cannot run this model: try the next
            if given and isinstance(e, UsageError):
                raise
            return 0.0, str(e)

    # given methods: that pair at the reference tolerance; auto: the kind's candidates in order, at
    # the reference tolerance and then looser ones (R.reference_ladder) until two of them succeed
    candidates = tuple(reference_methods) if given else R.auto_candidates(kind, setup.default_formulation)
    ladder = [tol] if given else R.reference_ladder(tol)
    failures: list[str] = []
    for t in ladder:
        good = []
        for lab in candidates:
            c, r = attempt(lab, t)
            if isinstance(r, str) or not r.success:
                failures.append(f"{lab} at tolerance {t:g}: " + (r if isinstance(r, str) else R.failure_text(r)))
                if given:
                    break
                continue
            good.append((lab, r, c))
            if len(good) == 2:
                break
        if len(good) == 2:
            (l1, r1, c1), (l2, r2, c2) = good
            ref = R.from_runs(r1, r2, columns, idx, (l1, l2), t, (c1, c2))
            ref.notes = ref.notes + [f"not used: {f}" for f in failures]
            return ref, points, idx
    raise R.reference_failed(failures, setup.span, given)


def run_bench(setup: Setup, *, variants: list[Variant], tolerances, reference="auto", reference_methods=None,
              compare="positions", repeats: int = 3, budget: float = DEFAULT_BUDGET,
              sweep_budget: float | None = None, stop_after: float | None = None, min_total: float = 0.0,
              log: Callable[[str], None] | None = None) -> BenchResult:
    """Every variant over the tolerance sweep against the reference.  budget: CPU seconds of
    one run beyond which its variant's tighter tolerances are skipped; sweep_budget: CPU
    seconds of all runs beyond which the remaining ones are skipped (None: no limit);
    stop_after: CPU seconds after which one run is stopped where the simulator reports
    progress (its row is skipped, and so are its variant's tighter tolerances); min_total: CPU
    seconds a row's timed runs add up to at least (more rounds than ``repeats`` for fast runs,
    at most MAX_ROUNDS)."""
    from ..simulation.monitors import is_conservative

    if repeats < 1:
        raise UsageError("repeats must be at least 1")
    tolerances = tuple(sorted(set(float(t) for t in tolerances), reverse=True))
    columns = compare_columns(setup.eom, compare)
    kind = classify_setup(setup)
    ref, points, idx = make_reference(setup, reference, columns, tolerances, kind, reference_methods, log)
    conservative = is_conservative(setup.eom)
    sweeps = {v.label: ([None] if v.fixed_dt is not None else list(tolerances)) for v in variants}
    done: dict[str, list[Row]] = {v.label: [] for v in variants}
    over: dict[str, Row] = {}              # variant -> its run that exceeded the per-run budget
    finished: set[str] = set()             # variants whose combination does not exist (n/a)
    spent = 0.0
    # tolerance by tolerance across the variants, so that a sweep budget cuts the tightest
    # tolerances of every variant rather than whole variants
    from ..interrupts import check_interrupt, interrupt_guard

    interrupted = False
    with interrupt_guard():              # a Ctrl-C CasADi swallows inside a run still stops the bench
        for i in range(max(len(sw) for sw in sweeps.values())):
            rerun: list = []               # this tolerance's rows, timed again in rounds across the variants
            for v in variants:
                sw = sweeps[v.label]
                if i >= len(sw) or v.label in finished:
                    continue
                tol = sw[i]
                if interrupted:
                    done[v.label].append(Row(label=v.label, method=v.method, formulation=v.formulation,
                                             tolerance=tol, status="skipped", message="interrupted (Ctrl-C)"))
                    continue
                try:
                    row, cpu, measured = _next_row(setup, v, tol, over, budget, sweep_budget, spent, points, idx,
                                                   ref, columns, 1, conservative, stop_after, rerun)
                    check_interrupt()
                except KeyboardInterrupt:
                    interrupted = True
                    done[v.label].append(Row(label=v.label, method=v.method, formulation=v.formulation,
                                             tolerance=tol, status="skipped", message="interrupted (Ctrl-C)"))
                    continue
                spent += cpu
                if log and measured:
                    log(one_line(row))
                if measured and row.cpu is not None and row.cpu > budget:
                    over[v.label] = row
                if row.status == "n/a":        # the combination does not exist: one row says so
                    finished.add(v.label)
                done[v.label].append(row)
            if not interrupted:
                try:
                    spent += _rounds(rerun, repeats - 1, min_total)
                except KeyboardInterrupt:
                    interrupted = True
    rows = [r for v in variants for r in done[v.label]]
    return BenchResult(setup=setup, columns=columns, reference=ref, rows=rows, tolerances=tolerances,
                       repeats=repeats, kind=kind, machine=machine(), interrupted=interrupted)


MAX_ROUNDS = 200       # rounds of timed runs (after the first) when min_total asks for more than the repeats


def _rounds(rerun: list, rounds: int, min_total: float = 0.0) -> float:
    """Time every (row, run) of ``rerun`` again, ``rounds`` times round-robin (every other round
    in reverse order): runs compared with each other are measured side by side, so a change of
    the machine's load hits them alike; each row keeps its minimum.  Rows whose timed runs
    add up to less than ``min_total`` CPU seconds go on in further rounds (at most MAX_ROUNDS):
    the minimum of a millisecond run needs more than a few tries on a loaded machine.
    The CPU seconds spent."""
    from ..interrupts import check_interrupt

    spent, stopped = 0.0, set()
    for k in range(max(rounds, MAX_ROUNDS)):
        for row, once in (rerun if k % 2 else rerun[::-1]):
            if id(row) in stopped or (k >= rounds and sum(row.cpu_runs) >= min_total):
                continue
            try:
                dt, _ = cpu_call(once)
            except OverBudget as e:        # stopped this time (the machine's load): its earlier runs stand
                stopped.add(id(row))
                spent += e.cpu
                continue
            check_interrupt()
            row.cpu_runs = row.cpu_runs + (dt,)
            row.cpu = min(row.cpu, dt)
            spent += dt
        if k + 1 >= rounds and all(id(r) in stopped or sum(r.cpu_runs) >= min_total for r, _ in rerun):
            break
    return spent


def _next_row(setup, v, tol, over, budget, sweep_budget, spent, points, idx, ref, columns, repeats,
              conservative, stop_after, rerun=None) -> tuple[Row, float, bool]:
    """(row, CPU seconds spent, measured) of variant ``v`` at tolerance ``tol``: skipped for a
    budget, or measured."""
    import time

    if v.label in over:
        o = over[v.label]
        return Row(label=v.label, method=v.method, formulation=v.formulation, tolerance=tol, status="skipped",
                   message=f"the run at tolerance {o.tolerance:g} took {o.cpu:.3g} s of CPU "
                           f"(budget {budget:g} s)"), 0.0, False
    if sweep_budget is not None and spent > sweep_budget:
        return Row(label=v.label, method=v.method, formulation=v.formulation, tolerance=tol, status="skipped",
                   message=f"the sweep used its budget of {sweep_budget:g} s of CPU"), 0.0, False
    c0 = time.process_time()
    row = measure_run(setup, v, tol, points, idx, ref, columns, repeats, conservative, stop_after, rerun=rerun)
    return row, time.process_time() - c0, True


def one_line(row: Row) -> str:
    tol = "-" if row.tolerance is None else f"{row.tolerance:.0e}"
    if row.ok:
        return (f"{row.label} tol={tol}: {row.cpu * 1e3:.3g} ms, error final {row.err_final:.2e}, "
                f"L2 {row.err_l2:.2e}")
    return f"{row.label} tol={tol}: {row.status}" + (f" ({row.message})" if row.message else "")


def machine() -> dict[str, Any]:
    import os

    from ..output.result import versions

    return {"platform": platform.platform(), "processor": platform.processor() or platform.machine(),
            "cpus": os.cpu_count(), "load_average": _load(), "versions": versions()}


def _load():
    import os

    try:
        return [round(x, 2) for x in os.getloadavg()]
    except OSError:
        return None
