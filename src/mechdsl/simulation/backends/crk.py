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
import os
import threading
from pathlib import Path

import numpy as np

from ... import integrators as I
from ...eom import sxcode
from ...eom.codegen import NOT_CACHED, compile_functions, find_compiler
from ...interrupts import in_main_thread
from . import runtime_lib
from .crk_calls import CANCELLED, COMPANION_INTERRUPTED, CRK_METHODS, STATUS, counts  # noqa: F401  (crk.X for the back ends)
from .crk_calls import Fun, KeptPair, Loop, data_address, _I64P, _VP, _ptr, call_loop, declare, map_rows, pair_loop, program_fun, tables_in_loop


def _plain(grid, x0, p, u):
    return (np.ascontiguousarray(grid, float), np.ascontiguousarray(np.ravel(x0), float),
            np.ascontiguousarray(np.ravel(p), float), None if u is None else np.ascontiguousarray(np.ravel(u), float))


def _as_run(c, npts: int, nx: int, max_steps, hmin) -> I.Run:
    """A crk_calls.Call as an integrators.Run (numpy arrays)."""
    run = I.Run(X=np.frombuffer(c.X, float).reshape(npts, nx), reached=c.reached, stats=c.raw,
                interrupted=c.interrupted)
    if c.interrupted:
        run.error = "interrupted (Ctrl-C)"
    elif c.fail_time is not None:
        run.error = STATUS.get(c.status, f"status {c.status}").format(max_steps=max_steps, hmin=hmin)
        run.fail_time, run.fail_state = c.fail_time, np.array(c.fail_state)
    return run


def run_compiled(loop, method, grid, x0, p, u, rtol, atol, max_steps, hmin, progress, drive=None,
                 payback=None):
    """``call_loop`` as an integrators.Run (numpy arrays)."""
    grid, x0, p, u = _plain(grid, x0, p, u)
    c = call_loop(loop, method, grid, x0, p, u, rtol, atol, max_steps, hmin, progress, drive, payback)
    return _as_run(c, len(grid), x0.size, max_steps, hmin)


def run_pair(loop, first: tuple, loop2, second: tuple, progress):
    """``pair_loop`` as integrators.Runs: (the run, its companion's run, None or COMPANION_INTERRUPTED);
    ``first`` and ``second``: (method, grid, x0, p, u, rtol, atol, max_steps, hmin)."""
    def plain(a):
        method, grid, x0, p, u, *rest = a
        return (method, *_plain(grid, x0, p, u), *rest)
    first, second = plain(first), plain(second)
    c1, c2 = pair_loop(loop, first, loop2, second, progress)
    run = _as_run(c1, len(first[1]), first[2].size, first[7], first[8])
    if c2 is None or c2 is COMPANION_INTERRUPTED:
        return run, c2
    return run, _as_run(c2, len(second[1]), second[2].size, second[7], second[8])


def kept_pair(loop, first: tuple, loop2, second: tuple):
    """crk_calls.KeptPair of ``run_pair``'s arguments (numpy faces), or None."""
    def plain(a):
        method, grid, x0, p, u, *rest = a
        return (method, *_plain(grid, x0, p, u), *rest)
    return KeptPair.make(loop, plain(first), loop2, plain(second))


def run_kept_pair(kp, x0, p, x02, p2, progress, first_limits, second_limits):
    """``run_pair``'s answer from the KeptPair ``kp`` at these starts and parameters (1-D float
    arrays); ``*_limits``: (max_steps, hmin) of each run, for their error texts.  None when
    another thread is calling ``kp`` (run_pair then)."""
    got = kp.call(x0, p, x02, p2, progress)
    if got is None:
        return None
    c1, c2 = got
    run = _as_run(c1, kp.c1.npts, kp.c1.nx, *first_limits)
    if c2 is None or c2 is COMPANION_INTERRUPTED:
        return run, c2
    return run, _as_run(c2, kp.c2.npts, kp.c2.nx, *second_limits)


SOURCES = tuple(Path(p) for p in runtime_lib.SOURCES)
_LIBS: dict = {}
_LOCK = threading.Lock()
_RUNTIME: dict = {}

