"""The compiled stepping loop's runtime as ctypes sees it: its records (Fun, Resume, Drive),
its entry points' argument types and the calls of a run (``call_loop``) and of a map
(``map_rows``).  Without CasADi (crk.py builds the loops; a prepared warm run, warm_run.py,
loads the libraries by path and calls them through here alone) and without numpy at import:
``call_loop`` runs on array.array buffers (a prepared warm run imports no numpy; crk.run_compiled
is its numpy face), ``map_rows`` and ``loop_drive`` import numpy when called."""
from __future__ import annotations

import ctypes
import threading
from array import array

from ...eom.vmprog import Program, address, data_address  # noqa: F401  (crk.data_address)

# method -> (id in crk.c, scipy class of the same algorithm)
CRK_METHODS = {"dopri5": (0, "RK45"), "dop853": (1, "DOP853")}
STATUS = {1: "more than {max_steps} steps in one output interval (max_num_steps)",
          2: "error control needs a step below the minimum {hmin:.3g} (min_step_size)",
          3: "Required step size is less than spacing between numbers.",
          4: "non-finite state",
          5: "cancelled",
          6: "out of memory in the compiled stepping loop",
          7: "the right-hand side returned an error (non-finite or failed evaluation, NaN)",
          8: "unknown method"}

CANCELLED = 5        # ctl[1] set: the loop stopped at its next step (Ctrl-C)

_I64P = ctypes.POINTER(ctypes.c_longlong)
_DP = ctypes.POINTER(ctypes.c_double)
_VP = ctypes.c_void_p


class Fun(ctypes.Structure):
    """crk.c's Fun: how the loop calls one model Function."""
    _fields_ = [("eval", _VP), ("ctx", _VP), ("init", _VP), ("sz_arg", ctypes.c_longlong),
                ("sz_res", ctypes.c_longlong), ("sz_iw", ctypes.c_longlong), ("sz_w", ctypes.c_longlong)]


RUN_ARGTYPES = [ctypes.POINTER(Fun), ctypes.c_int, ctypes.c_longlong, _DP, ctypes.c_longlong, _DP, _DP, _DP,
                ctypes.c_double, ctypes.c_double, ctypes.c_double, ctypes.c_longlong, _DP, _DP, _I64P, _DP]
EVENTS_ARGTYPES = RUN_ARGTYPES + [ctypes.POINTER(Fun), ctypes.c_longlong, ctypes.c_double, ctypes.c_int, _DP,
                                  ctypes.POINTER(Fun), _DP, _DP, _DP, ctypes.c_longlong]

# crk_run as call_loop calls it: every array by its address (an int: numpy's data_as costs
# 4.5 us an array, a tenth of a small model's whole run)
LOOP_ARGTYPES = [ctypes.POINTER(Fun), ctypes.c_int, ctypes.c_longlong, _VP, ctypes.c_longlong, _VP, _VP, _VP,
                 ctypes.c_double, ctypes.c_double, ctypes.c_double, ctypes.c_longlong, _VP, _VP, _VP, _VP, _VP, _VP]


# crk_run_pair's second run (after crk_run's arguments): no nx (the same model's) and no Drive
PAIR_ARGTYPES = [ctypes.POINTER(Fun), ctypes.c_int, _VP, ctypes.c_longlong, _VP, _VP, _VP, ctypes.c_double,
                 ctypes.c_double, ctypes.c_double, ctypes.c_longlong, _VP, _VP, _VP, _VP, _VP, _VP, _VP]


def _ptr(a):
    return a.ctypes.data_as(_DP)       # (a numpy array)


def declare(lib):
    """Set the argument and result types of the runtime library's entry points (``lib``: ctypes.CDLL)."""
    for name, args in (("crk_run", LOOP_ARGTYPES), ("crk_run_events", EVENTS_ARGTYPES),
                       ("crk_eval_n", [ctypes.POINTER(Fun), ctypes.c_double, _DP, _DP, _DP, _DP, ctypes.c_longlong]),
                       ("crk_map", [ctypes.POINTER(Fun), ctypes.c_longlong, ctypes.c_longlong, _VP, _VP, _DP,
                                    ctypes.c_longlong])):
        fn = getattr(lib, name)
        fn.restype, fn.argtypes = ctypes.c_int, args
    lib.crk_run_batch.restype = ctypes.c_longlong
    lib.crk_run_batch.argtypes = [ctypes.POINTER(Fun), ctypes.c_int, ctypes.c_longlong, _DP, ctypes.c_longlong,
                                  ctypes.c_longlong, _DP, _DP, _DP, ctypes.c_longlong, ctypes.c_double,
                                  ctypes.c_double, ctypes.c_double, ctypes.c_longlong, _DP, _DP, _I64P,
                                  _I64P, _I64P]
    return lib


