"""Where finished chunks go, and the files a sweep writes.

``Store.put(chunk)`` takes chunks in any order: into memory (no ``out=``, or a CSV, which is
written from memory at the end) and, with ``out=``, at once into the sweep's journal
(journal.py: one file per chunk, what survives a kill).  ``Store.finish(...)`` adds the
per-run status table, the swept values, the units and long names of every variable and the
provenance (provenance.py), and writes the output:

    .nc    streamed chunk by chunk from the journal into a netCDF file (h5netcdf) under a
           temporary name, renamed when complete; the returned Dataset reads it lazily
    .csv   the long table (one row per run and time) streamed in blocks of runs under a
           temporary name, with its JSON sidecar (units, long names, provenance and the
           CSV's SHA-256, checked by ``read``), both renamed when complete

``read(path)`` opens either kind again (the CSV only when its sidecar's checksum matches).
"""
from __future__ import annotations

import hashlib
import json
import os
from pathlib import Path

import numpy as np

from ..diagnostics import UsageError

CSV_BLOCK = 64          # runs per block of the streamed CSV


def warm_up(netcdf: bool) -> None:
    """Import now what writing the results needs (xarray's first Dataset imports its duck-array
    modules, dask among them; h5netcdf and its xarray back end): seconds that would otherwise
    come after a Ctrl-C, when a sweep must stop within a second or two."""
    import xarray as xr

    xr.Dataset({"x": ("a", np.zeros(1))}, coords={"a": np.zeros(1)})
    if netcdf:
        import h5netcdf  # noqa: F401
        import xarray.backends.h5netcdf_  # noqa: F401


class Store:
    def __init__(self, n: int, grid, states, variables, *, memory: bool = True, journal=None):
        self.n, self.grid, self.states, self.variables = n, np.asarray(grid, float), tuple(states), tuple(variables)
        self.journal = journal
        self.status: list = [None] * n
        self.warnings: list = []
        self.done = 0
        nt = len(self.grid)
        self.X = np.full((n, nt, len(self.states)), np.nan) if memory else None
        self.S = np.full((n, nt, len(self.variables)), np.nan) if memory else None
        self.resumed = 0
        if journal is not None:             # the runs kept from before (resume)
            for chunk in journal.chunks():
                self._place(chunk)
                self.resumed += len(chunk.status)

    def todo(self) -> np.ndarray:
        """Indices of the runs without a result yet."""
        return np.array([i for i, s in enumerate(self.status) if s is None], int)

    def _place(self, chunk) -> None:
        a, k = chunk.first, len(chunk.status)
        if self.X is not None:
            self.X[a:a + k] = chunk.X
            self.S[a:a + k] = chunk.signals
        self.status[a:a + k] = chunk.status
        self.warnings += [tuple(w) for w in chunk.warnings]
        self.done += k

    def put(self, chunk) -> None:
        if self.journal is not None:
            self.journal.put(chunk)
        self._place(chunk)

    def dataset(self, coords: dict, attrs: dict, meta: dict):
        """The Dataset in memory (no file)."""
        import xarray as xr

        c = _coords(self.n, self.grid, coords, meta)
        data = {name: (("run", "time"), self.X[:, :, j], _attrs(meta, name)) for j, name in enumerate(self.states)}
        data.update({name: (("run", "time"), self.S[:, :, j], _attrs(meta, name))
                     for j, name in enumerate(self.variables)})
        data.update(_status_vars(self.status, meta))
        return xr.Dataset(data, coords=c, attrs=_clean(attrs))

    def finish(self, coords: dict, attrs: dict, meta: dict, out: str | None = None):
        """The Dataset, and the output file when ``out`` is given (then the journal goes)."""
        if out is None:
            return self.dataset(coords, attrs, meta)
        if str(out).endswith(".csv"):
            ds = self.dataset(coords, attrs, meta)
            write_csv(ds, out, meta)
        else:
            ds = self._write_nc(out, coords, attrs, meta)
        if self.journal is not None:
            self.journal.remove()
        return ds

    def _write_nc(self, out, coords, attrs, meta):
        """Stream the journal's chunks into a netCDF file, written with h5netcdf alone (no
        xarray writer: it imports dask.distributed, seconds that came after a Ctrl-C); the
        swept values are CF auxiliary coordinates (the ``coordinates`` attribute)."""
        import h5netcdf
        import xarray as xr

        from ..output.fileio import atomic_target

        part, final = atomic_target(out, overwrite=True)
        aux = " ".join(coords)
        try:
            nt = len(self.grid)
            with h5netcdf.File(part, "w") as f:
                f.dimensions = {"run": self.n, "time": nt}
                for name, values in (("run", np.arange(self.n)), ("time", self.grid)):
                    v = f.create_variable(name, (name,), values.dtype, data=values)
                    v.attrs.update(_attrs(meta, name))
                for name, values in coords.items():
                    v = f.create_variable(name, ("run",), float, data=np.asarray(values, float))
                    v.attrs.update(_attrs(meta, name))
                vs = []
                for name in self.states + self.variables:
                    v = f.create_variable(name, ("run", "time"), float, fillvalue=np.nan, chunks=(1, nt))
                    v.attrs.update(_attrs(meta, name))
                    if aux:
                        v.attrs["coordinates"] = aux
                    vs.append(v)
                nx = len(self.states)
                for chunk in (self.journal.chunks() if self.journal is not None else ()):
                    a, k = chunk.first, len(chunk.status)
                    for j, v in enumerate(vs):
                        v[a:a + k, :] = chunk.X[:, :, j] if j < nx else chunk.signals[:, :, j - nx]
                for name, (_, values, va) in _status_vars(self.status, meta).items():
                    if values.dtype == bool:        # as xarray stores booleans
                        v = f.create_variable(name, ("run",), np.int8, data=values.astype(np.int8))
                        v.attrs["dtype"] = "bool"
                    elif values.dtype == object:
                        import h5py

                        v = f.create_variable(name, ("run",), h5py.string_dtype())
                        v[:] = np.asarray(values, dtype=object)
                    else:
                        v = f.create_variable(name, ("run",), values.dtype, data=values)
                    v.attrs.update(va)
                    if aux:
                        v.attrs["coordinates"] = aux
                f.attrs.update(_clean(attrs))
            os.replace(part, final)
        except BaseException:
            try:
                os.unlink(part)
            except OSError:
                pass
            raise
        return xr.open_dataset(final, engine="h5netcdf")

    def abandon(self) -> None:
        """An error before the end: the journal stays only if it holds finished runs (resume)."""
        if self.journal is not None and self.done == 0:
            self.journal.remove()