RUNTIME_FLAGS = runtime_lib.RUNTIME_FLAGS       # (their reasons: runtime_lib.py)
MODEL_FLAGS = ["-O1"]       # sxcode's chunks: within a few % of -O2 at 3/4 of its compile time
COMPILE_OPS = 12_000        # models up to this many operations are compiled (about a second of gcc)

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


def runtime():
    """(the runtime library (ctypes) or None, note): crk.c and vm.c, compiled once per cache
    folder and loaded once per process."""
    with _LOCK:
        hit = _RUNTIME.get("lib")
    if hit is not None:
        return hit
    if find_compiler() is None:
        return None, "no C compiler"
    units = runtime_lib.texts()
    installed = runtime_lib.packaged(units)
    if installed is not None:       # built when mechdsl was installed (runtime_lib.py): no gcc now
        try:
            return _keep((declare(ctypes.CDLL(installed)), ""))
        except (OSError, AttributeError):
            pass                    # (then built into the cache, as without it)
    loaded, note, path = compile_functions([], tag="crk", jacobian=False, extra_units=units,
                                           extra_flags=RUNTIME_FLAGS)
    lib = None
    if loaded is not None:
        try:
            lib = declare(ctypes.CDLL(path))
        except (OSError, AttributeError) as e:
            lib, note = None, f"cannot load the stepping loop's library {path}: {e}"
    return _keep((lib, note))


def _keep(out):
    with _LOCK:
        _RUNTIME.setdefault("lib", out)
        return _RUNTIME["lib"]


def loaded_runtime():
    """The runtime library when a run of this process has loaded it already, else None (nothing
    is compiled): the error estimate's comparison uses it (simulation/difference.py)."""
    hit = _RUNTIME.get("lib")
    return None if hit is None else hit[0]


_COMPILER: dict = {}
# os.environ's own dict where it has one (POSIX: bytes keys; os.environ.get costs about 1.5 us
# through its Mapping layers, and every run asks twice, checking its kept setups): the same values
_ENVIRON = getattr(os.environ, "_data", None)
if not isinstance(_ENVIRON, dict) or os.name != "posix":
    _ENVIRON = None
_CC, _PATH = (b"CC", b"PATH") if _ENVIRON is not None else ("CC", "PATH")


def _environ_strings():
    return os.environ


def compiler() -> str | None:
    """codegen.find_compiler, kept per $CC and $PATH (method = auto asks on every run)."""
    env = _ENVIRON if _ENVIRON is not None else _environ_strings()
    key = (env.get(_CC), env.get(_PATH))
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


def build_loop(funcs: dict, tag: str, engine: str, rent: bool = False):
    """(Loop or None, note) for the Functions ``funcs`` (name -> casadi.Function, each called by
    its name) in ``engine``.  ``rent`` (engine compiled): when the cache does not hold their
    library, the interpreted loop instead (``loop.rented``; the same bits), nothing compiled:
    the pay-back rule of payback.py decides when it is built."""
    rt, note = runtime()
    if rt is None:
        return None, note
    funs, keep = {}, []
    if engine == "interpreted":
        progs = {}
        for name, f in funcs.items():
            prog = progs[name] = sxcode.program(f)
            keep.append(prog)
            funs[name] = program_fun(rt, prog)
        loop = Loop(rt, funs, engine, keep)
        loop.spec = {"engine": engine, "runtime": rt._name, "programs": {n: p.arrays() for n, p in progs.items()}}
        return loop, ""
    mine = {n: f for n, f in funcs.items() if sxcode.supported(f)}
    theirs = [f for n, f in funcs.items() if n not in mine]
    try:
        # sxcode's sources in one translation unit (their helpers are guarded, their names
        # prefixed): one gcc process for the ode and its recorder instead of one each
        units = tuple(sxcode.c_source(f, n) for n, f in mine.items())
        rent = rent and not theirs          # (the interpreter runs SX Functions only)
        loaded, note, path = compile_functions(theirs, tag=tag, jacobian=False,
                                               extra_units=("\n".join(units),) if units else (),
                                               extra_flags=MODEL_FLAGS, cached_only=rent)
    except Exception as e:  # noqa: BLE001 - e.g. a Function CasADi cannot generate C for
        return None, f"cannot generate C for the model ({str(e).strip().splitlines()[-1][:200]})"
    if rent and loaded is None and note == NOT_CACHED:
        loop, note = build_loop({"ode": funcs["ode"]}, tag, "interpreted")     # (the others: their own programs)
        if loop is not None:
            loop.rented = True      # (and what to compile when it is bought: the same library)
            loop.rent_extra = {n: f for n, f in funcs.items() if n != "ode"}
        return loop, note
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
    loop = Loop(rt, funs, engine, [lib])
    loop.spec = {"engine": engine, "runtime": rt._name, "library": path, "functions": list(funcs)}
    return loop, note