def map_rows(rt, fun, nnz_in, nout, dense, where, npts: int, rows):
    """Values (npts, entries of output 0, structural zeros included) of the Fun ``fun`` (one
    output of ``nout`` nonzeros at the places ``where`` of ``dense`` entries; None: dense) by
    the runtime's ``crk_map``; ``rows``: per input an array of npts rows (its entries, C order)
    or one row shared by every point."""
    import numpy as np

    arrs, strides = [], []
    for a, nnz in zip(rows, nnz_in):
        a = np.ascontiguousarray(a, float)
        shared = a.size == nnz and not (npts == 1 and a.ndim > 1)
        arrs.append(a)
        strides.append(0 if shared or nnz == 0 else nnz)
    out = np.zeros((npts, max(nout, 1)))
    ptrs = (_VP * len(arrs))(*[a.ctypes.data if a.size else None for a in arrs])
    st = np.array(strides, dtype=np.int64)
    status = rt.crk_map(ctypes.byref(fun), npts, len(arrs), ptrs, st.ctypes.data, _ptr(out), out.shape[1])
    if status:
        raise RuntimeError(f"evaluation failed (status {status})")
    if where is None:
        return out[:, :nout]
    full = np.zeros((npts, dense))
    full[:, where] = out[:, :nout]
    return full


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
    import numpy as np

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


class Call:
    """One run of the loop on plain buffers (``call_loop``): ``X`` (array.array of npts x nx
    doubles, row-major, NaN where not reached), ``reached`` (grid points with a state),
    ``status``, ``raw`` (the loop's counts), ``interrupted``, ``fail_time`` and ``fail_state``
    (list) after a failure."""

    def __init__(self, X, reached, status, raw, interrupted, fail_time, fail_state):
        self.X, self.reached, self.status, self.raw = X, reached, status, raw
        self.interrupted, self.fail_time, self.fail_state = interrupted, fail_time, fail_state


def _doubles(v) -> array:
    """``v`` as array.array('d'): itself, or a copy of a contiguous float64 numpy array's bytes
    (iterating the array would make a numpy scalar per entry)."""
    if type(v) is array and v.typecode == "d":
        return v
    try:
        mv = memoryview(v)
    except TypeError:                   # a list or a tuple
        return array("d", v)
    if mv.format != "d" or not mv.c_contiguous:
        return array("d", v.tolist() if hasattr(v, "tolist") else list(v))
    out = array("d")
    out.frombytes(mv.cast("B"))
    return out


class _Prepared:
    """One crk_run call's buffers and arguments (kept alive with it): the output rows ``X``, the
    small arrays in one buffer ``W`` (stats, ctl, xfail, the carried y and f, x0, p, u), the
    Resume, the input tables' Drive."""

    __slots__ = ("grid", "npts", "nx", "X", "W", "ctl", "rs", "args", "keep")


def _prepare(loop, method, grid, x0, p, u, rtol, atol, max_steps, hmin, drive=None) -> _Prepared:
    c = _Prepared()
    c.grid, c.npts = grid, len(grid)
    x0, pc, uc = _doubles(x0), _doubles(p), _doubles(() if u is None else u)
    c.nx = nx = len(x0)
    c.X = array("d", [float("nan")]) * (c.npts * nx)
    # one buffer for the small arrays, each passed by its address: stats (4), the progress and
    # cancel words ctl (2, int64), xfail (nx), the carried y and f (nx each), x0, p, u
    m, npar, nu = max(nx, 1), len(pc), len(uc)
    c.W = W = array("d", bytes(8 * (6 + 3 * m + m + npar + nu)))
    o = 6 + 3 * m
    W[o:o + nx] = x0
    W[o + m:o + m + npar] = pc
    W[o + m + npar:o + m + npar + nu] = uc
    a = W.buffer_info()[0]
    c.ctl = ctypes.c_longlong.from_address(a + 32)
    c.rs = rs = Resume(SLICE, 0, 0.0, 0.0, 0, 0, 0, 0, 0, a + 8 * (6 + m), a + 8 * (6 + 2 * m))
    drv, c.keep = loop_drive(drive, float(grid[0]), float(grid[-1]), uc) if tables_in_loop(drive) else (None, ())
    c.args = (loop.fun("ode"), CRK_METHODS[method][0], nx, address(grid), c.npts, a + 8 * o, a + 8 * (o + m + npar),
              a + 8 * (o + m), float(rtol), float(atol), float(hmin), int(max_steps), c.X.buffer_info()[0], a,
              a + 32, a + 48, ctypes.byref(rs), None if drv is None else ctypes.byref(drv))
    return c


