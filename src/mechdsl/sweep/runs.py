"""One chunk of runs, the unit every back end executes (in-process, in a worker process,
on a Dask worker): ``run_chunk(job, first, values) -> Chunk``.

Each run goes through the one simulation layer: its settings are the sweep's resolved
``SimulationSettings`` with the run's parameter vector and start vector (``p``, ``x0``),
and its statistics are the layer's schema (``accuracy.SCHEMA``).  The problem is prepared
once per chunk and model structure (``simulation.prepared.prepare``: Functions, method,
integrator), and every run is that preparation ``at`` its values.  Two ways to integrate:

    per run     the start check, then ``solve(prepared.at(p=..., x0=...))``: any problem kind
    vectorized  ODE problems without inputs: the chunk in one call, either the compiled
                stepping loop's ensemble call (``crk.run_batch``: dopri5/dop853, method =
                auto's choice) or the prepared CasADi integrator ``map``-ped over the chunk;
                the layer's post steps (the run's signals and metadata, non-finite check,
                statistics schema, accuracy report) then run per run on its trajectory.  A
                run that fails or is not finite (or a chunk the call rejects) is rerun per
                run, so its failure says when and why exactly as a single run would.

The ensemble call and the mapped integrator integrate with what a single run of the prepared
problem integrates with (the loop's Function and options; ``Prepared.integrator``), so both
ways give the same numbers (bit-identical: the same C code or the same CasADi Function).
"""
from __future__ import annotations

import copy
import os
import time
from dataclasses import dataclass, field

import numpy as np

from .. import integrators as I
from ..diagnostics import MechError, UsageError
from ..eom.preflight import check_start
from ..eom.start import start_vector
from ..interrupts import check_interrupt
from ..simulation import accuracy as A
from ..simulation.choose import NO_U
from ..simulation.prepared import prepare
from ..simulation.problem import formulate
from ..simulation.template import solve


STATUS = ("success", "failure_time", "cause", "detail", "steps", "rhs_evals", "rejected_steps", "points",
          "cpu_time", "wall_time", "energy_drift", "energy_drift_relative", "error_estimate")


@dataclass
class Job:
    """What a worker needs (pickles: the Model pickles by its source text)."""

    model: object                        # mechdsl.api.Model
    settings: object                     # SimulationSettings (resolved once for the whole sweep)
    real: tuple[str, ...]
    structural: tuple[str, ...]
    starts: dict                         # sweep name -> start key
    variables: tuple[str, ...]           # recorded signals kept per run
    grid: np.ndarray                     # the output times
    states: tuple[str, ...] = ()         # every state name over the sweep (Integer parameters change them)
    vectorized: bool = False
    threads: int = 1                     # threads of the mapped integrator


@dataclass
class Chunk:
    first: int
    X: np.ndarray                        # (k, n_t, n_x), NaN after a failure
    signals: np.ndarray                  # (k, n_t, n_var)
    status: list = field(default_factory=list)    # one dict per run (STATUS keys)
    warnings: list = field(default_factory=list)  # (run, text)


def run_chunk(job: Job, first: int, values: dict) -> Chunk:
    try:
        return _run_chunk(job, first, values)
    except Exception:
        # a Ctrl-C inside CasADi comes out as a RuntimeError, or as a SystemError when it
        # arrived while CasADi converted a result ("DM.__array__ returned a result with an
        # exception set"): whatever it became, it is the interrupt
        check_interrupt()
        raise


def _run_chunk(job: Job, first: int, values: dict) -> Chunk:
    k = len(next(iter(values.values())))
    nt, nx = len(job.grid), len(job.states)
    out = Chunk(first, np.full((k, nt, nx), np.nan), np.full((k, nt, len(job.variables)), np.nan),
                [None] * k)
    todo = []
    runs = {}
    for i in range(k):
        row = {name: float(v[i]) for name, v in values.items()}
        try:
            runs[i] = _prepare(job, row)
            todo.append(i)
        except (UsageError, MechError) as e:
            out.status[i] = _invalid(str(e).strip().splitlines()[0] if str(e).strip() else type(e).__name__)
        # a Ctrl-C that a CasADi call swallowed (and someone handled as a plain failure) would
        # otherwise wait for the end of the chunk
        check_interrupt()
    prepared: dict = {}             # structural values -> the problem prepared once (simulation.prepared)
    if job.vectorized and todo:
        todo = _mapped(job, todo, runs, out, prepared)
    for i in todo:
        eom, s, key = runs[i]
        _store(job, out, i, _solve_one(prepared, key, eom, s))
        check_interrupt()            # a Ctrl-C the run's integrator swallowed (it failed "interrupted")
    return out


