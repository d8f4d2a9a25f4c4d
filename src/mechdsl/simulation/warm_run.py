"""Prepared warm runs of ``mech simulate`` (issue 24 item 8): the second run of the same command
without CasADi.

A run of ``mech simulate`` that ran the normal way (parse or model cache, derive, formulate,
choose, compile, integrate, record, estimate) and was one call of the compiled stepping loop
(the error estimate's companion another) leaves a *prepared run* in the cache folder
(``<cache>/runs/<key>.pkl``): the loops' libraries by path (or the interpreter's programs),
the calls' arguments, the recorder's program and the Result's metadata that no number of the
run decides (warm_capture.py).  The key is the SHA-256 of the file's text and name, every
option of the command that is not about where output goes, mechdsl's code fingerprint, the
versions of Python and numpy, CasADi's files, the C compiler found and MECHDSL_CFLAGS.

``replay(key)`` runs it: loads the libraries by ctypes (crk_calls.py), integrates, records the
signals with the runtime's interpreter, and computes the statistics, the invariant drift, the
error estimate (the companion run and estimate.compare) and the accuracy warning with the same
functions as the normal path, so the numbers and files are the same (tests/test_warm_run.py).
None (the normal path runs) when there is no entry or it cannot be trusted or used (a
library removed, a run that did not reach its end).
"""
from __future__ import annotations

import os
import pickle
import sys
import time
from pathlib import Path

import numpy as np

from ..digest import sha256
from ..eom import cachefiles
from ..eom.compiler import find_compiler
from ..eom.modelcache import code_fingerprint
from ..eom.sxcode import Program
from ..output.result import Result
from . import accuracy as A
from .backends import crk_calls as C
from .difference import compare

FORMAT = "mechdsl-warm-run 1"
MAX_ENTRIES = 200


class _NoProgress:
    def update(self, t):
        pass


def directory() -> Path:
    return cachefiles.cache_dir() / "runs"


def key(filename: str, text: bytes, options: tuple) -> str:
    """The key of a prepared run: the file and every run option (``options``: plain values)."""
    parts = (FORMAT, code_fingerprint(), sys.version, np.__version__, _casadi_files(), _compiler(),
             os.environ.get("MECHDSL_CFLAGS"), str(filename), options)
    h = sha256(repr(parts).encode("utf-8"))
    h.update(b"\0")
    h.update(text)
    return h.hexdigest()


def _compiler() -> tuple | None:
    """The C compiler a normal run would use (codegen.find_compiler): its real path, size and
    modification time (a new compiler builds new libraries, so the prepared run is not used)."""
    cc = find_compiler()
    if cc is None:
        return None
    try:
        st = os.stat(cc)
    except OSError:
        return (cc,)
    return os.path.realpath(cc), st.st_size, st.st_mtime_ns


def _casadi_files() -> tuple:
    """CasADi's installed files as the key sees them (size, modification time): a prepared run
    holds what that CasADi built."""
    import importlib.util

    spec = importlib.util.find_spec("casadi")
    if spec is None or not spec.origin:
        return ()
    d = os.path.dirname(spec.origin)
    out = []
    for name in ("__init__.py", "casadi.py"):
        try:
            st = os.stat(os.path.join(d, name))
            out.append((name, st.st_size, st.st_mtime_ns))
        except OSError:
            out.append((name, None))
    return tuple(out)


def write(k: str, data: dict) -> bool:
    try:
        payload = pickle.dumps(data, protocol=pickle.HIGHEST_PROTOCOL)
    except Exception:  # noqa: BLE001 - something that does not pickle: no prepared run
        return False
    path = directory() / f"{k}.pkl"
    head = f"{FORMAT} {k} {sha256(payload).hexdigest()}\n".encode("ascii")
    new = not path.exists()
    ok = cachefiles.write_bytes(path, [head, payload])
    if ok and new:
        from ..eom.modelcache import trim

        trim(path.parent, MAX_ENTRIES)
    return ok


def read(k: str) -> dict | None:
    data, why = cachefiles.read_bytes(directory() / f"{k}.pkl")
    if data is None:
        cachefiles.miss("warm-run", k[:16], why)
        return None
    head, sep, payload = data.partition(b"\n")
    parts = head.decode("ascii", "replace").rsplit(" ", 2)
    if not sep or len(parts) != 3 or parts[0] != FORMAT or parts[1] != k or sha256(payload).hexdigest() != parts[2]:
        cachefiles.miss("warm-run", k[:16], "another format, key or content")
        return None
    try:
        out = pickle.loads(payload)
    except Exception as e:  # noqa: BLE001 - written by another version of a dependency
        cachefiles.miss("warm-run", k[:16], f"the payload does not load ({type(e).__name__})")
        return None
    for lib in (out["run"]["loop"], *((out["companion"]["loop"],) if out["companion"] else ())):
        for path in (lib["runtime"], lib.get("library")):
            try:
                bad = path is not None and cachefiles.problem(os.stat(path), "file")
            except OSError:
                bad = "is gone"
            if bad:
                cachefiles.miss("warm-run", k[:16], f"the library {path} {bad}")
                return None
    cachefiles.hit("warm-run", k[:16])
    return out