def _slices(loop, c: _Prepared, progress, payback, status):
    """(status, interrupted, the loop that ran last): ``c`` called until it does not yield
    (``status``: of a call made already; None: none yet); between calls progress, Ctrl-C and the
    pay-back switch."""
    grid, ctl, rs, args = c.grid, c.ctl, c.rs, c.args
    interrupted = False
    try:
        while True:
            if status is None:
                status = loop.run(*args)
            if status != YIELD:
                break
            status = None
            progress.update(float(grid[max(ctl.value, 1) - 1]))
            if payback is not None and loop.engine == "interpreted":
                better = payback.check(int(rs.nfev))
                if better is not None:          # the rest of the run in compiled code
                    loop, args = better, (better.fun("ode"),) + args[1:]
    except KeyboardInterrupt:            # Ctrl-C between slices: the rows written so far are kept
        status, interrupted = CANCELLED, True
    progress.update(float(grid[max(ctl.value, 1) - 1]))
    return status, interrupted, loop


def _result(c: _Prepared, engine: str, status: int, interrupted: bool, payback=None) -> Call:
    """The Call of ``c`` ended with ``status``."""
    W, reached = c.W, c.ctl.value
    raw = {"n_steps": int(W[0]), "n_rhs": int(W[1]), "n_reject": int(W[2]), "status": int(status),
           "engine": engine}
    if payback is not None:
        payback.record(int(W[1]))
        if payback.switched_at is not None and payback.switched_at >= 0:
            raw["compiled_after"] = payback.switched_at       # evaluations made interpreted first
    failed = not interrupted and (status != 0 or reached < c.npts)
    return Call(c.X, reached, status, raw, interrupted, float(W[3]) if failed else None,
                list(W[6:6 + c.nx]) if failed else None)


def call_loop(loop, method, grid, x0, p, u, rtol, atol, max_steps, hmin, progress, drive=None,
              payback=None) -> Call:
    """The run as C calls of SLICE seconds each in the calling thread (the state carried
    from call to call: the steps are those of one call), progress shown and Ctrl-C let through
    between calls; a short run is one call (no thread is started: 0.12 ms of CPU a run).
    ``grid``: a contiguous float64 numpy array or array.array('d'); ``x0``, ``p``, ``u`` (None:
    no inputs): sequences of floats.  ``payback`` (payback.Payback, an interpreted run): between
    calls, the compiled loop once the interpreted evaluations have paid for its compile (the same
    bits: only the cost changes)."""
    c = _prepare(loop, method, grid, x0, p, u, rtol, atol, max_steps, hmin, drive)
    status, interrupted, loop = _slices(loop, c, progress, payback, None)
    return _result(c, loop.engine, status, interrupted, payback)


COMPANION_INTERRUPTED = "the companion run was interrupted (Ctrl-C)"     # pair_loop's second answer then


