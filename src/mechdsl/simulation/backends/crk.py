"""The compiled stepping loop: explicit Runge-Kutta in C, one C call per run.

Methods ``dopri5`` (Dormand-Prince 5(4)) and ``dop853`` (Dormand-Prince 8(5,3)), each with
the step-size control, initial step, error norm and dense output of scipy's RK45 and DOP853
(``crk.c`` beside this file, a small hand-written driver).  The driver and the interpreter of
``vm.c`` are one model-independent library (the *runtime*, compiled once per cache folder
with the cached compile machinery of ``mechdsl.eom.codegen``); the model's Functions reach it
as ``Fun`` records, in one of two engines that give the same bits (tests/test_sxcode.py):

``compiled``
    the model's C (``mechdsl.eom.sxcode.c_source`` for SX Functions, CasADi's code generator
    for the others) in a library of its own, cached by its code;
``interpreted``
    programs of vm.c's interpreter (``sxcode.program``): nothing to compile.

``engine_for(f)`` decides from the Function alone (its operation count), never from what the
cache holds, so a run's metadata and numbers do not depend on what ran before.  Runs are one
ctypes call in a worker thread (ctypes releases the GIL; the main thread shows progress from
the rows written and can cancel).  No Jacobian is generated.

Without a C compiler, or when the model's code cannot be translated or compiled, the same
algorithm runs as scipy's RK45/DOP853 stepped in Python on the virtual machine (the same
steps up to round-off), and the run's warnings say so.

The outcome is a ``mechdsl.integrators.Run`` like every other integrator plug-in's (plugins.py).
"""
from __future__ import annotations

import ctypes
import threading
from pathlib import Path

import numpy as np

from ... import integrators as I
from ...eom import sxcode
from ...eom.codegen import compile_functions, find_compiler
from ...interrupts import in_main_thread


# method -> (id in crk.c, scipy class of the same algorithm)
CRK_METHODS = {"dopri5": (0, "RK45"), "dop853": (1, "DOP853")}
SOURCES = (Path(__file__).with_name("crk.c"), Path(__file__).with_name("vm.c"))
STATUS = {1: "more than {max_steps} steps in one output interval (max_num_steps)",
          2: "error control needs a step below the minimum {hmin:.3g} (min_step_size)",
          3: "Required step size is less than spacing between numbers.",
          4: "non-finite state",
          5: "cancelled",
          6: "out of memory in the compiled stepping loop",
          7: "the right-hand side returned an error (non-finite or failed evaluation, NaN)",
          8: "unknown method"}
# crk.c, vm.c (compiled once per cache folder, in a first run): crk.c at -O1 takes gcc 0.36 s
# (-Og 0.19 s, but its loop steps about 5 % slower: pendulum, 2544 steps, 5.55 ms against 5.3 ms;
# every later run pays that, so the one-time compile keeps -O1); the interpreter of vm.c is 1.4x
# faster at -O2.  Same bits at every level (no fast-math, no FMA contraction on x86-64).
RUNTIME_FLAGS = (["-O1"], ["-O2"])
MODEL_FLAGS = ["-O1"]       # sxcode's chunks: within a few % of -O2 at 3/4 of its compile time
COMPILE_OPS = 12_000        # models up to this many operations are compiled (about a second of gcc)

CANCELLED = 5        # ctl[1] set: the loop stopped at its next step (Ctrl-C)

_LIBS: dict = {}
_LOCK = threading.Lock()
_RUNTIME: dict = {}
_I64P = ctypes.POINTER(ctypes.c_longlong)
_DP = ctypes.POINTER(ctypes.c_double)
_VP = ctypes.c_void_p


class Fun(ctypes.Structure):
    """crk.c's Fun: how the loop calls one model Function."""
    _fields_ = [("eval", _VP), ("ctx", _VP), ("init", _VP), ("sz_arg", ctypes.c_longlong),
                ("sz_res", ctypes.c_longlong), ("sz_iw", ctypes.c_longlong), ("sz_w", ctypes.c_longlong)]


