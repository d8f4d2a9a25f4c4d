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
Without numpy (whose import alone is most of a warm process): the loops run on array.array
buffers (crk_calls.call_loop), the signals, drift and estimate figures are computed in plain
Python over them (accuracy.note_plain, difference.report: the same floating-point operations),
and the CSV is written by the one formatter of Result (result.csv_text).
None (the normal path runs) when there is no entry or it cannot be trusted or used (a
library removed, a run that did not reach its end).
"""
from __future__ import annotations

import ctypes
import math
import os
import pickle
import stat
import sys
import time
from array import array
from pathlib import Path

from ..digest import sha256
from ..eom import cachefiles
from ..eom.compiler import find_compiler
from ..eom.modelcache import code_fingerprint
from ..eom.vmprog import Program, address
from ..output.result import Result, csv_text
from . import accuracy as A
from .backends import crk_calls as C
from .backends import runtime_lib
from .difference import every_kth, report

FORMAT = "mechdsl-warm-run 2"
MAX_ENTRIES = 200


class _NoProgress:
    def update(self, t):
        pass


def directory() -> Path:
    return cachefiles.cache_dir() / "runs"


def key(filename: str, text: bytes, options: tuple) -> str:
    """The key of a prepared run: the file and every run option (``options``: plain values)."""
    parts = (FORMAT, code_fingerprint(), sys.version, _package_files("numpy", ("__init__.py", "version.py")),
             _package_files("casadi", ("__init__.py", "casadi.py")), _compiler(), os.environ.get("MECHDSL_CFLAGS"),
             str(filename), options)
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


def _package_files(package: str, names) -> tuple:
    """A package's installed files as the key sees them (size, modification time), without
    importing it: a prepared run holds what that CasADi built and numbers that numpy computed."""
    import importlib.util

    spec = importlib.util.find_spec(package)
    if spec is None or not spec.origin:
        return ()
    d = os.path.dirname(spec.origin)
    out = []
    for name in names:
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


class _Plain(pickle.Unpickler):
    """A prepared run's payload holds plain data (warm_capture.plain): one that needs numpy is
    refused (a warm run would import it) rather than loaded."""

    def find_class(self, module, name):
        if module == "numpy" or module.startswith("numpy."):
            raise pickle.UnpicklingError("the payload holds numpy values")
        return super().find_class(module, name)


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
        import io

        out = _Plain(io.BytesIO(payload)).load()
    except Exception as e:  # noqa: BLE001 - written by another version of a dependency
        cachefiles.miss("warm-run", k[:16], f"the payload does not load ({type(e).__name__})")
        return None
    for lib in (out["run"]["loop"], *((out["companion"]["loop"],) if out["companion"] else ())):
        for path in (lib["runtime"], lib.get("library")):
            try:
                st = None if path is None else os.stat(path)
                # (the runtime installed with mechdsl, runtime_lib.py: owned by whoever installed it)
                bad = st is not None and (cachefiles.problem(st, "file") if os.path.dirname(path) != runtime_lib.PACKAGED
                                          else "is not a regular file" if not stat.S_ISREG(st.st_mode) else None)
            except OSError:
                bad = "is gone"
            if bad:
                cachefiles.miss("warm-run", k[:16], f"the library {path} {bad}")
                return None
    for c in (out["run"], out["companion"]):
        pay = c and c.get("payback")
        if pay and _evaluations(pay["path"]) >= pay["limit"]:
            cachefiles.miss("warm-run", k[:16], "the interpreted model has paid for its compile (payback.py)")
            return None
    cachefiles.hit("warm-run", k[:16])
    return out


def _evaluations(path: str) -> int:
    """The interpreted evaluations counted in the file ``path`` (payback.py's count)."""
    data, _ = cachefiles.read_bytes(Path(path))
    try:
        return max(int(data.decode()), 0) if data is not None else 0
    except ValueError:
        return 0


def _call(c: dict):
    """(raw statistics, X) of one loop call ``c`` (warm_capture's loop_call): X the states,
    array.array of rows [q, qd] (the first row the start values, as the normal path sets it),
    or None when the run did not reach its end or a value is not finite (the normal path then
    runs and says why)."""
    loop = C.open_loop(c["loop"])
    run = C.call_loop(loop, c["method"], c["grid"], c["x0"], c["p"], c["u"], c["rtol"], c["atol"],
                      c["max_steps"], c["hmin"], _NoProgress())
    if run.interrupted:
        raise KeyboardInterrupt
    pay = c.get("payback")
    if pay:                             # an interpreted model counts towards its compile (payback.py)
        cachefiles.write_bytes(Path(pay["path"]), str(_evaluations(pay["path"]) + int(run.raw["n_rhs"])).encode())
    if run.fail_time is not None or run.reached < len(c["grid"]):
        return None
    X = run.X
    X[:len(c["x0"])] = c["x0"]
    if not math.isfinite(sum(X)):       # (the normal path says which value and when)
        return None
    return run.raw, X


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


class Rows(Result):
    """A prepared run's Result for ``mech simulate`` (summary, CSV and sidecar): ``t`` and each
    signal an array.array, the states the rows of ``X`` ([q, qd] each, array.array); ``q`` and
    ``qd`` are None (no numpy: this Result is written, never handed to a caller)."""

    X: array = None

    def to_csv_text(self) -> str:
        t, X, sigs = self.t, self.X, list(self.signals.values())
        nx = len(X) // len(t) if len(t) else 0
        return csv_text(self.columns, ([t[i], *X[i * nx:(i + 1) * nx], *[v[i] for v in sigs]]
                                       for i in range(len(t))))


def replay(data: dict) -> Result | None:
    """The Result of the prepared run ``data`` (read), as the normal path makes it; None when
    its loop did not reach the end or a value is not finite."""
    wall0, cpu0 = time.perf_counter(), time.process_time()
    c = data["run"]
    got = _call(c)
    if got is None:
        return None
    raw, X = got
    t = array("d", c["grid"])
    signals = _record(data["recorder"], t, X, c["p"])
    if signals is None or not A.note_plain(signals.values()):
        return None
    meta = data["metadata"]            # (read for this run: its own)
    stats = {**{k: v for k, v in C.counts(raw).items() if v is not None}, "points": len(t),
             "wall_time": time.perf_counter() - wall0}
    stats.update({k: v for k, v in A.energy_drift(signals).items() if v is not None})
    stats.update(A.integral_drift_of(signals, data["recorder"]["integrals"]))
    stats["raw"] = raw
    r = Rows(t=t, q=None, qd=None, coordinates=list(data["coordinates"]), signals=signals, stats=stats,
             metadata=meta, failure=None)
    r.X = X
    r.source_model = _Declared(data["units"])
    problem = _Problem(data["settings"], data["invariants"])
    A.normalize_stats(r, time.process_time() - cpu0, time.perf_counter() - wall0)
    A.accuracy_report(r, problem, fixed_step=False)
    if data["companion"] is None:
        r.metadata.setdefault("accuracy", {}).update(data["estimate_off"])
    elif not _estimate(r, data, c["n"]):
        return None
    A.accuracy_warning(r, problem)
    return r


def _estimate(r: Rows, data: dict, n: int) -> bool:
    """The default error estimate from the companion call (estimate.estimate's steps, compare's
    numbers by difference.report over the buffers)."""
    comp, s = data["companion"], data["settings"]
    acc = r.metadata.setdefault("accuracy", {})
    acc["error_estimate_method"] = comp["how"]
    cpu0 = time.process_time()
    got = _call(comp)
    r.stats["error_estimate_cpu_time"] = time.process_time() - cpu0
    if got is None:
        return False
    raw, Y = got
    counted = C.counts(raw)
    r.stats["error_estimate_steps"] = counted["steps"]
    r.stats["error_estimate_rhs_evals"] = counted["rhs_evals"]
    t, X, u = r.t, r.X, comp["grid"]
    k = every_kth(t, u, s.t_end - s.t_start)
    nx, ny = len(X) // len(t), len(Y) // len(u)
    if k is None or comp["n"] != n:
        return False                    # (the normal path's general matching of times)
    factor = comp["factor"]
    per, where = [], []
    for j in range(n):
        d = [abs(a - b) / factor for a, b in zip(X[j::k * nx], Y[j::ny])]
        per.append(max(d))
        where.append(d.index(per[-1]))
    qmax = [max(map(abs, X[j::nx])) for j in range(n)]
    units = data["units"]["si"]
    report(acc, r.coordinates, per, qmax, lambda j: t[where[j] * k], s, lambda name: units.get(name))
    return True


def _record(rec: dict, t, X, p) -> dict | None:
    """The recorded signals (record._evaluate's interpreted branch, from the program alone, by
    the runtime's crk_map: q and qd read in place from the rows of X), or None when the
    recorder does not have the inputs (t, q, qd, u, p, lam) this reads."""
    N = len(t)
    n, nu, m = rec["sizes"]
    nnz = rec["nnz_in"]
    nx = len(X) // N
    if len(nnz) != 6 or nnz[:3] != [1, n, n] or nnz[3] != nu or nnz[5] != m or nnz[4] != len(p) or nx != 2 * n:
        return None
    rt = C.open_runtime(rec["runtime"])
    prog = Program(rec["program"])
    fun = C.program_fun(rt, prog)
    width = max(rec["nout"], 1)
    out = array("d", bytes(8 * N * width))
    zeros = array("d", bytes(8 * max(nu, m, 1)))
    x = address(X)
    args = (ctypes.c_void_p * 6)(address(t), x, x + 8 * n, address(zeros) if nu else None, address(p),
                                 address(zeros) if m else None)
    strides = array("q", [1, nx, nx, 0, 0, 0])
    status = rt.crk_map(ctypes.byref(fun), N, 6, args, address(strides), ctypes.cast(address(out), C._DP), width)
    if status:
        return None
    cols = [out[i::width] for i in range(rec["nout"])]
    if rec["where"] is not None:
        dense = [None] * rec["dense"]
        for i, w in enumerate(rec["where"]):
            dense[w] = cols[i]
        cols = [v if v is not None else array("d", bytes(8 * N)) for v in dense]
    return dict(zip(rec["names"], cols))