class Mapped:
    """An SX Function evaluated at many points by the runtime's interpreter (``crk_map``): what
    the recorder evaluates on the output grid, without compiling and at about half the cost
    of CasADi's virtual machine."""

    def __init__(self, rt, f, loop=None, name=None, grouped=False):
        if loop is not None:        # the compiled code of f in a loop's library (the same bits)
            self.rt, self.prog, self._loop = rt, None, loop
            self.fun = loop.funs[name]
        else:
            self.rt, self.prog = rt, sxcode.program(f, grouped=grouped)    # grouped: the loop's program (sxcode)
            self.fun = program_fun(rt, self.prog)
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
        at = self._rows(t, X, n, p)
        if at is None:
            return None
        if self._by_address is None:
            fn = self.rt["crk_map"]          # a function pointer of its own: its argument types are these
            fn.restype, fn.argtypes = ctypes.c_int, [_VP, ctypes.c_longlong, ctypes.c_longlong, _VP, _VP, _VP,
                                                     ctypes.c_longlong]
            self._by_address = (fn, ctypes.addressof(self.fun))
        fn, fun = self._by_address
        nout = max(self.nout, 1)
        out = np.empty((npts, nout))
        ptrs, st = at
        status = fn(fun, npts, 6, ctypes.addressof(ptrs), st, data_address(out), nout)
        if status:
            raise RuntimeError(f"evaluation failed (status {status})")
        return out[:, :self.nout]

    def _rows(self, t, X, n: int, p):
        """(the input pointers, the strides' address) for evaluating at the rows of X (states and
        columns), or None when the Function or the arrays do not have that shape."""
        kept = self._shape(n, p)
        if (not kept or X.dtype != np.float64 or not X.flags.c_contiguous or X.shape != (len(t), 2 * n)
                or t.dtype != np.float64 or not t.flags.c_contiguous or not p.flags.c_contiguous
                or p.dtype != np.float64 or len(t) == 0):
            return None
        x = data_address(X)
        return (_VP * 6)(data_address(t), x, x + 8 * n, None, data_address(p) if p.size else None, None), kept[1]

    def _shape(self, n: int, p):
        """(the strides of states' inputs, their address) when the Function has states' shape
        for n coordinates and the parameters p, else False; worked out once per shape."""
        kept = self._kept_strides.get((n, p.size))
        if kept is None:
            fits = (self.where is None and len(self.nnz_in) == 6 and self.nnz_in[1] == n and self.nnz_in[2] == n
                    and not self.nnz_in[3] and not self.nnz_in[5] and self.nnz_in[0] == 1 and p.size == self.nnz_in[4])
            st = (ctypes.c_longlong * 6)(1, 2 * n, 2 * n, 0, 0, 0)
            kept = self._kept_strides[(n, p.size)] = (st, ctypes.addressof(st)) if fits else False
        return kept

    def columns(self, t, X, n: int, p):
        """``states``' values by column, (entries, npts) C order, and each column's extremes from
        the same pass (crk_map_cols: largest, smallest, ambiguous-zero flag, 3 x entries floats);
        None when ``states`` would answer None or the runtime predates crk_map_cols."""
        npts = len(t)
        at = self._rows(t, X, n, p) if self.nout >= 1 else None
        if at is None:
            return None
        fn = self.__dict__.get("_cols")
        if fn is None:
            try:
                fn = self.rt["crk_map_cols"]
            except AttributeError:
                fn = False
            else:
                fn.restype, fn.argtypes = ctypes.c_int, [_VP, ctypes.c_longlong, ctypes.c_longlong, _VP, _VP, _VP,
                                                         ctypes.c_longlong, _VP]
            self._cols = fn
        if fn is False:
            return None
        nout = self.nout
        out = np.empty((nout, npts))
        facts = np.empty(3 * nout)
        ptrs, st = at
        status = fn(ctypes.addressof(self.fun), npts, 6, ctypes.addressof(ptrs), st, data_address(out), nout,
                    data_address(facts))
        if status:
            raise RuntimeError(f"evaluation failed (status {status})")
        return out, facts.tolist()

    def __call__(self, npts: int, rows) -> np.ndarray:
        """Values (npts, entries of output 0, structural zeros included); ``rows``: per input an array of npts rows (its
        entries, C order) or one row shared by every point."""
        return map_rows(self.rt, self.fun, self.nnz_in, self.nout, self.dense, self.where, npts, rows)