def dense_ode(ode):
    """``ode`` with a dense output column (the C loop reads xdot as a dense vector)."""
    if ode.sparsity_out(0).is_dense():
        return ode
    import casadi as ca

    if ode.is_a("SXFunction"):
        args = [ca.SX.sym(ode.name_in(i), ode.sparsity_in(i)) for i in range(ode.n_in())]
    else:
        args = [ca.MX.sym(ode.name_in(i), ode.sparsity_in(i)) for i in range(ode.n_in())]
    outs = ode.call(args)
    return ca.Function(ode.name(), args, [ca.densify(o) for o in outs], ode.name_in(), ode.name_out())


RUN_ARGTYPES = [ctypes.POINTER(Fun), ctypes.c_int, ctypes.c_longlong, _DP, ctypes.c_longlong, _DP, _DP, _DP,
                ctypes.c_double, ctypes.c_double, ctypes.c_double, ctypes.c_longlong, _DP, _DP, _I64P, _DP]
EVENTS_ARGTYPES = RUN_ARGTYPES + [ctypes.POINTER(Fun), ctypes.c_longlong, ctypes.c_double, ctypes.c_int, _DP,
                                  ctypes.POINTER(Fun), _DP, _DP, _DP, ctypes.c_longlong]

# crk_run as run_compiled calls it: every array by its address (an int: numpy's data_as costs
# 4.5 us an array, a tenth of a small model's whole run)
LOOP_ARGTYPES = [ctypes.POINTER(Fun), ctypes.c_int, ctypes.c_longlong, _VP, ctypes.c_longlong, _VP, _VP, _VP,
                 ctypes.c_double, ctypes.c_double, ctypes.c_double, ctypes.c_longlong, _VP, _VP, _VP, _VP, _VP, _VP]


def runtime():
    """(the runtime library (ctypes) or None, note): crk.c and vm.c, compiled once per cache
    folder and loaded once per process."""
    with _LOCK:
        hit = _RUNTIME.get("lib")
    if hit is not None:
        return hit
    if find_compiler() is None:
        return None, "no C compiler"
    loaded, note, path = compile_functions([], tag="crk", jacobian=False,
                                           extra_units=tuple(p.read_text() for p in SOURCES),
                                           extra_flags=RUNTIME_FLAGS)
    lib = None
    if loaded is not None:
        try:
            lib = ctypes.CDLL(path)
            for name, args in (("crk_run", LOOP_ARGTYPES), ("crk_run_events", EVENTS_ARGTYPES),
                               ("crk_eval_n", [ctypes.POINTER(Fun), ctypes.c_double, _DP, _DP, _DP, _DP,
                                               ctypes.c_longlong]),
                               ("crk_map", [ctypes.POINTER(Fun), ctypes.c_longlong, ctypes.c_longlong, _VP, _VP,
                                            _DP, ctypes.c_longlong])):
                fn = getattr(lib, name)
                fn.restype, fn.argtypes = ctypes.c_int, args
            lib.crk_run_batch.restype = ctypes.c_longlong
            lib.crk_run_batch.argtypes = [ctypes.POINTER(Fun), ctypes.c_int, ctypes.c_longlong, _DP, ctypes.c_longlong,
                                          ctypes.c_longlong, _DP, _DP, _DP, ctypes.c_longlong, ctypes.c_double,
                                          ctypes.c_double, ctypes.c_double, ctypes.c_longlong, _DP, _DP, _I64P,
                                          _I64P, _I64P]
        except (OSError, AttributeError) as e:
            lib, note = None, f"cannot load the stepping loop's library {path}: {e}"
    out = (lib, note)
    with _LOCK:
        _RUNTIME.setdefault("lib", out)
        return _RUNTIME["lib"]


_COMPILER: dict = {}


def compiler() -> str | None:
    """codegen.find_compiler, kept per $CC and $PATH (method = auto asks on every run)."""
    import os

    key = (os.environ.get("CC"), os.environ.get("PATH"))
    if key not in _COMPILER:
        _COMPILER.clear()
        _COMPILER[key] = find_compiler()
    return _COMPILER[key]