def _prepare(job: Job, row: dict):
    """The run's EOM and settings (the one place a run's p and x0 are built) and the key of its
    structure (runs with equal keys share one prepared problem)."""
    from ..numbers import start_value

    m = job.model
    key = tuple(row[n] for n in job.structural)
    if job.structural:
        m = m.with_params(**{n: int(row[n]) if float(row[n]).is_integer() else row[n] for n in job.structural})
    if job.real:
        m = m.with_params(**{n: row[n] for n in job.real})
    eom = m.eom
    pv = np.asarray(m.parameter_values, float)
    x0 = start_vector(eom, {key_: start_value(m.model, key_, row[name]) for name, key_ in job.starts.items()} or None, pv)
    return eom, job.settings.replace(p=pv, x0=x0), key


def _prepared(prepared: dict, key, eom, s):
    """The problem of this structure, prepared once per chunk (its Functions, method and
    integrator); the runs are solved ``at`` their parameters and start values."""
    hit = prepared.get(key)
    if hit is None:
        hit = prepared[key] = prepare(formulate(eom, s))
    return hit


def _solve_one(prepared: dict, key, eom, s):
    """One run: the start check of every run (as simulation.simulate), then the prepared problem
    at this run's values."""
    try:
        check_start(eom, p=s.p, x0=s.x0, t=s.t_start, drift_bound=s.dae.bound(s.atol))
        return solve(_prepared(prepared, key, eom, s).at(p=s.p, x0=s.x0))
    except (UsageError, MechError) as e:
        return str(e).strip().splitlines()[0] if str(e).strip() else type(e).__name__
    except Exception:
        check_interrupt()            # CasADi's RuntimeError for a Ctrl-C is the interrupt
        raise


def _invalid(text: str) -> dict:
    st = {k: None for k in STATUS}
    st.update(success=False, failure_time=np.nan, cause="invalid run", detail=text, points=0)
    return st


def _store(job: Job, out: Chunk, i: int, r) -> None:
    if isinstance(r, str):
        out.status[i] = _invalid(r)
        return
    n = len(r.t)
    names = list(r.coordinates) + [f"der({c})" for c in r.coordinates]
    cols = [job.states.index(c) for c in names]
    out.X[i, :n][:, cols] = np.hstack([r.q, r.qd])
    for j, name in enumerate(job.variables):
        v = r.signals.get(name)
        if isinstance(v, np.ndarray) and v.ndim == 1:
            out.signals[i, :len(v), j] = v
    st = {k: r.stats.get(k) for k in STATUS if k in r.stats}
    st["error_estimate"] = (r.metadata.get("accuracy") or {}).get("error_estimate")   # None: not asked
    f = r.failure
    st.update(success=f is None, failure_time=np.nan if f is None else float(f.time),
              cause="" if f is None else f.cause, detail="" if f is None else (f.detail or ""))
    out.status[i] = {k: st.get(k) for k in STATUS}
    for w in r.metadata.get("warnings", []):
        out.warnings.append((out.first + i, w))


# --------------------------------------------------------------------------- vectorized


_MAPS: dict = {}


def mapped_integrator(prep, k: int, threads: int):
    """The one place the sweep touches the model's CasADi Functions: the integrator of the
    prepared problem (the same Function and options a single run integrates with) mapped over
    k runs."""
    integ = prep.integrator()
    key = (id(integ), k, threads)
    hit = _MAPS.get(key)
    if hit is None or hit[0] is not integ:
        if len(_MAPS) > 8:
            _MAPS.clear()
        hit = _MAPS[key] = (integ, integ.map(k, "thread", threads) if threads > 1 else integ.map(k))
    return hit[1]


def scheme_parameter(pv) -> np.ndarray:
    """The integrator's parameter input [u; p] (integrators.dae_function); u is empty: the
    vectorized path serves models without inputs only."""
    return np.r_[NO_U, np.asarray(pv, float).ravel()]


