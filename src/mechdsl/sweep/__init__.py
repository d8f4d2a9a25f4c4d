"""Ensembles: parameter sweeps and Monte Carlo over a model (issue 14; docs/sweeps.md).

    ds = m.sweep(params={"l": [0.5, 1, 2]}, starts={"j1.phi": np.linspace(0, 3, 64)}, t_end=10)
    ds = m.sweep(params=mechdsl.sample.normal(m=(1, 0.05), n=1000, seed=1), t_end=5, scheduler="processes")

    spec.py        grids, tables, samplers -> the design (one row per run); names classified
    runs.py        run_chunk: the runs of one chunk through the simulation layer (per run or mapped)
    schedulers.py  where chunks run: vectorized (in-process), processes, dask, tcp://...
    pool.py        the processes scheduler: workers that may die (retries, failed rows)
    journal.py     finished chunks on disk while a sweep runs: survives a kill; resume
    store.py       finished chunks -> memory, .nc or .csv + sidecar; the status table; read
    provenance.py  units, long names, the model/settings/design hashes

The sweep resolves its settings once (``Model.settings``: argument > scene > default);
``method="auto"`` of an ODE is resolved once, from the first run's start, so every back
end integrates every run with the same method and the results do not depend on where
they ran.  Needs the ``sweep`` extra (xarray, pandas, h5netcdf); Dask the ``dask`` extra.
"""
from __future__ import annotations

import math
import sys
import time
from pathlib import Path

import numpy as np

from ..diagnostics import UsageError
from ..model.names import split_state
from .spec import Table, table  # noqa: F401  (public: mechdsl.sweep.table)
from .store import read  # noqa: F401  (public: mechdsl.sweep.read)

__all__ = ["sweep", "read", "table", "to_frame", "first_time"]

MEMORY_LIMIT = 2e9      # bytes of results a sweep may hold in memory; beyond, stream with out="x.nc"