def _call(c: dict):
    """(t, X, raw statistics) of one loop call ``c`` (warm_capture's loop_call), or None when it
    did not reach its end (the normal path then runs and says why)."""
    loop = C.open_loop(c["loop"])
    run = C.run_compiled(loop, c["method"], c["grid"], c["x0"], c["p"], c["u"], c["rtol"], c["atol"],
                         c["max_steps"], c["hmin"], _NoProgress())
    if run.interrupted:
        raise KeyboardInterrupt
    if run.error is not None or run.reached < len(c["grid"]):
        return None
    X = run.X.copy()
    X[0] = c["x0"]
    return c["grid"].copy(), X, run.stats


class _Declared:
    """The declared units of the coordinates and outputs (output/units.signal_units reads them)."""

    def __init__(self, units: dict):
        self.coordinates = [_Named(k, u) for k, u in units["coordinates"].items()]
        self.outputs = [_Named(k, u) for k, u in units["outputs"].items()]


class _Named:
    def __init__(self, name, unit):
        self.name, self.unit = name, unit


class _Problem:
    """What the accuracy report and warning read of a problem."""

    def __init__(self, settings, invariants):
        self.settings, self.invariants, self.kind = settings, invariants, "ode"


def replay(data: dict) -> Result | None:
    """The Result of the prepared run ``data`` (read), as the normal path makes it; None when
    its loop did not reach the end."""
    wall0, cpu0 = time.perf_counter(), time.process_time()
    c = data["run"]
    got = _call(c)
    if got is None:
        return None
    t, X, raw = got
    n = c["n"]
    meta = data["metadata"]            # (read for this run: its own)
    signals = _record(data["recorder"], t, X, c["p"])
    stats = {**{k: v for k, v in C.counts(raw).items() if v is not None}, "points": int(len(t)),
             "wall_time": time.perf_counter() - wall0}
    stats.update({k: v for k, v in A.energy_drift(signals).items() if v is not None})
    stats.update(A.integral_drift_of(signals, data["recorder"]["integrals"]))
    stats["raw"] = raw
    r = Result(t=t, q=X[:, :n], qd=X[:, n:], coordinates=list(data["coordinates"]), signals=signals, stats=stats,
               metadata=meta, failure=None)
    r.source_model = _Declared(data["units"])
    problem = _Problem(data["settings"], data["invariants"])
    A.check_finite(r)
    A.normalize_stats(r, time.process_time() - cpu0, time.perf_counter() - wall0)
    A.accuracy_report(r, problem, fixed_step=False)
    if data["companion"] is None:
        r.metadata.setdefault("accuracy", {}).update(data["estimate_off"])
    elif not _estimate(r, data):
        return None
    A.accuracy_warning(r, problem)
    return r


def _estimate(r: Result, data: dict) -> bool:
    """The default error estimate from the companion call (estimate.estimate's steps)."""
    comp, s = data["companion"], data["settings"]
    acc = r.metadata.setdefault("accuracy", {})
    acc["error_estimate_method"] = comp["how"]
    cpu0 = time.process_time()
    got = _call(comp)
    r.stats["error_estimate_cpu_time"] = time.process_time() - cpu0
    if got is None or not np.isfinite(got[1]).all():
        return False
    t, X, raw = got
    counted = C.counts(raw)
    r.stats["error_estimate_steps"] = counted["steps"]
    r.stats["error_estimate_rhs_evals"] = counted["rhs_evals"]
    other = _States(t, X[:, :comp["n"]])
    units = data["units"]["si"]
    compare(r, other, comp["factor"], s, lambda name: units.get(name))
    return True


class _States:
    def __init__(self, t, q):
        self.t, self.q, self.failure = t, q, None


def _record(rec: dict, t, X, p) -> dict:
    """The recorded signals (record._evaluate's interpreted branch, from the program alone)."""
    N = len(t)
    n, nu, m = rec["sizes"]
    rt = C.open_runtime(rec["runtime"])
    prog = Program(arrays=rec["program"])
    fun = C.program_fun(rt, prog)
    rows = (t.reshape(N, 1), X[:, :n], X[:, n:], np.zeros((N, nu)), np.asarray(p, float).reshape(-1), np.zeros((N, m)))
    vals = C.map_rows(rt, fun, rec["nnz_in"], rec["nout"], rec["dense"], rec["where"], N, rows).T
    return {k: vals[i] for i, k in enumerate(rec["names"])}
