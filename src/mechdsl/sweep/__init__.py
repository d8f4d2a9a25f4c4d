"""Ensembles: parameter sweeps and Monte Carlo over a model (issue 14; docs/sweeps.md).

    ds = m.sweep(params={"l": [0.5, 1, 2]}, starts={"j1.phi": np.linspace(0, 3, 64)}, t_end=10)
    ds = m.sweep(params=mechdsl.sample.normal(m=(1, 0.05), n=1000, seed=1), t_end=5, scheduler="processes")

    spec.py        grids, tables, samplers -> the design (one row per run); names classified
    plan.py        the job every chunk gets: settings and method auto resolved once, scheduler, chunk size
    execute.py     the chunks run on the scheduler into the store; Ctrl-C keeps what finished
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

import sys
import time
from pathlib import Path

import numpy as np

from ..diagnostics import UsageError
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
    from .execute import mark_not_run, run_chunks
    from .journal import blocks
    from .plan import check_arguments, chunk_size as default_chunk_size, label, plan
    from .provenance import identity, variable_meta
    from .spec import classify, design

    check_arguments(options, workers, chunk_size, resume, out)
    d = design(params, starts)
    names = classify(model, d.names)
    if scheduler is not None:
        scheduler = S.check(scheduler)
    if out is not None:
        _check_out(out, overwrite or resume)
    job, settings, scheduler, workers, method_note = plan(model, d, names, t_end, scheduler, workers, options)
    labels = {n: label(n, names.starts) for n in d.names}
    coords = {labels[n]: v for n, v in d.values.items()}
    ident = identity(model, settings, [labels[n] for n in d.names], coords)
    meta = variable_meta(model, job.states, job.variables, labels, names.starts)
    store, journal = _store(d, job, out, ident, resume, memory_limit)
    todo = store.todo()
    size = chunk_size or default_chunk_size(len(todo), scheduler, workers)
    chunks = [(int(a), {k: v[idx] for k, v in d.values.items()}) for a, idx in blocks(todo, size)]
    bar = _bar(progress, d.n)
    if bar is not None and store.done:
        bar.update(store.done)
    wall0 = time.perf_counter()
    interrupted, engine_notes = run_chunks(job, chunks, scheduler, workers, connect_timeout, store, bar)
    wall = time.perf_counter() - wall0
    mark_not_run(store)
    notes = (journal.notes if journal is not None else []) + engine_notes
    attrs = {**ident, **_run_attributes(store, d, settings, scheduler, method_note, interrupted, notes, wall,
                                        workers if scheduler != "vectorized" else 1, job.threads),
             "swept": ",".join(labels[n] for n in d.names), "grid_axes": ",".join(labels[n] for n, _ in d.axes),
             "states": ",".join(job.states)}
    ds = store.finish(coords, attrs, meta, out)
    return to_frame(ds) if frame else ds


def _store(d, job, out, ident, resume: bool, memory_limit: float):
    """(the store the finished chunks go into, the journal of a sweep written to a file): results
    in memory (refused beyond memory_limit) or streamed to a .nc file; a resumed sweep's
    finished runs kept."""
    from .store import Store, warm_up

    nc = out is not None and str(out).endswith(".nc")
    need = d.n * len(job.grid) * (len(job.states) + len(job.variables)) * 8
    if not nc and need > memory_limit:
        raise UsageError(f"the sweep's results would take {need / 1e9:.3g} GB in memory (limit {memory_limit / 1e9:.3g} "
                         "GB): pass out='sweep.nc' (-o sweep.nc) to stream them to disk, fewer points, or a "
                         "larger memory_limit")
    warm_up(nc)              # the imports of writing the results, now: not after a Ctrl-C
    journal = None
    if out is not None:
        from .journal import Journal, finished_of

        journal = Journal(out, ident, d.n, resume)
        if resume and Path(out).exists() and not journal.kept.any():
            journal.adopt(*finished_of(out, d.n))
    return Store(d.n, job.grid, job.states, job.variables, memory=not nc, journal=journal), journal


def _run_attributes(store, d, settings, scheduler: str, method_note, interrupted: bool, notes: list, wall: float,
                    workers: int, threads: int) -> dict:
    """The dataset's attributes about how the sweep ran: counts, summary, method, warnings."""
    failed = sum(1 for r in store.status if not r["success"])
    not_run = sum(1 for r in store.status if r["cause"] == "not run")
    summary = (f"{d.n} runs, {d.n - failed} succeeded, {failed - not_run} failed"
               + (f", {not_run} not run (interrupted)" if not_run else "")
               + (f"; {store.resumed} kept from before (resumed)" if store.resumed else ""))
    warnings = [f"sweep: {n}" for n in notes] + [f"run {i}: {w}" for i, w in store.warnings[:20]]
    return {"scheduler": scheduler, "method": settings.method,
            "method_note": method_note, "rtol": settings.rtol, "atol": settings.atol,
            "t_start": settings.t_start, "t_end": settings.t_end, "n_runs": d.n, "n_failed": failed,
            "n_finished": store.done, "n_resumed": store.resumed, "interrupted": int(interrupted),
            "summary": summary, "wall_time": wall, "workers": workers, "threads": threads,
            "n_warnings": len(store.warnings) + len(notes),
            "warnings": "\n".join(warnings) or None}


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