def sweep(model, params=None, starts=None, t_end=None, *, scheduler: str | None = None, out: str | None = None,
          progress=None, workers: int | None = None, chunk_size: int | None = None, frame: bool = False,
          overwrite: bool = False, connect_timeout: float = 10.0, memory_limit: float = MEMORY_LIMIT,
          resume: bool = False, **options):
    """Run the model over a grid, a table or a sample; returns an ``xarray.Dataset``
    (dimensions run, time; swept values as coordinates on run; per-run status variables;
    units and long names on every variable, provenance in the attributes) or, with
    ``frame=True``, a long pandas DataFrame.  ``out``: a .nc file (streamed) or a .csv
    table with its JSON sidecar.  ``resume=True``: continue the sweep ``out`` holds (killed
    or interrupted), after checking that model, settings and design are the same.  Ctrl-C
    stops it and returns (and writes) what finished.  See docs/sweeps.md."""
    _need("xarray")
    from . import schedulers as S
    from .provenance import identity, variable_meta
    from .runs import Job, default_threads
    from .spec import classify, design
    from ..simulation import formulate

    for bad in ("p", "x0"):
        if options.get(bad) is not None:
            raise UsageError(f"sweep: give swept values as params=/starts=, not {bad}=")
    d = design(params, starts)
    names = classify(model, d.names)
    if scheduler is not None:
        scheduler = S.check(scheduler)
    if workers is not None and (isinstance(workers, bool) or not isinstance(workers, int) or workers < 1):
        raise UsageError(f"workers must be an integer >= 1 (got {workers!r})")
    if chunk_size is not None and (isinstance(chunk_size, bool) or not isinstance(chunk_size, int) or chunk_size < 1):
        raise UsageError(f"chunk_size must be an integer >= 1 (got {chunk_size!r})")
    if resume and out is None:
        raise UsageError("resume=True continues the sweep an output file holds: give out= (-o)")
    if out is not None:
        _check_out(out, overwrite or resume)
    from ..simulation.settings import DEFAULT_POINTS

    settings = model.settings(t_end=t_end, **options)
    if settings.points is None:
        settings = settings.replace(points=DEFAULT_POINTS)     # one time grid for every run
    if settings.estimate_error:
        raise UsageError("estimate_error is not available in sweeps (run the runs of interest alone)")
    problem = formulate(model.eom, settings)
    job = Job(model=model, settings=settings, real=names.real, structural=names.structural, starts=names.starts,
              variables=(), grid=np.linspace(settings.t_start, settings.t_end, settings.points))
    method_note = None
    vector_why = _vectorizable(problem, names)
    if problem.kind == "ode" and settings.method == "auto" and not names.structural:
        # once for the sweep (the runs are prepared once and share the method, whatever the scheduler)
        settings, method_note = _resolve_auto(job, d, settings)
        job.settings = settings
        vector_why = _vectorizable(problem, names, settings.method)
    if scheduler is None:
        scheduler = "vectorized" if vector_why is None else "processes"
    elif scheduler == "vectorized" and vector_why is not None:
        raise UsageError(f"the vectorized scheduler cannot run this sweep: {vector_why}; use "
                         "scheduler='processes' (--scheduler processes) or 'dask'")
    job.vectorized = vector_why is None
    # threads of the mapped integrator only when asked (workers=): on the 2-core test machine
    # CasADi's thread map of the erk integrator used 1.8 cores for no gain in wall time
    # (benchmarks/sweep.py, docs/performance.md); processes do use both cores
    job.threads = (workers or 1) if scheduler == "vectorized" else 1
    workers = workers or default_threads()
    job.variables = _variables(model, problem)
    states = _states(model, d, names)
    job.states = states
    labels = {n: _label(n, names.starts) for n in d.names}
    coords = {labels[n]: v for n, v in d.values.items()}
    ident = identity(model, settings, [labels[n] for n in d.names], coords)
    meta = variable_meta(model, states, job.variables, labels, names.starts)

    nc = out is not None and str(out).endswith(".nc")
    need = d.n * len(job.grid) * (len(states) + len(job.variables)) * 8
    if not nc and need > memory_limit:
        raise UsageError(f"the sweep's results would take {need / 1e9:.3g} GB in memory (limit {memory_limit / 1e9:.3g} "
                         "GB): pass out='sweep.nc' (-o sweep.nc) to stream them to disk, fewer points, or a "
                         "larger memory_limit")
    from .store import Store, warm_up

    warm_up(nc)              # the imports of writing the results, now: not after a Ctrl-C
    journal = None
    if out is not None:
        from .journal import Journal, finished_of

        journal = Journal(out, ident, d.n, resume)
        if resume and Path(out).exists() and not journal.kept.any():
            journal.adopt(*finished_of(out, d.n))
    store = Store(d.n, job.grid, states, job.variables, memory=not nc, journal=journal)
    todo = store.todo()
    size = chunk_size or _chunk_size(len(todo), scheduler, workers)
    from .journal import blocks

    chunks = [(int(a), {k: v[idx] for k, v in d.values.items()}) for a, idx in blocks(todo, size)]
    bar = _bar(progress, d.n)
    if bar is not None and store.done:
        bar.update(store.done)
    engine = None
    interrupted = False
    wall0 = time.perf_counter()
    from ..interrupts import check_interrupt, interrupt_guard

    try:
        with interrupt_guard():          # CasADi swallows Ctrl-C into a RuntimeError: noted here
            try:
                if not chunks:
                    it = iter(())
                elif scheduler == "vectorized":
                    it = S.in_process(job, chunks)
                elif scheduler == "processes":
                    from .pool import Pool

                    engine = Pool(workers)
                    it = engine.run(job, chunks)
                else:
                    engine = S.Dask(scheduler, workers, connect_timeout)
                    it = engine.run(job, chunks)
                for chunk in it:
                    store.put(chunk)
                    if bar is not None:
                        bar.update(len(chunk.status))
                    check_interrupt()
            except KeyboardInterrupt:
                interrupted = True
                for chunk in (engine.drain() if engine is not None else ()):     # the runs finished meanwhile
                    store.put(chunk)
    except BaseException:
        if engine is not None:
            engine.close(cancel=True)
        store.abandon()
        raise
    finally:
        if bar is not None:
            bar.close()
    if engine is not None:
        engine.close(cancel=interrupted)
    wall = time.perf_counter() - wall0
    for i, row in enumerate(store.status):
        if row is None:
            from .runs import _invalid

            store.status[i] = dict(_invalid("the sweep was interrupted before this run"), cause="not run")
    failed = sum(1 for r in store.status if not r["success"])
    not_run = sum(1 for r in store.status if r["cause"] == "not run")
    summary = (f"{d.n} runs, {d.n - failed} succeeded, {failed - not_run} failed"
               + (f", {not_run} not run (interrupted)" if not_run else "")
               + (f"; {store.resumed} kept from before (resumed)" if store.resumed else ""))
    notes = (journal.notes if journal is not None else []) + list(getattr(engine, "notes", []))
    warnings = [f"sweep: {n}" for n in notes] + [f"run {i}: {w}" for i, w in store.warnings[:20]]
    attrs = {**ident, "scheduler": scheduler, "method": settings.method,
             "method_note": method_note, "rtol": settings.rtol, "atol": settings.atol,
             "t_start": settings.t_start, "t_end": settings.t_end, "n_runs": d.n, "n_failed": failed,
             "n_finished": store.done, "n_resumed": store.resumed, "interrupted": int(interrupted),
             "summary": summary, "wall_time": wall, "workers": workers if scheduler != "vectorized" else 1,
             "threads": job.threads, "n_warnings": len(store.warnings) + len(notes),
             "warnings": "\n".join(warnings) or None,
             "swept": ",".join(labels[n] for n in d.names), "grid_axes": ",".join(labels[n] for n, _ in d.axes),
             "states": ",".join(states)}
    ds = store.finish(coords, attrs, meta, out)
    return to_frame(ds) if frame else ds