def engine_for(f) -> str:
    """``compiled`` or ``interpreted``: from the Function alone (deterministic: not from what the
    cache holds).  SX Functions of at most COMPILE_OPS operations are compiled (their compile
    takes up to about a second and is cached on disk by the code), larger ones interpreted (a
    first run of a 200-link chain would otherwise spend seconds in gcc); others (MX: the
    numeric linear solve) are compiled by CasADi's code generator, which the interpreter does
    not run."""
    if not f.is_a("SXFunction"):
        return "compiled"
    return "compiled" if f.n_instructions() <= COMPILE_OPS else "interpreted"


class Loop:
    """The model's Functions as the runtime calls them (``funs``: name -> Fun), the runtime's
    entry points, and what keeps both alive (programs, the model's library)."""

    def __init__(self, rt, funs: dict, engine: str, keep):
        self.rt, self.funs, self.engine, self._keep = rt, funs, engine, keep
        self.run = rt.crk_run
        self.run_events = rt.crk_run_events

    def fun(self, name):
        f = self.funs.get(name)
        return None if f is None else ctypes.byref(f)


def build_loop(funcs: dict, tag: str, engine: str):
    """(Loop or None, note) for the Functions ``funcs`` (name -> casadi.Function, each called by
    its name) in ``engine``."""
    rt, note = runtime()
    if rt is None:
        return None, note
    funs, keep = {}, []
    if engine == "interpreted":
        ev = ctypes.cast(rt.vm_eval, _VP).value
        init = ctypes.cast(rt.vm_init, _VP).value
        for name, f in funcs.items():
            prog = sxcode.program(f)
            keep.append(prog)
            funs[name] = Fun(ev, ctypes.addressof(prog.prog), init, f.n_in(), f.n_out(), 0, prog.nreg)
        return Loop(rt, funs, engine, keep), ""
    mine = {n: f for n, f in funcs.items() if sxcode.supported(f)}
    theirs = [f for n, f in funcs.items() if n not in mine]
    try:
        # sxcode's sources in one translation unit (their helpers are guarded, their names
        # prefixed): one gcc process for the ode and its recorder instead of one each
        units = tuple(sxcode.c_source(f, n) for n, f in mine.items())
        loaded, note, path = compile_functions(theirs, tag=tag, jacobian=False,
                                               extra_units=("\n".join(units),) if units else (),
                                               extra_flags=MODEL_FLAGS)
    except Exception as e:  # noqa: BLE001 - e.g. a Function CasADi cannot generate C for
        return None, f"cannot generate C for the model ({str(e).strip().splitlines()[-1][:200]})"
    if loaded is None:
        return None, note
    try:
        lib = ctypes.CDLL(path)
        ev = ctypes.cast(rt.crk_casadi_eval, _VP).value
        for name in funcs:
            sz = [ctypes.c_longlong(0) for _ in range(4)]
            getattr(lib, name + "_work")(*map(ctypes.byref, sz))
            funs[name] = Fun(ev, ctypes.cast(getattr(lib, name), _VP).value, None, *(v.value for v in sz))
    except (OSError, AttributeError) as e:
        return None, f"cannot load the model's library {path}: {e}"
    return Loop(rt, funs, engine, [lib]), note