def pair_loop(loop, first: tuple, loop2, second: tuple, progress):
    """(the run's Call, its companion's Call or None; its raw counts with its own cpu_time and
    wall_time, seconds of the call that were the companion's): call_loop of ``first`` = (method,
    grid, x0, p, u, rtol, atol, max_steps, hmin) on ``loop`` and of ``second`` on ``loop2`` (the
    same model in the same runtime, no input tables) in one C call when the first reaches its end
    within its first slice (crk_run_pair; the same steps, so the same bits as two calls).  The
    companion is None when it did not run to its end in that call (a long or failed run: the
    caller runs it as usual), COMPANION_INTERRUPTED when a Ctrl-C came after the run had reached
    its end (the caller says so as an interrupted estimate, as when the companion runs alone)."""
    pair = getattr(loop.rt, "_pair", None)
    if pair is None:
        pair = loop.rt._pair = _declared_pair(loop.rt)
    if pair is False or loop2.rt is not loop.rt:
        return call_loop(loop, *first, progress), None
    c1, c2 = _prepare(loop, *first), _prepare(loop2, *second)
    which = ctypes.c_int(-1)
    took = (ctypes.c_double * 2)()
    a2 = c2.args
    return _pair_call(loop, loop2, pair, c1, c2, (*c1.args, a2[0], a2[1], *a2[3:17], ctypes.byref(which), took),
                      which, took, progress)


class KeptPair:
    """``pair_loop``'s call of one run and its companion prepared once (the buffers, the Resumes and
    every argument as ctypes takes it) for a setup's warm runs: each ``call`` writes the starts
    and parameters into the kept buffers, resets the progress and cancel words and the Resumes,
    gives each run fresh output rows (NaN where not reached: a Call's X is never written again)
    and makes the same C call as ``pair_loop`` (the same steps, the same bits).  ``first`` and
    ``second`` as pair_loop's; built only where pair_loop would make the pair call (``make``)."""

    __slots__ = ("loop", "loop2", "c1", "c2", "tail", "which", "took", "shapes", "lock")

    @classmethod
    def make(cls, loop, first: tuple, loop2, second: tuple):
        """A KeptPair, or None when pair_loop would not call both at once (another runtime, a
        runtime without crk_run_pair, input tables)."""
        pair = getattr(loop.rt, "_pair", None)
        if pair is None:
            pair = loop.rt._pair = _declared_pair(loop.rt)
        if pair is False or loop2.rt is not loop.rt or len(first) > 9 or len(second) > 9:
            return None
        k = cls()
        k.loop, k.loop2 = loop, loop2
        k.c1, k.c2 = _prepare(loop, *first), _prepare(loop2, *second)
        k.which, k.took = ctypes.c_int(-1), (ctypes.c_double * 2)()
        a2 = k.c2.args
        k.tail = (a2[0], a2[1], *a2[3:12])          # the companion's arguments before its X
        k.shapes = (k.c1.nx, len(first[3]), k.c2.nx, len(second[3]))
        k.lock = threading.Lock()       # one call at a time on the kept buffers
        return k

    def fits(self, x0, p, x02, p2) -> bool:
        return self.shapes == (len(x0), len(p), len(x02), len(p2))

    @staticmethod
    def _renew(c: _Prepared, x0, p):
        W, nx = c.W, c.nx
        m = max(nx, 1)
        o = 6 + 3 * m
        W[o:o + nx] = _doubles(x0)
        W[o + m:o + m + len(p)] = _doubles(p)
        W[4] = W[5] = 0.0                       # ctl: progress and cancel words (int64 zeros)
        c.rs.started = 0
        c.X = array("d", [float("nan")]) * (c.npts * nx)
        x = c.X.buffer_info()[0]
        c.args = c.args[:12] + (x,) + c.args[13:]
        return x

    def call(self, x0, p, x02, p2, progress):
        """(the run's Call, the companion's Call or None or COMPANION_INTERRUPTED), as pair_loop's;
        None when another thread is calling it (the caller prepares a call of its own)."""
        if not self.lock.acquire(False):
            return None
        try:
            c1, c2 = self.c1, self.c2
            self._renew(c1, x0, p)
            x2 = self._renew(c2, x02, p2)
            which, took = self.which, self.took
            which.value = -1
            a2 = c2.args
            return _pair_call(self.loop, self.loop2, self.loop.rt._pair, c1, c2,
                              (*c1.args, *self.tail, x2, *a2[13:17], ctypes.byref(which), took), which, took,
                              progress)
        finally:
            self.lock.release()


