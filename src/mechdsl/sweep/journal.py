"""A sweep's finished chunks on disk while it runs: what survives a kill and what ``resume``
continues from.

With ``out=``, every finished chunk is written at once to its own file in a folder beside the
output, ``.NAME.parts/`` (``chunk-FIRST-COUNT.npz``, written under a temporary name and
renamed, so a file there is always whole), next to ``manifest.json``: the sweep's identity
(provenance.identity: model, settings and design hashes), its size, and the writer's process
id.  Nothing in it is pickled (``np.load(allow_pickle=False)``; the status rows are JSON).
At the end (normal or Ctrl-C) the output file is assembled from the chunks and the folder
removed.  After a kill (SIGKILL, a power cut) the folder stays:

    resume=True     its chunks are kept (after the identity check) and only the other runs run;
                    an output file finished earlier (an interrupted sweep: rows 'not run')
                    gives its finished runs the same way
    resume=False    the next sweep on that output removes it (and says so)

A folder whose writer is alive belongs to a sweep still running: a second sweep on the same
output is refused.
"""
from __future__ import annotations

import json
import math
import os
import shutil
from pathlib import Path

import numpy as np

from ..diagnostics import UsageError

FORMAT = "mechdsl-sweep-parts 1"


def parts_folder(out) -> Path:
    out = Path(out)
    return out.parent / f".{out.name}.parts"


class Journal:
    def __init__(self, out, identity: dict, n: int, resume: bool):
        from ..output.fileio import _alive

        self.out = Path(out)
        self.folder = parts_folder(out)
        self.identity = identity
        self.n = n
        self.notes: list[str] = []
        self.kept = np.zeros(n, bool)            # runs whose results were kept from before
        manifest = self._manifest()
        if manifest is not None:
            pid = manifest.get("pid")
            if isinstance(pid, int) and pid != os.getpid() and _alive(pid):
                raise UsageError(f"another sweep (process {pid}) is writing {self.out} now; wait for it, or "
                                 f"choose another output")
            if resume:
                self._check(manifest, f"the partial results of a killed sweep in {self.folder}")
            else:
                shutil.rmtree(self.folder, ignore_errors=True)
                self.notes.append(f"removed the partial results of an earlier sweep on {self.out} that was killed "
                                  "(resume=True / --resume continues such a sweep instead)")
        elif self.folder.exists():               # no manifest: a kill while it was being created
            shutil.rmtree(self.folder, ignore_errors=True)
        self.folder.mkdir(exist_ok=True)
        self._write_manifest()
        for first, k in self._stored():
            self.kept[first:first + k] = True

    # -- the folder ---------------------------------------------------------------------
    def _manifest(self) -> dict | None:
        try:
            data = json.loads((self.folder / "manifest.json").read_text(encoding="utf-8"))
        except (OSError, ValueError):
            return None
        return data if isinstance(data, dict) and data.get("format") == FORMAT else None

    def _write_manifest(self) -> None:
        data = dict(self.identity, format=FORMAT, n_runs=self.n, pid=os.getpid())
        _replace(self.folder / "manifest.json", json.dumps(data, indent=1, sort_keys=True).encode("utf-8"))

    def _check(self, old: dict, what: str) -> None:
        from .provenance import differences

        diff = differences(old, self.identity)
        if old.get("n_runs", self.n) != self.n and not diff:
            diff = [f"the design ({old.get('n_runs')} runs then, {self.n} now)"]
        if diff:
            raise UsageError(f"cannot resume from {what}: " + "; ".join(diff) + " differ; run without resume to "
                             "start again (it replaces the output)")

    def _stored(self) -> list[tuple[int, int]]:
        out = []
        for p in self.folder.glob("chunk-*.npz"):
            try:
                first, k = (int(x) for x in p.stem.split("-")[1:3])
            except ValueError:
                continue
            if 0 <= first and first + k <= self.n:
                out.append((first, k))
        return sorted(out)

    # -- chunks -------------------------------------------------------------------------
    def put(self, chunk) -> None:
        k = len(chunk.status)
        path = self.folder / f"chunk-{chunk.first:09d}-{k}.npz"
        import io

        buf = io.BytesIO()
        np.savez(buf, X=np.asarray(chunk.X, float), S=np.asarray(chunk.signals, float),
                 status=np.array(json.dumps(_plain(chunk.status))), warnings=np.array(json.dumps(chunk.warnings)))
        _replace(path, buf.getvalue())

    def chunks(self):
        """The stored chunks, one at a time (bounded memory), by run index."""
        from .runs import Chunk

        for first, k in self._stored():
            with np.load(self.folder / f"chunk-{first:09d}-{k}.npz", allow_pickle=False) as z:
                yield Chunk(first, z["X"], z["S"], json.loads(str(z["status"])),
                            [tuple(w) for w in json.loads(str(z["warnings"]))])

    def adopt(self, old_attrs: dict, finished) -> None:
        """Keep the finished runs of an earlier output (``finished`` yields their Chunks)."""
        self._check(old_attrs, f"{self.out}")
        for chunk in finished:
            if not self.kept[chunk.first:chunk.first + len(chunk.status)].any():
                self.put(chunk)
                self.kept[chunk.first:chunk.first + len(chunk.status)] = True

    def remove(self) -> None:
        shutil.rmtree(self.folder, ignore_errors=True)


