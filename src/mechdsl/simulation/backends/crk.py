"""The compiled stepping loop: explicit Runge-Kutta in C, one C call per run.

Methods ``dopri5`` (Dormand-Prince 5(4)) and ``dop853`` (Dormand-Prince 8(5,3)), each with
the step-size control, initial step, error norm and dense output of scipy's RK45 and DOP853
(``crk.c`` beside this file, a small hand-written driver).  The driver and the CasADi C of
the model's right-hand side ``ode`` are compiled into one shared library with the cached
compile machinery of ``mechdsl.eom.codegen`` (cache key: the code, flags, compiler and CasADi
versions), loaded with ctypes and called once per run in a worker thread (ctypes releases
the GIL; the main thread shows progress from the rows written and can cancel).  No
Jacobian is generated.

Without a C compiler, or when the model's code cannot be generated or compiled, the same
algorithm runs as scipy's RK45/DOP853 stepped in Python on the virtual machine (the same
steps up to round-off), and the run's warnings say so.

The outcome is a ``mechdsl.integrators.Run`` like every other integrator plug-in's (plugins.py).
"""
from __future__ import annotations

import ctypes
import math
import threading
from pathlib import Path

import numpy as np

from ... import integrators as I
from ...eom.codegen import compile_functions, find_compiler
from ..choose import time_scale


# method -> (id in crk.c, scipy class of the same algorithm)
CRK_METHODS = {"dopri5": (0, "RK45"), "dop853": (1, "DOP853")}
SOURCE = Path(__file__).with_name("crk.c")
STATUS = {1: "more than {max_steps} steps in one output interval (max_num_steps)",
          2: "error control needs a step below the minimum {hmin:.3g} (min_step_size)",
          3: "Required step size is less than spacing between numbers.",
          4: "non-finite state",
          5: "cancelled",
          6: "out of memory in the compiled stepping loop",
          7: "the right-hand side returned an error (non-finite or failed evaluation, NaN)",
          8: "unknown method"}

_LIBS: dict = {}
_LOCK = threading.Lock()
_I64P = ctypes.POINTER(ctypes.c_longlong)
_DP = ctypes.POINTER(ctypes.c_double)


def dense_ode(ode):
    """``ode`` with a dense output column (the C loop reads xdot as a dense vector)."""
    if ode.sparsity_out(0).is_dense():
        return ode
    import casadi as ca

    args = [ca.MX.sym(ode.name_in(i), ode.sparsity_in(i)) for i in range(4)]
    return ca.Function("ode", args, [ca.densify(ode(*args))], [ode.name_in(i) for i in range(4)], ["xdot"])


RUN_ARGTYPES = [ctypes.c_int, ctypes.c_longlong, _DP, ctypes.c_longlong, _DP, _DP, _DP, ctypes.c_double,
                ctypes.c_double, ctypes.c_double, ctypes.c_longlong, _DP, _DP, _I64P, _DP]


def library(ode, tag: str = "model"):
    """(ctypes function crk_run or None, note) for the model Function ``ode``; cached per Function."""

    def load(lib):
        fn = lib.crk_run
        fn.restype = ctypes.c_int
        fn.argtypes = RUN_ARGTYPES
        fn._keep = lib
        return fn

    return cached_library(id(ode), ode, (), tag, load, "the compiled stepping loop")


def cached_library(key, ode, extra, tag, load, what):
    """(load(ctypes library) or None, note): the C of ``ode`` (dense output), of the Functions
    ``extra`` and of crk.c in one cached shared library; cached in memory under ``key``."""
    with _LOCK:
        hit = _LIBS.get(key)
    if hit is not None and hit[0] is ode:
        return hit[1], hit[2]
    try:
        loaded, note, path = compile_functions([dense_ode(ode), *extra], tag=tag, jacobian=False,
                                               extra_units=(SOURCE.read_text(),))
    except Exception as e:  # noqa: BLE001 - e.g. a Function CasADi cannot generate C for
        loaded, note, path = None, f"cannot generate C for the model ({str(e).strip().splitlines()[-1][:200]})", None
    obj = None
    if loaded is not None:
        try:
            obj = load(ctypes.CDLL(path))
        except (OSError, AttributeError) as e:
            obj, note = None, f"cannot load {what} {path}: {e}"
    with _LOCK:
        if len(_LIBS) >= 16:
            _LIBS.pop(next(iter(_LIBS)))
        _LIBS[key] = (ode, obj, note)
    return obj, note


def _ptr(a):
    return a.ctypes.data_as(_DP)


def call_in_thread(call, ctl, tick):
    """``call()`` (a ctypes call of the loop, which releases the GIL) in a worker thread; the main
    thread calls ``tick(rows written)`` every 0.1 s from the progress word ctl[0] and, on Ctrl-C,
    sets ctl[1] (the loop stops at its next step) and lets the interrupt through.  The status, or
    7 when the call raised.  ``call`` keeps the buffers it passes alive while the worker runs."""
    box = {}

    def work():
        box["status"] = call()

    th = threading.Thread(target=work, name="mechdsl-crk", daemon=True)
    th.start()
    try:
        while th.is_alive():
            th.join(0.1)
            if ctl[0]:
                tick(int(ctl[0]))
    except BaseException:
        ctl[1] = 1          # ask the loop to stop at its next step, then let the interrupt through
        raise
    return box.get("status", 7)