class Mapped:
    """An SX Function evaluated at many points by the runtime's interpreter (``crk_map``): what
    the recorder evaluates on the output grid, without compiling and at about half the cost
    of CasADi's virtual machine."""

    def __init__(self, rt, f, loop=None, name=None):
        if loop is not None:        # the compiled code of f in a loop's library (the same bits)
            self.rt, self.prog, self._loop = rt, None, loop
            self.fun = loop.funs[name]
        else:
            self.rt, self.prog = rt, sxcode.program(f)
            self.fun = Fun(ctypes.cast(rt.vm_eval, _VP).value, ctypes.addressof(self.prog.prog),
                           ctypes.cast(rt.vm_init, _VP).value, f.n_in(), f.n_out(), 0, self.prog.nreg)
        self.nnz_in = [f.nnz_in(i) for i in range(f.n_in())]
        self.nout = f.nnz_out(0)
        sp = f.sparsity_out(0)      # the program writes the nonzeros: entries that are structurally 0 are not
        self.dense = sp.numel()
        self.where = None if sp.is_dense() else np.array(sp.find(), dtype=np.int64)
        self._by_address = None     # crk_map with every pointer an address (states())
        self._kept_strides = {}

    def states(self, t, X, n: int, p):
        """The recorder's Function (t, q, qd, u, p, lam) at the rows of the trajectory X (npts, 2n,
        C order, float): q and qd read in place (strides of 2n), no u and no multipliers (a
        model without inputs or constraints), p shared.  The values of ``__call__`` on the same
        rows (one evaluation per row of the same code), as (npts, entries); None when the
        Function does not have that shape (the caller then uses ``__call__``)."""
        npts = len(t)
        if (self.where is not None or len(self.nnz_in) != 6 or self.nnz_in[1] != n or self.nnz_in[2] != n
                or self.nnz_in[3] or self.nnz_in[5] or self.nnz_in[0] != 1 or p.size != self.nnz_in[4]
                or X.dtype != np.float64 or not X.flags.c_contiguous or X.shape != (npts, 2 * n)
                or t.dtype != np.float64 or not t.flags.c_contiguous or not p.flags.c_contiguous
                or p.dtype != np.float64 or npts == 0):
            return None
        if self._by_address is None:
            fn = self.rt["crk_map"]          # a function pointer of its own: its argument types are these
            fn.restype, fn.argtypes = ctypes.c_int, [_VP, ctypes.c_longlong, ctypes.c_longlong, _VP, _VP, _VP,
                                                     ctypes.c_longlong]
            self._by_address = (fn, ctypes.addressof(self.fun))
        fn, fun = self._by_address
        st = self._kept_strides.get(n)
        if st is None:
            st = self._kept_strides[n] = (ctypes.c_longlong * 6)(1, 2 * n, 2 * n, 0, 0, 0)
        out = np.empty((npts, max(self.nout, 1)))
        x = X.ctypes.data
        ptrs = (_VP * 6)(t.ctypes.data, x, x + 8 * n, None, p.ctypes.data if p.size else None, None)
        status = fn(fun, npts, 6, ctypes.addressof(ptrs), ctypes.addressof(st), out.ctypes.data, out.shape[1])
        if status:
            raise RuntimeError(f"evaluation failed (status {status})")
        return out[:, :self.nout]

    def __call__(self, npts: int, rows) -> np.ndarray:
        """Values (npts, entries of output 0, structural zeros included); ``rows``: per input an array of npts rows (its
        entries, C order) or one row shared by every point."""
        arrs, strides = [], []
        for a, nnz in zip(rows, self.nnz_in):
            a = np.ascontiguousarray(a, float)
            shared = a.size == nnz and not (npts == 1 and a.ndim > 1)
            arrs.append(a)
            strides.append(0 if shared or nnz == 0 else nnz)
        out = np.zeros((npts, max(self.nout, 1)))
        ptrs = (_VP * len(arrs))(*[a.ctypes.data if a.size else None for a in arrs])
        st = np.array(strides, dtype=np.int64)
        status = self.rt.crk_map(ctypes.byref(self.fun), npts, len(arrs), ptrs, st.ctypes.data, _ptr(out),
                                 out.shape[1])
        if status:
            raise RuntimeError(f"evaluation failed (status {status})")
        if self.where is None:
            return out[:, :self.nout]
        full = np.zeros((npts, self.dense))
        full[:, self.where] = out[:, :self.nout]
        return full


def compiled_mapped(loop, name, f):
    """A Mapped of the Function ``f`` compiled as ``name`` in the library of ``loop`` (a Loop
    built with it, ``library(..., extra=...)``), or None when the loop does not have it."""
    if loop is None or name not in loop.funs or loop.engine != "compiled":
        return None
    return Mapped(loop.rt, f, loop=loop, name=name)


def mapped(f):
    """A Mapped of the SX Function ``f``, or None (no runtime library, an MX Function)."""
    rt, _ = runtime()
    if rt is None or not sxcode.supported(f):
        return None
    return Mapped(rt, f)