def _pair_call(loop, loop2, pair, c1, c2, args, which, took, progress):
    """pair_loop's C call of the prepared ``c1`` and ``c2`` (``args``: every argument) and what
    follows it: (the run's Call, the companion's Call or None or COMPANION_INTERRUPTED)."""
    try:
        status = pair(*args)
    except KeyboardInterrupt:
        if which.value != -1:            # during the companion: the run itself reached its end
            progress.update(float(c1.grid[-1]))
            return _result(c1, loop.engine, 0, False), COMPANION_INTERRUPTED
        status, interrupted = CANCELLED, True      # during the run: the rows written are kept
        progress.update(float(c1.grid[max(c1.ctl.value, 1) - 1]))
    else:
        status, interrupted, _ = _slices(loop, c1, progress, None, status)
    run = _result(c1, loop.engine, status, interrupted)
    other = None
    if not interrupted and which.value == 0 and c2.ctl.value == c2.npts:
        other = _result(c2, loop2.engine, 0, False)
        other.raw["cpu_time"], other.raw["wall_time"] = took[0], took[1]
    return run, other


def _declared_pair(rt):
    """The runtime's crk_run_pair (argument types declared), or False (a runtime built before it)."""
    try:
        fn = rt.crk_run_pair
    except AttributeError:
        return False
    fn.restype, fn.argtypes = ctypes.c_int, LOOP_ARGTYPES + PAIR_ARGTYPES
    return fn


class Loop:
    """The model's Functions as the runtime calls them (``funs``: name -> Fun), the runtime's
    entry points, and what keeps both alive (programs, the model's library)."""

    def __init__(self, rt, funs: dict, engine: str, keep):
        self.rt, self.funs, self.engine, self._keep = rt, funs, engine, keep
        self.spec = None        # how crk_calls.open_loop loads it again without CasADi (build_loop)
        self.run = rt.crk_run
        self.run_events = rt.crk_run_events

    def fun(self, name):
        f = self.funs.get(name)
        return None if f is None else ctypes.byref(f)


def program_fun(rt, prog) -> Fun:
    """The Fun of vm.c's program ``prog`` (sxcode.Program; the caller keeps it alive)."""
    return Fun(ctypes.cast(rt.vm_eval, _VP).value, ctypes.addressof(prog.prog), ctypes.cast(rt.vm_init, _VP).value,
               prog.n_in, prog.n_out, 0, prog.nreg)


_OPEN: dict = {}


def open_runtime(path: str):
    """The runtime library at ``path`` (ctypes, its entry points declared), loaded once a process."""
    lib = _OPEN.get(path)
    if lib is None:
        lib = _OPEN[path] = declare(ctypes.CDLL(path))
    return lib


def _open_model(path: str, names) -> tuple:
    """(the model's library at ``path``, {name: (address, work sizes)}), loaded once a process
    (a run and its error estimate's companion call the same library)."""
    hit = _OPEN.get((path, tuple(names)))
    if hit is None:
        lib = ctypes.CDLL(path)
        funs = {}
        for name in names:
            sz = [ctypes.c_longlong(0) for _ in range(4)]
            getattr(lib, name + "_work")(*map(ctypes.byref, sz))
            funs[name] = (ctypes.cast(getattr(lib, name), _VP).value, tuple(v.value for v in sz))
        hit = _OPEN[(path, tuple(names))] = (lib, funs)
    return hit


def open_loop(spec: dict) -> Loop:
    """A Loop again from its ``spec`` (crk.build_loop's plain data: the libraries' paths, or the
    programs of the interpreter), without CasADi.  OSError/AttributeError: a library is gone."""
    rt = open_runtime(spec["runtime"])
    funs, keep = {}, []
    if spec["engine"] == "interpreted":
        for name, arrays in spec["programs"].items():
            prog = Program(arrays=arrays)
            keep.append(prog)
            funs[name] = program_fun(rt, prog)
    else:
        lib, found = _open_model(spec["library"], spec["functions"])
        keep.append(lib)
        ev = ctypes.cast(rt.crk_casadi_eval, _VP).value
        for name, (address, sizes) in found.items():
            funs[name] = Fun(ev, address, None, *sizes)
    loop = Loop(rt, funs, spec["engine"], keep)
    loop.spec = spec
    return loop


def counts(raw: dict) -> dict:
    """A loop run's statistics (call_loop's raw) under the names of every run's."""
    return {"steps": raw.get("n_steps"), "rhs_evals": raw.get("n_rhs"), "jac_evals": 0,
            "rejected_steps": raw.get("n_reject")}