def compiled_mapped(loop, name, f):
    """A Mapped of the Function ``f`` compiled as ``name`` in the library of ``loop`` (a Loop
    built with it, ``library(..., extra=...)``), or None when the loop does not have it."""
    if loop is None or name not in loop.funs or loop.engine != "compiled":
        return None
    return Mapped(loop.rt, f, loop=loop, name=name)


def mapped(f, grouped: bool = False):
    """A Mapped of the SX Function ``f``, or None (no runtime library, an MX Function).
    ``grouped``: the program the stepping loop runs (built once, kept: for a Function the loop
    will interpret), not the one for a few evaluations."""
    rt, _ = runtime()
    if rt is None or not sxcode.supported(f):
        return None
    return Mapped(rt, f, grouped=grouped)


def interpreted_rows(funcs):
    """For ``choose_method``'s stiffness test: ``rows(t0, X, u, p)``, the loop's ode at the
    columns of X (nx, k) by the interpreter program its run will use (a model the loop
    interprets, ``engine_for``), or None.  The same bits as CasADi's virtual machine on the
    same Function (each operation the same IEEE operation on the same operands), at 3-6x less
    cost: the 200-link chain's 801 evaluations took ~0.3 s in the virtual machine."""
    if getattr(funcs, "tables_only", False) or isinstance(funcs, LoopFunctions):
        return None
    ode = funcs["ode"]
    if loop_ode(funcs) is not ode or engine_for(ode) != "interpreted" or ode.n_in() != 4 or ode.n_out() != 1:
        return None
    m = mapped(ode, grouped=True)
    if m is None or m.where is not None:
        return None

    def rows(t0, X, u, p):
        return m(X.shape[1], [np.array([t0]), np.ascontiguousarray(X.T), u, p]).T
    return rows


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


def library(ode, tag: str = "model", engine: str | None = None, extra: dict | None = None, rent: bool = False):
    """(Loop or None, note) for the model Function ``ode`` (its engine: ``engine_for`` unless
    given); cached per Function and engine.  ``extra``: more Functions (name -> SX Function)
    compiled into the same library (one compile: a run's recorder, OdeSetup), part of the key.
    ``rent``: see ``build_loop``."""
    engine = engine or engine_for(ode)
    rent = rent and engine == "compiled"
    if not extra:
        return cached_library((id(ode), engine, rent), ode, {}, tag, engine, rent)
    key = (id(ode), engine, rent, *((n, id(f)) for n, f in sorted(extra.items())))
    return cached_library(key, ode, extra, tag, engine, rent)


def cached_library(key, ode, extra: dict, tag, engine, rent: bool = False):
    """(Loop or None, note): ``ode`` (dense output) and the Functions ``extra`` (name ->
    Function) in ``engine``; cached in memory under ``key``."""
    with _LOCK:
        hit = _LIBS.get(key)
    if hit is not None and hit[0] is ode:
        return hit[1], hit[2]
    try:
        loop, note = build_loop({"ode": dense_ode(ode), **extra}, tag, engine, rent)
    except sxcode.Unsupported as e:
        loop, note = None, f"cannot translate the model ({e})"
    with _LOCK:
        if len(_LIBS) >= 16:
            _LIBS.pop(next(iter(_LIBS)))
        _LIBS[key] = (ode, loop, note, tuple(extra.values()))     # (the extra Functions' ids stay theirs)
    return loop, note


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
    why = (f"{ops} operations a right-hand side: compiled (at most {COMPILE_OPS}), cached on disk (until the "
           "model's interpreted evaluations have paid for its compile it runs interpreted in C, the same bits)"
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