def rhs_seconds(loop, x, u, p, reps: int) -> float:
    """CPU seconds of one evaluation of the loop's ``ode`` at (0, x, u, p), from ``reps``
    evaluations in C (the right-hand side's own cost, without the loop)."""
    import time

    x, u, p = (np.ascontiguousarray(np.ravel(v), float) for v in (x, u, p))
    out = np.zeros(x.size)
    c = time.process_time()
    status = loop.rt.crk_eval_n(loop.fun("ode"), 0.0, _ptr(x), _ptr(u), _ptr(p), _ptr(out), int(reps))
    dt = time.process_time() - c
    if status:
        raise RuntimeError(f"the right-hand side failed (status {status})")
    return dt / reps


def library(ode, tag: str = "model", engine: str | None = None, extra: dict | None = None):
    """(Loop or None, note) for the model Function ``ode`` (its engine: ``engine_for`` unless
    given); cached per Function and engine.  ``extra``: more Functions (name -> SX Function)
    compiled into the same library (one compile: a run's recorder, OdeSetup), part of the key."""
    engine = engine or engine_for(ode)
    if not extra:
        return cached_library((id(ode), engine), ode, {}, tag, engine)
    key = (id(ode), engine, *((n, id(f)) for n, f in sorted(extra.items())))
    return cached_library(key, ode, extra, tag, engine)


def cached_library(key, ode, extra: dict, tag, engine):
    """(Loop or None, note): ``ode`` (dense output) and the Functions ``extra`` (name ->
    Function) in ``engine``; cached in memory under ``key``."""
    with _LOCK:
        hit = _LIBS.get(key)
    if hit is not None and hit[0] is ode:
        return hit[1], hit[2]
    try:
        loop, note = build_loop({"ode": dense_ode(ode), **extra}, tag, engine)
    except sxcode.Unsupported as e:
        loop, note = None, f"cannot translate the model ({e})"
    with _LOCK:
        if len(_LIBS) >= 16:
            _LIBS.pop(next(iter(_LIBS)))
        _LIBS[key] = (ode, loop, note, tuple(extra.values()))     # (the extra Functions' ids stay theirs)
    return loop, note


def _ptr(a):
    return a.ctypes.data_as(_DP)


def call_in_thread(call, ctl, tick=None):
    """``call()`` (a ctypes call of the loop, which releases the GIL) in a worker thread; the main
    thread calls ``tick(rows written)`` every 0.1 s from the progress word ctl[0] and, on Ctrl-C,
    sets ctl[1]: the loop stops at its next step, and once it has (the rows written so far, its
    statistics and state are then complete) the interrupt goes on.  The status, or 7 when the
    call raised.  ``call`` keeps the buffers it passes alive while the worker runs."""
    box = {}

    def work():
        box["status"] = call()

    th = threading.Thread(target=work, name="mechdsl-crk", daemon=True)
    th.start()
    try:
        while th.is_alive():
            th.join(0.1)
            if ctl[0] and tick is not None:
                tick(int(ctl[0]))
    except BaseException:
        ctl[1] = 1          # ask the loop to stop at its next step, then let the interrupt through
        while th.is_alive():
            try:
                th.join()
            except KeyboardInterrupt:     # a second Ctrl-C while the loop finishes its step
                pass
        raise
    return box.get("status", 7)


def call_here_or_in_thread(call, ctl, tick=None):
    """``call()`` directly when nothing needs the main thread meanwhile (no progress to show, not
    the main thread: no Ctrl-C arrives), else through ``call_in_thread``."""
    if tick is None and not in_main_thread():
        return call()
    return call_in_thread(call, ctl, tick)


class Resume(ctypes.Structure):
    """crk.c's Resume: the state of a run in slices."""
    _fields_ = [("slice", ctypes.c_double), ("started", ctypes.c_int), ("t", ctypes.c_double),
                ("h_abs", ctypes.c_double), ("k", ctypes.c_longlong), ("steps", ctypes.c_longlong),
                ("rejected", ctypes.c_longlong), ("steps_here", ctypes.c_longlong), ("nfev", ctypes.c_longlong),
                ("y", _VP), ("f", _VP)]


class _Tab(ctypes.Structure):
    _fields_ = [("hold", ctypes.c_int), ("n", ctypes.c_longlong), ("t", _DP), ("v", _DP), ("cur", ctypes.c_longlong)]