def _replace(path: Path, data: bytes) -> None:
    from ..output.fileio import temp_name

    tmp = temp_name(path)
    try:
        with open(tmp, "wb") as f:
            f.write(data)
        os.replace(tmp, path)
    except BaseException:
        try:
            os.unlink(tmp)
        except OSError:
            pass
        raise


def _plain(rows):
    out = []
    for r in rows:
        out.append({k: (None if isinstance(v, float) and not np.isfinite(v) else
                        float(v) if isinstance(v, (np.floating, float)) else
                        int(v) if isinstance(v, (np.integer,)) else
                        bool(v) if isinstance(v, np.bool_) else v) for k, v in (r or {}).items()})
    return out


def blocks(todo: np.ndarray, size: int):
    """(first run, indices) of chunks of at most ``size`` consecutive runs of ``todo``."""
    start = 0
    while start < len(todo):
        end = start + 1
        while end < len(todo) and end - start < size and todo[end] == todo[end - 1] + 1:
            end += 1
        yield todo[start], todo[start:end]
        start = end


def finished_of(out, n: int):
    """(attributes, finished chunks) of an earlier output file (an interrupted sweep's)."""
    from .runs import Chunk
    from .store import read

    ds = read(out)
    attrs = dict(ds.attrs)
    if int(ds.sizes.get("run", -1)) != n:
        attrs["n_runs"] = int(ds.sizes.get("run", -1))

    def chunks():
        try:
            cause = np.asarray(ds["cause"].values).astype(str)
            done = np.flatnonzero(cause != "not run")
            states = [s for s in str(attrs.get("states", "")).split(",") if s]
            per_time = [v for v in ds.data_vars if ds[v].dims == ("run", "time")]
            variables = [v for v in per_time if v not in states]
            from .runs import STATUS

            for first, idx in blocks(done, 256):
                sel = slice(int(idx[0]), int(idx[-1]) + 1)
                X = np.stack([np.asarray(ds[s].values[sel], float) for s in states], axis=-1)
                S = np.stack([np.asarray(ds[v].values[sel], float) for v in variables], axis=-1)
                rows = [{k: _py(ds[k].values[i]) for k in STATUS} for i in range(sel.start, sel.stop)]
                yield Chunk(int(first), X, S, rows)
        finally:
            ds.close()

    return attrs, chunks()


def _py(v):
    v = v.item() if hasattr(v, "item") else v
    return None if isinstance(v, float) and not math.isfinite(v) else v