def run_compiled(fn, method, grid, x0, p, u, rtol, atol, max_steps, hmin, progress) -> I.Run:
    """One C call over the whole output grid, in a worker thread (progress and Ctrl-C stay live)."""
    grid = np.ascontiguousarray(grid, float)
    nx = x0.size
    X = np.full((len(grid), nx), np.nan)
    x0c = np.ascontiguousarray(x0, float)
    pc = np.ascontiguousarray(np.ravel(p), float)
    uc = np.ascontiguousarray(np.zeros(0) if u is None else np.ravel(u), float)
    stats = np.zeros(4)
    ctl = np.zeros(2, dtype=np.int64)
    xfail = np.zeros(nx)

    def call():
        return fn(CRK_METHODS[method][0], nx, _ptr(grid), len(grid), _ptr(x0c), _ptr(uc), _ptr(pc),
                  float(rtol), float(atol), float(hmin), int(max_steps), _ptr(X), _ptr(stats),
                  ctl.ctypes.data_as(_I64P), _ptr(xfail))

    status = call_in_thread(call, ctl, lambda rows: progress.update(float(grid[rows - 1])))
    reached = int(ctl[0])
    progress.update(float(grid[max(reached, 1) - 1]))
    raw = {"n_steps": int(stats[0]), "n_rhs": int(stats[1]), "n_reject": int(stats[2]), "status": int(status)}
    run = I.Run(X=X, reached=reached, stats=raw)
    if status != 0 or reached < len(grid):
        t_end = float(stats[3])
        run.error = STATUS.get(status, f"status {status}").format(max_steps=max_steps, hmin=hmin)
        run.fail_time, run.fail_state = t_end, xfail.copy()
    return run


# --------------------------------------------------------------------------- when compiling pays

# Cost model (measured on this project's 2-core machine, N-link chains N = 2..30, rtol 1e-8,
# docs/internals/numerics.md): erk in the virtual machine costs about 3 us of step machinery
# plus 2 ns per operation of the right-hand side per evaluation; the compiled dop853 loop
# 0.3 us + 0.6 ns per operation and 0.65x erk's evaluations; gcc 0.35 s + 0.17 ms per
# operation.  erk's evaluations ~ 2.6 sqrt(n) * span * omega * rtol^(-1/5), omega the time
# scale at the start (simulate.time_scale); the sqrt(n) is the chains' whip (faster motion
# than at the start), fitted within 2x on N = 2..30 and the shipped double pendulum.
VM_CALL, VM_OP = 3e-6, 2e-9
C_CALL, C_OP, C_EVALS = 0.3e-6, 0.6e-9, 0.65
GCC_FIXED, GCC_OP = 0.35, 1.7e-4
PAYBACK_RUNS = 20     # the library is cached on disk by the model's structure: later runs reuse it


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


def auto_choice(eom, funcs, x0, pv, t0, t1, rtol, u, rho=None) -> tuple[str | None, str, dict]:
    """(method or None, reason, numbers): compile the dop853 loop (dopri5 at rtol >= 1e-5) when
    the time it saves per run, estimated from the model's size and the run's length, repays the
    estimated compile time within PAYBACK_RUNS runs."""
    if find_compiler() is None:
        return None, "no C compiler", {}
    ops = rhs_cost(funcs["ode"])
    if ops is None:
        return None, "the right-hand side calls Python (an input given as a callable): no C code for it", {}
    omega, _ = time_scale(funcs, x0, pv, t0, t1, u, rho=rho)
    span = t1 - t0
    evals = 2.6 * math.sqrt(max(eom.n, 1)) * span * omega * rtol ** -0.2
    if not math.isfinite(evals):        # a subnormal span or an overflowing time scale
        return None, f"no estimate of the run's work (span {span:.3g} s, time scale {omega:.3g} rad/s)", {}
    vm = evals * (VM_CALL + VM_OP * ops)
    comp = C_EVALS * evals * (C_CALL + C_OP * ops)
    gcc = GCC_FIXED + GCC_OP * ops
    info = {"rhs_operations": ops, "estimated_rhs_evals": round(evals), "estimated_vm_time": vm,
            "estimated_compiled_time": comp, "estimated_compile_time": gcc}
    numbers = (f"estimated {vm * 1e3:.3g} ms a run in the virtual machine, {comp * 1e3:.3g} ms compiled; "
               f"compiling ~{gcc:.2g} s once, cached on disk")
    if (vm - comp) * PAYBACK_RUNS < gcc:
        return None, numbers + f": does not pay back within {PAYBACK_RUNS} runs", info
    method = loop_method(rtol)
    return method, numbers + f": pays back within {PAYBACK_RUNS} runs", info


def loop_method(rtol: float) -> str:
    """The compiled loop's method when the choice is automatic: dopri5 at rtol >= 1e-5 (its
    lower order pays at loose tolerances), else dop853 (auto_choice; the FMU's co-simulation
    stepper, mechdsl.export)."""
    return "dopri5" if rtol >= 1e-5 else "dop853"


def scipy_name(method: str) -> str:
    """The scipy method (in mechdsl's names) that a compiled loop's method runs as in Python."""
    return "scipy-" + CRK_METHODS[method][1].lower()