class _Drive(ctypes.Structure):
    _fields_ = [("nu", ctypes.c_longlong), ("tab", ctypes.POINTER(_Tab)), ("u0", _DP), ("u", _DP),
                ("nb", ctypes.c_longlong), ("breaks", _DP), ("bcur", ctypes.c_longlong)]


def tables_in_loop(drive) -> bool:
    """Whether the loop reads every input itself: constants and tables only (a Python callable
    or a Function of (t, x) is closed into the model's ode instead)."""
    return drive is not None and bool(drive.signals) and all(
        s.kind in ("default", "constant", "table") for s in drive.signals) and not drive.constant


def loop_drive(drive, t0, t1, u0):
    """(crk.c's Drive for one run, what keeps its arrays alive): the tables as data, their
    samples inside (t0, t1) the times steps end on."""
    sigs = drive.signals
    tabs = (_Tab * max(len(sigs), 1))()
    keep = []
    for j, s in enumerate(sigs):
        if s.kind == "table":
            tt = np.ascontiguousarray(s.table.times, float)
            vv = np.ascontiguousarray(s.table.values, float)
            keep += [tt, vv]
            tabs[j] = _Tab(0 if s.table.hold == "zoh" else 1, tt.size, _ptr(tt), _ptr(vv), 0)
    # steps end on every sample: a hold's jump, and a linear table's kink (stepping across kinks
    # left errors 1000 times the tolerance on the cart-pole with 11 samples)
    held = [s.table.times for s in sigs if s.kind == "table"]
    tol = 1e-12 * max(1.0, abs(t0), abs(t1))
    br = np.unique(np.concatenate(held)) if held else np.zeros(0)
    br = np.ascontiguousarray(br[(br > t0 + tol) & (br < t1 - tol)], float)
    u0 = np.ascontiguousarray(u0, float)
    u = np.zeros(max(len(sigs), 1))
    keep += [br, u0, u, tabs]
    return _Drive(len(sigs), tabs, _ptr(u0), _ptr(u), br.size, _ptr(br), 0), keep


SLICE = 0.05            # seconds (monotonic clock) of one C call of a run: progress and Ctrl-C between calls
YIELD = 11


def run_compiled(loop, method, grid, x0, p, u, rtol, atol, max_steps, hmin, progress, drive=None,
                 payback=None) -> I.Run:
    """The run as C calls of SLICE seconds each in the calling thread (the state carried
    from call to call: the steps are those of one call), progress shown and Ctrl-C let through
    between calls; a short run is one call (no thread is started: 0.12 ms of CPU a run).
    ``payback`` (payback.Payback, an interpreted run): between calls, the compiled loop once the
    interpreted evaluations have paid for its compile (the same bits: only the cost changes)."""
    grid = np.ascontiguousarray(grid, float)
    nx = x0.size
    X = np.empty((len(grid), nx))
    X.fill(np.nan)
    pc = np.ravel(p)
    uc = np.zeros(0) if u is None else np.ravel(u)
    # one buffer for the small arrays, each passed by its address: stats (4), the progress and
    # cancel words ctl (2, int64), xfail (nx), the carried y and f (nx each), x0, p, u
    m, npar, nu = max(nx, 1), pc.size, uc.size
    W = np.zeros(6 + 3 * m + m + npar + nu)
    stats, ctl = W[:4], W[4:6].view(np.int64)
    xfail = W[6:6 + nx]
    o = 6 + 3 * m
    W[o:o + nx] = x0
    W[o + m:o + m + npar] = pc
    W[o + m + npar:o + m + npar + nu] = uc
    a = W.ctypes.data
    rs = Resume(SLICE, 0, 0.0, 0.0, 0, 0, 0, 0, 0, a + 8 * (6 + m), a + 8 * (6 + 2 * m))
    drv, keep = loop_drive(drive, float(grid[0]), float(grid[-1]), uc) if tables_in_loop(drive) else (None, ())
    args = (loop.fun("ode"), CRK_METHODS[method][0], nx, grid.ctypes.data, len(grid), a + 8 * o, a + 8 * (o + m + npar),
            a + 8 * (o + m), float(rtol), float(atol), float(hmin), int(max_steps), X.ctypes.data, a, a + 32,
            a + 48, ctypes.byref(rs), None if drv is None else ctypes.byref(drv))
    interrupted = False
    try:
        while True:
            status = loop.run(*args)
            if status != YIELD:
                break
            progress.update(float(grid[max(int(ctl[0]), 1) - 1]))
            if payback is not None and loop.engine == "interpreted":
                better = payback.check(int(rs.nfev))
                if better is not None:          # the rest of the run in compiled code
                    loop, args = better, (better.fun("ode"),) + args[1:]
    except KeyboardInterrupt:            # Ctrl-C between slices: the rows written so far are kept
        status, interrupted = CANCELLED, True
    reached = int(ctl[0])
    progress.update(float(grid[max(reached, 1) - 1]))
    raw = {"n_steps": int(stats[0]), "n_rhs": int(stats[1]), "n_reject": int(stats[2]), "status": int(status),
           "engine": loop.engine}
    if payback is not None:
        payback.record(int(stats[1]))
        if payback.switched_at is not None and payback.switched_at >= 0:
            raw["compiled_after"] = payback.switched_at       # evaluations made interpreted first
    run = I.Run(X=X, reached=reached, stats=raw, interrupted=interrupted)
    if interrupted:
        run.error = "interrupted (Ctrl-C)"
    elif status != 0 or reached < len(grid):
        t_end = float(stats[3])
        run.error = STATUS.get(status, f"status {status}").format(max_steps=max_steps, hmin=hmin)
        run.fail_time, run.fail_state = t_end, xfail.copy()
    del keep
    return run