def _ensemble(prep, todo: list, runs: dict):
    """(trajectories (run, time, state), raw statistics per run or None, runs that failed) of
    ``todo`` in one C call of the stepping loop (crk_run_batch), or None when the prepared
    problem does not run in the loop (then the mapped CasADi integrator)."""
    from ..simulation.backends import crk, payback

    setup = prep.setup
    funcs = setup.funcs
    if not isinstance(funcs, crk.LoopFunctions) or funcs.drive is not None or setup.extra:
        return None
    # a model run interpreted because the cache has not compiled it yet (payback.py): an ensemble is a
    # loop of runs, where the compile pays first
    engine = "compiled" if getattr(getattr(funcs, "loop", None), "rented", False) else funcs.engine
    loop, _ = crk.library(funcs.loop_ode, tag=setup.eom.name, engine=engine)
    if loop is None:
        return None
    pay = None
    if loop.engine == "interpreted":      # too large to compile up front: until the chunks have paid
        pay = payback.Payback(funcs.loop_ode, setup.eom.name)     # (payback.py; the same bits either way)
        loop = pay.compiled_now() or loop
    s = setup.settings
    X0 = np.vstack([runs[i][1].x0 for i in todo])
    P = np.vstack([np.ravel(runs[i][1].p) for i in todo])
    from ..simulation.choose import min_step

    X, stats, status, reached = crk.run_batch(loop, setup.method, setup.grid, X0, P, setup.drive.vector(s.t_start),
                                              s.rtol, s.atol, setup.max_steps, min_step(s.t_start, s.t_end))
    raw = [{"n_steps": int(st[0]), "n_rhs": int(st[1]), "n_reject": int(st[2]), "status": 0, "engine": loop.engine}
           for st in stats]
    if pay is not None and loop.engine == "interpreted":
        pay.record(sum(int(st[1]) for st in stats))
    failed = {j for j in range(len(todo)) if status[j] != 0 or reached[j] < len(setup.grid)}
    return X, raw, failed


def _mapped(job: Job, todo: list, runs: dict, out: Chunk, prepared: dict) -> list:
    """Integrate ``todo`` runs in one call (the stepping loop's ensemble call, else the mapped
    integrator); returns the runs left for the per-run path."""
    eom0, s0, key0 = runs[todo[0]]
    k = len(todo)
    wall0, cpu0 = time.perf_counter(), time.process_time()
    raw, failed = [{}] * k, set()
    try:
        prep = _prepared(prepared, key0, eom0, s0)
        batch = _ensemble(prep, todo, runs)
        if batch is not None:
            traj, raw, failed = batch
        else:
            X0 = np.column_stack([runs[i][1].x0 for i in todo])
            P = np.column_stack([scheme_parameter(runs[i][1].p) for i in todo])
            F = mapped_integrator(prep, k, job.threads)
            check_interrupt()
            with I.captured_messages():
                xf = np.asarray(F(x0=X0, p=P)["xf"], float)
            traj = xf.reshape(X0.shape[0], k, len(job.grid)).transpose(1, 2, 0)        # (run, time, state)
    except Exception:  # noqa: BLE001 - a run failed inside the map: every run of the chunk alone
        check_interrupt()            # ... unless it was Ctrl-C, which CasADi turns into a RuntimeError
        return todo
    cpu = (time.process_time() - cpu0) / k
    wall = (time.perf_counter() - wall0) / k
    nt = len(job.grid)
    setup, problem = prep.setup, prep.problem
    left = []
    for j, i in enumerate(todo):
        X = traj[j]
        if j in failed or not np.isfinite(X).all():
            left.append(i)
            continue
        eom, s, _ = runs[i]
        X[0] = s.x0
        # the layer's post steps on the trajectory: the run's signals and metadata (OdeSetup.record),
        # non-finite check, statistics schema, accuracy report
        r = setup.record(job.grid.copy(), X, s.p, s.x0, copy.deepcopy(setup.meta), I.Run(X=X, reached=nt, stats=raw[j]),
                         None, setup.loop_compiled, time.perf_counter())
        A.check_finite(r)
        A.normalize_stats(r, cpu, wall)
        A.accuracy_report(r, problem, fixed_step=False)
        A.accuracy_warning(r, problem)
        _store(job, out, i, r)
    return left


def default_threads() -> int:
    return max(1, len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1))