def _attrs(meta: dict, name: str) -> dict:
    m = meta.get(name) or {}
    return {"units": m.get("units", ""), "long_name": m.get("long_name", name)}


def _coords(n, grid, coords: dict, meta: dict) -> dict:
    c = {"run": ("run", np.arange(n), _attrs(meta, "run")), "time": ("time", grid, _attrs(meta, "time"))}
    c.update({name: ("run", np.asarray(v, float), _attrs(meta, name)) for name, v in coords.items()})
    return c


def _clean(attrs: dict) -> dict:
    return {k: v for k, v in attrs.items() if v is not None}


def _status_vars(rows, meta: dict) -> dict:
    from .runs import STATUS

    out = {}
    for key in STATUS:
        vals = [r.get(key) if r else None for r in rows]
        if key == "success":
            arr = np.array([bool(v) for v in vals])
        elif key in ("cause", "detail"):
            arr = np.array([str(v) if v is not None else "" for v in vals], dtype=object)
        elif key in ("steps", "rhs_evals", "rejected_steps", "points"):
            arr = np.array([-1 if v is None else int(v) for v in vals], dtype=np.int64)   # -1: not counted
        else:
            arr = np.array([np.nan if v is None else float(v) for v in vals])
        out[key] = ("run", arr, _attrs(meta, key))
    return out


# --------------------------------------------------------------------------- CSV + sidecar


def csv_columns(ds) -> list[str]:
    per_time = [v for v in ds.data_vars if ds[v].dims == ("run", "time")]
    per_run = [v for v in ds.data_vars if ds[v].dims == ("run",)]
    swept = [c for c in ds.coords if ds[c].dims == ("run",) and c != "run"]
    return ["run", "time"] + swept + per_time + per_run