def run_batch(loop, method, grid, X0, P, u, rtol, atol, max_steps, hmin):
    """An ensemble in one C call (crk_run_batch): run j from X0[j] at the parameters P[j], the
    inputs u shared, each taking the steps a single run takes.  Returns (X (m, ngrid, nx),
    stats (m, 4): steps, evaluations, rejected, last time; status (m); rows reached (m))."""
    grid = np.ascontiguousarray(grid, float)
    X0 = np.ascontiguousarray(np.atleast_2d(X0), float)
    m, nx = X0.shape
    P = np.ascontiguousarray(np.reshape(P, (m, -1)), float)
    uc = np.ascontiguousarray(np.zeros(0) if u is None else np.ravel(u), float)
    X = np.full((m, len(grid), nx), np.nan)
    stats = np.zeros((m, 4))
    status = np.zeros(m, dtype=np.int64)
    reached = np.zeros(m, dtype=np.int64)
    ctl = np.zeros(2, dtype=np.int64)

    def call():
        return loop.rt.crk_run_batch(loop.fun("ode"), CRK_METHODS[method][0], nx, _ptr(grid), len(grid), m,
                                     _ptr(X0), _ptr(uc), _ptr(P), P.shape[1], float(rtol), float(atol), float(hmin),
                                     int(max_steps), _ptr(X), _ptr(stats), status.ctypes.data_as(_I64P),
                                     reached.ctypes.data_as(_I64P), ctl.ctypes.data_as(_I64P))

    call_here_or_in_thread(call, ctl)     # Ctrl-C stops the ensemble before its next run, then goes on
    return X, stats, status, reached


# --------------------------------------------------------------------------- method = auto

# auto: dopri5 at rtol >= this, dop853 below (benchmarks/auto_wp.py, issue 24 item 1: at rtol 1e-2..1e-4
# dopri5 took 0.6-0.9 of dop853's CPU at the same tolerance on the double pendulum and the 5- and
# 30-link chains, and no other run as accurate as it was cheaper by more than noise; from 1e-5 on
# dop853 is the cheaper one at equal accuracy).  A rule of the tolerance alone: deterministic.
DOPRI5_RTOL = 1e-4


