"""Where finished chunks go: memory, or a netCDF file written chunk by chunk (bounded memory).

``Store.put(chunk)`` takes chunks in any order; ``Store.finish(...)`` adds the per-run status
table, the swept values and the summary, and returns the ``xarray.Dataset`` (read lazily
from the file when streaming).  A file is written under a temporary name in the same folder and renamed when
complete, so no half-written file ever carries the final name.
"""
from __future__ import annotations

import os

import numpy as np


class Store:
    def __init__(self, n: int, grid, states, variables, path: str | None = None, overwrite: bool = False):
        self.n, self.grid, self.states, self.variables = n, np.asarray(grid, float), tuple(states), tuple(variables)
        self.path = path
        self.status: list = [None] * n
        self.warnings: list = []
        self.done = 0
        nt = len(self.grid)
        if path is None:
            self.X = np.full((n, nt, len(self.states)), np.nan)
            self.S = np.full((n, nt, len(self.variables)), np.nan)
            self._f = None
        else:
            import h5netcdf

            from ..output.fileio import atomic_target

            self.part, self.final = atomic_target(path, overwrite)     # renamed when complete
            self._f = h5netcdf.File(self.part, "w")
            self._f.dimensions = {"run": n, "time": nt}
            chunks = (1, nt)
            self._vars = [self._f.create_variable(name, ("run", "time"), float, fillvalue=np.nan, chunks=chunks)
                          for name in self.states + self.variables]

    def put(self, chunk) -> None:
        a, k = chunk.first, len(chunk.status)
        if self._f is None:
            self.X[a:a + k] = chunk.X
            self.S[a:a + k] = chunk.signals
        else:
            nx = len(self.states)
            for j, v in enumerate(self._vars):
                v[a:a + k, :] = chunk.X[:, :, j] if j < nx else chunk.signals[:, :, j - nx]
        self.status[a:a + k] = chunk.status
        self.warnings += chunk.warnings
        self.done += k

    def finish(self, coords: dict, attrs: dict):
        import xarray as xr

        status = _status_vars(self.status)
        c = {"run": np.arange(self.n), "time": self.grid}
        c.update({name: ("run", np.asarray(v, float)) for name, v in coords.items()})
        attrs = {k: v for k, v in attrs.items() if v is not None}
        if self._f is None:
            data = {name: (("run", "time"), self.X[:, :, j]) for j, name in enumerate(self.states)}
            data.update({name: (("run", "time"), self.S[:, :, j]) for j, name in enumerate(self.variables)})
            data.update(status)
            return xr.Dataset(data, coords=c, attrs=attrs)
        self._f.close()
        self._f = None
        xr.Dataset(status, coords=c, attrs=attrs).to_netcdf(self.part, mode="a", engine="h5netcdf")
        os.replace(self.part, self.final)
        return xr.open_dataset(self.path, engine="h5netcdf")

    def abandon(self) -> None:
        """An error before the end: remove the partial file."""
        if self._f is not None:
            self._f.close()
            self._f = None
            try:
                os.remove(self.part)
            except OSError:
                pass


def _status_vars(rows) -> dict:
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
        out[key] = ("run", arr)
    return out