def write_csv(ds, out, meta: dict) -> list[Path]:
    """The long table of ``ds`` and its sidecar, streamed (blocks of CSV_BLOCK runs) under
    temporary names; the sidecar holds the CSV's SHA-256."""
    import pandas as pd

    from .. import __version__
    from ..output.fileio import check_writable, temp_name
    from ..output.result import sidecar_path

    final = check_writable(out, overwrite=True)
    side = check_writable(sidecar_path(out), overwrite=True)
    cols = csv_columns(ds)
    per_time = [v for v in ds.data_vars if ds[v].dims == ("run", "time")]
    per_run = [c for c in cols[2:] if c not in per_time]
    t = np.asarray(ds["time"].values, float)
    nt = len(t)
    tmp, tmp_side = temp_name(final), temp_name(side)
    h = hashlib.sha256()
    try:
        with open(tmp, "w", encoding="utf-8", newline="") as f:
            for a in range(0, ds.sizes["run"], CSV_BLOCK):
                b = min(a + CSV_BLOCK, ds.sizes["run"])
                block = {"run": np.repeat(np.arange(a, b), nt), "time": np.tile(t, b - a)}
                for name in per_run:
                    block[name] = np.repeat(np.asarray(ds[name].values[a:b]), nt)
                for name in per_time:
                    block[name] = np.asarray(ds[name].values[a:b], float).reshape(-1)
                text = pd.DataFrame(block, columns=cols).to_csv(index=False, header=(a == 0), lineterminator="\n",
                                                                na_rep="NaN")
                h.update(text.encode("utf-8"))
                f.write(text)
        attrs = {k: (v.item() if hasattr(v, "item") else v) for k, v in ds.attrs.items()}
        sidecar = {"generator": f"mechdsl {__version__}", "kind": "sweep", "table": final.name,
                   "csv_sha256": h.hexdigest(), "attrs": attrs,
                   "columns": {c: _attrs(meta, c) for c in cols}}
        with open(tmp_side, "w", encoding="utf-8") as f:
            f.write(json.dumps(sidecar, indent=2, sort_keys=True, default=str) + "\n")
        # the CSV first: a kill between the renames leaves a new CSV beside an old sidecar,
        # which the checksum tells (read, resume)
        os.replace(tmp, final)
        os.replace(tmp_side, side)
    except BaseException:
        for p in (tmp, tmp_side):
            try:
                os.unlink(p)
            except OSError:
                pass
        raise
    return [final, side]


def read(path):
    """A sweep's output as an ``xarray.Dataset``: a netCDF file (read lazily) or a CSV with its
    sidecar (checked: the CSV must match the SHA-256 the sidecar recorded)."""
    import xarray as xr

    p = Path(path)
    if not p.is_file():
        raise UsageError(f"{p}: no such file")
    if p.suffix == ".nc":
        try:
            return xr.open_dataset(p, engine="h5netcdf")
        except (OSError, ValueError) as e:
            raise UsageError(f"{p} is not a readable netCDF file ({e})") from None
    if p.suffix != ".csv":
        raise UsageError(f"{p}: a sweep's output is a .nc or .csv file")
    from ..output.fileio import pair_problem
    from ..output.result import sidecar_path

    why = pair_problem(p)
    if why:
        raise UsageError(f"{p} {why}")
    side = json.loads(Path(sidecar_path(p)).read_text(encoding="utf-8"))
    if side.get("kind") != "sweep":
        raise UsageError(f"{p} is not a sweep's table (its sidecar says {side.get('kind', 'nothing')!r})")
    import pandas as pd

    # round_trip: the exact doubles written (pandas < 2 parses with its fast, not exact, reader)
    df = pd.read_csv(p, keep_default_na=False, na_values=["NaN"], float_precision="round_trip")
    return _from_table(df, side)


def _from_table(df, side: dict):
    """The Dataset of a sweep's long table (as write_csv wrote it)."""
    import xarray as xr

    from .runs import STATUS

    runs = np.asarray(df["run"].to_numpy(), int)
    n = int(runs.max()) + 1 if len(runs) else 0
    t = np.unique(np.asarray(df["time"].to_numpy(), float))
    nt = len(t)
    if len(df) != n * nt:
        raise UsageError("the sweep's table is not one row per run and time")
    df = df.iloc[np.lexsort((np.asarray(df["time"].to_numpy(), float), runs))]
    meta, attrs = side.get("columns", {}), side.get("attrs", {})
    swept = [c for c in str(attrs.get("swept", "")).split(",") if c]
    coords = {"run": ("run", np.arange(n), meta.get("run", {})), "time": ("time", t, meta.get("time", {}))}
    data = {}
    for c in df.columns:
        if c in ("run", "time"):
            continue
        v = df[c].to_numpy()
        if c in swept:
            coords[c] = ("run", np.asarray(v[::nt], float), meta.get(c, {}))
        elif c == "success":
            data[c] = ("run", np.array([str(x) == "True" for x in v[::nt]]), meta.get(c, {}))
        elif c in ("cause", "detail"):
            data[c] = ("run", np.array([str(x) for x in v[::nt]], dtype=object), meta.get(c, {}))
        elif c in ("steps", "rhs_evals", "rejected_steps", "points"):
            data[c] = ("run", np.asarray(v[::nt], np.int64), meta.get(c, {}))
        elif c in STATUS:
            data[c] = ("run", np.asarray(v[::nt], float), meta.get(c, {}))
        else:
            data[c] = (("run", "time"), np.asarray(v, float).reshape(n, nt), meta.get(c, {}))
    return xr.Dataset(data, coords=coords, attrs=attrs)