def rhs_cost(f) -> int | None:
    """Operations of one evaluation of a CasADi Function: SX instructions, through calls, plus
    n^3 for a linear solve of size n (deterministic: no timing).  None when it calls a Function
    that has no C code (a Python callback: a time-varying input given as a callable)."""
    import casadi as ca

    if f.is_a("SXFunction"):
        return int(f.n_instructions())
    if not f.is_a("MXFunction"):
        return None
    total = 0
    for i in range(f.n_instructions()):
        total += 1
        op = f.instruction_id(i)
        if op == ca.OP_CALL:
            inner = rhs_cost(f.instruction_MX(i).which_function())
            if inner is None:
                return None
            total += inner
        elif op == ca.OP_SOLVE:
            total += int(f.instruction_MX(i).dep(1).size1()) ** 3
    return total


class LoopFunctions(dict):
    """The Functions of a loop run (``funcs``' own, for the failure diagnosis and the Python
    fallback) with the Function the loop integrates and its engine, decided once by the back
    end (``compiled = true`` compiles whatever the size)."""

    def __init__(self, funcs, ode, engine, drive=None, loop=None):
        super().__init__()
        self.funcs, self.loop_ode, self.engine = funcs, ode, engine
        self.loop = loop            # the Loop built for them (None: looked up by ``library``)
        self.drive = drive if tables_in_loop(drive) else None      # tables read by the loop
        self.eom = getattr(funcs, "eom", None)
        self.notes = list(getattr(funcs, "notes", []))

    def __missing__(self, name):
        return self.funcs[name]


def loop_ode(funcs):
    """The Function the loop integrates for the Functions ``funcs`` of a run: the model's own
    ``ode`` as an SX Function where it has one (``Model.casadi()``'s: for M qdd = bias the
    unrolled LDL^T solve, ``codegen.ldl_solve``, up to SX_SOLVE_MAX coordinates; small models'
    leaned, ``eom.lean``), which both engines run; otherwise ``funcs["ode"]`` (a closed loop
    with input signals, larger Lagrange-route models)."""
    from ...eom.codegen import SX_SOLVE_MAX, FunctionSet, casadi_functions

    if isinstance(funcs, LoopFunctions):
        return funcs.loop_ode
    if getattr(funcs, "tables_only", False):      # the loop reads the tables: the model's own ode
        funcs = funcs.base
    ode = funcs["ode"]
    eom = getattr(funcs, "eom", None)
    if (not isinstance(funcs, FunctionSet) or eom is None or funcs.fixed or funcs.want_compiled or funcs.sx
            or (eom.n > SX_SOLVE_MAX and not ode.is_a("SXFunction"))):
        return ode
    return casadi_functions(eom, names=("ode",), sx=True)["ode"]


def auto_choice(eom, funcs, x0, pv, t0, t1, rtol, u, rho=None) -> tuple[str | None, str, dict]:
    """(method or None, reason, numbers) for method = auto on a non-stiff model: the stepping
    loop, dop853 (dopri5 at rtol >= DOPRI5_RTOL), its engine by ``engine_for``; None (erk in the
    virtual machine) without a C compiler or when the right-hand side calls Python.  From the
    model and the options alone: the same choice whatever the cache holds."""
    if compiler() is None:
        return None, "no C compiler", {}
    ode = loop_ode(funcs)
    ops = rhs_cost(ode)
    if ops is None:
        return None, "the right-hand side calls Python (an input given as a callable): no C code for it", {}
    method = loop_method(rtol)
    engine = engine_for(ode)
    info = {"rhs_operations": ops, "engine": engine}
    why = (f"{ops} operations a right-hand side: compiled (at most {COMPILE_OPS}), cached on disk"
           if engine == "compiled" else
           f"{ops} operations a right-hand side: interpreted in C (above {COMPILE_OPS}, a first run would "
           "spend seconds compiling; compiled once its interpreted evaluations have paid for that, "
           "the same bits; compiled = true compiles)")
    return method, why, info


def loop_method(rtol: float) -> str:
    """The stepping loop's method when the choice is automatic (auto_choice; the FMU's
    co-simulation stepper, mechdsl.export): dopri5 at rtol >= DOPRI5_RTOL, else dop853."""
    return "dopri5" if rtol >= DOPRI5_RTOL else "dop853"


def scipy_name(method: str) -> str:
    """The scipy method (in mechdsl's names) that a compiled loop's method runs as in Python."""
    return "scipy-" + CRK_METHODS[method][1].lower()