def _states(model, d, names) -> tuple[str, ...]:
    """Every state name of the sweep: Integer parameters may change the coordinates."""
    models = [model]
    if names.structural:
        combos = sorted({tuple(float(d.values[n][i]) for n in names.structural) for i in range(d.n)})
        for combo in combos:
            try:
                models.append(model.with_params(**{n: int(v) if v.is_integer() else v
                                                   for n, v in zip(names.structural, combo)}))
            except Exception:  # noqa: BLE001 - that run becomes an 'invalid run' row
                pass
    out: list[str] = []
    for m in models:
        for c in list(m.coordinates) + [f"der({c})" for c in m.coordinates]:
            if c not in out:
                out.append(c)
    return tuple(out)


def _label(name: str, starts: dict) -> str:
    """The coordinate name of a swept value: parameters by name, start values as c.start / c.speed."""
    key = starts.get(name)
    if key is None:
        return name
    coord, speed = split_state(key)
    return f"{coord}.speed" if speed else f"{coord}.start"


def _vectorizable(problem, names, method: str | None = None) -> str | None:
    """None when one mapped integrator can run the sweep, else why not."""
    from ..simulation import registry as R

    if names.structural:
        return (f"{', '.join(names.structural)} is an Integer/Boolean parameter: it changes the model's "
                "structure, so the runs do not share one integrator")
    if getattr(problem.eom, "nu", 0):
        return "the model has inputs"
    if problem.kind != "ode":
        return {"dae": "the model has constraints (a DAE)", "hybrid": "the model has contacts (events)",
                "canonical": f"method {problem.settings.method} is a fixed-step canonical method"}[problem.kind]
    m = method or problem.settings.method
    if m != "auto" and R.spec(m).family not in ("casadi", "crk"):
        return f"method {m} is neither the stepping loop nor a CasADi integrator"
    if problem.settings.ode.functions is not None:
        return "the functions option replaces the model's Functions"
    if problem.settings.error_estimate != "off":
        return "each run carries an error estimate (error_estimate on): a companion run of its own"
    return None


def _resolve_auto(job, d, settings):
    """method=auto, once for the sweep: the method a single run at the first run's start would
    use (prepared as that run: the stepping loop where a single run takes it)."""
    from ..simulation import formulate
    from ..simulation.prepared import prepare
    from .runs import _prepare

    row = {k: float(v[0]) for k, v in d.values.items()}
    try:
        eom, s, _ = _prepare(job, row)
    except Exception:  # noqa: BLE001 - an invalid first run: decide at the model's own start
        eom, s = job.model.eom, settings.replace(p=job.model.parameter_values, x0=None)
        from ..eom.start import start_vector

        s = s.replace(x0=start_vector(eom, None, s.p))
    prep = prepare(formulate(eom, s))
    method = prep.method
    reason = (prep.setup.meta.get("method_reason") if prep.setup is not None else None) or "auto"
    return settings.replace(method=method), f"auto -> {method} (from the first run's start: {reason})"


def _variables(model, problem) -> tuple[str, ...]:
    """Recorded signals kept per run: the model's scalar outputs and the energy."""
    eom = model.eom
    names = []
    for name in problem.outputs:
        expr = (getattr(eom, "outputs", None) or {}).get(name)
        shape = getattr(expr, "shape", (1, 1))
        if tuple(shape) in ((1, 1), (1,), ()):
            names.append(name)
    return tuple(names) + ("energy",)


def _chunk_size(n: int, scheduler: str, workers: int) -> int:
    if scheduler == "vectorized":
        return max(1, min(256, n))
    return max(1, min(256, math.ceil(n / (4 * workers))))


def _bar(progress, n):
    show = sys.stderr.isatty() if progress is None else bool(progress)
    if not show:
        return None
    from tqdm import tqdm

    return tqdm(total=n, unit="run", file=sys.stderr, leave=False, mininterval=0.5)


def _check_out(out: str, overwrite: bool) -> None:
    from ..output.fileio import check_writable

    if not str(out).endswith((".nc", ".csv")):
        raise UsageError(f"sweep out= must be a .nc (netCDF, streamed) or .csv file (got {out!r})")
    check_writable(out, overwrite)
    if str(out).endswith(".csv"):
        check_writable(str(out)[:-4] + ".json", overwrite)
    _need("h5netcdf" if str(out).endswith(".nc") else "pandas")


def _need(module: str) -> None:
    import importlib.util

    if importlib.util.find_spec(module) is None:
        raise UsageError(f"sweeps need {module}: pip install 'mechdsl[sweep]'")


def to_frame(ds):
    """The long table: one row per (run, time) with the swept values and the run's status."""
    _need("pandas")
    per_time = [v for v in ds.data_vars if ds[v].dims == ("run", "time")]
    per_run = [v for v in ds.data_vars if ds[v].dims == ("run",)]
    df = ds[per_time].to_dataframe().reset_index()
    status = ds[per_run].to_dataframe().reset_index()
    return df.merge(status, on=[c for c in status.columns if c in df.columns])


def first_time(ds, values, above: float):
    """Per run: the first output time at which ``|values| > above`` (NaN if never).

    ``values`` is a (run, time) DataArray, e.g. ``ds["j1.phi"] + ds["j2.phi"]``."""
    v = np.abs(np.asarray(values, float)) > above
    t = np.asarray(ds["time"], float)
    hit = v.any(axis=1)
    idx = v.argmax(axis=1)
    return np.where(hit, t[idx], np.nan)
