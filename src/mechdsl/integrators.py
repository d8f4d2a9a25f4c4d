"""Integrator back ends: CasADi integrator plugins and scipy's solve_ivp steppers.

Both runners integrate x' = ode(t, x, u, p) (u constant during the run: the model's input
values, empty without inputs; time-varying inputs are closed into ``ode`` beforehand) from x0 over a given output grid and return a
``Run``: the states at the grid points reached (rows after a failure are NaN), the raw
statistics, and, on failure, the error text.  They never raise for a numerical failure.

CasADi: one integrator Function over the whole grid, evaluated through ``Function.buffer()``
in a worker thread.  CasADi writes each output column into our numpy array as soon as the
integrator reaches it and releases the GIL while it runs, so the main thread can show
progress by watching the array fill, and a failure keeps every point reached before it.
Numbers do not depend on whether progress is shown.  CasADi's own messages (e.g. CVODES'
"At t = ..., mxstep steps taken before reaching tout") are captured, not printed.

scipy: the OdeSolver classes (RK45, DOP853, Radau, BDF, LSODA) stepped in a Python loop,
the grid filled from each step's dense output; the right-hand side and Jacobian are called
through ``codegen.FastFunction`` (buffer calls).
"""
from __future__ import annotations

import contextlib
import io
import math
import sys
import threading
import time
from dataclasses import field
from typing import Any, Callable

import numpy as np

from .model.records import record

# CasADi plug-ins that take a fixed number of steps (number_of_finite_elements)
FIXED_STEP_PLUGINS = ("rk", "collocation")


@record(frozen=False)
class Run:
    X: np.ndarray                         # (n_t, nx); NaN after a failure
    reached: int                          # number of grid points with a valid state
    stats: dict[str, Any] = field(default_factory=dict)
    error: str | None = None              # back end's error text on failure
    messages: str = ""                    # captured back-end messages
    fail_time: float | None = None        # when the back end says it failed (if it says)
    fail_state: np.ndarray | None = None  # state at fail_time when known (scipy)


# --------------------------------------------------------------------------- progress


class Progress:
    """tqdm bar over simulated time, on stderr; shown only for runs longer than ``delay`` s."""

    def __init__(self, enabled, t0: float, t1: float, label: str = "simulating", delay: float = 0.5):
        self.callback = enabled if callable(enabled) else None
        self.bar = None
        self.t0, self.t1 = t0, t1
        self.done = 0.0
        if enabled is True:
            try:
                from tqdm import tqdm
            except ImportError:  # pragma: no cover - tqdm is a core dependency
                return
            from .output.display import notebook_bar

            self.bar = notebook_bar(total=round(t1 - t0, 12), desc=label, unit="s", leave=False)   # in Jupyter
            if self.bar is None:
                self.bar = tqdm(total=round(t1 - t0, 12), desc=label, unit="s", delay=delay, file=sys.stderr,
                                leave=False, bar_format="{desc}: {percentage:3.0f}%|{bar}| t = {n:.4g}/{total:.4g} "
                                                        "[{elapsed}<{remaining}]")

    def update(self, t: float) -> None:
        d = min(max(t - self.t0, 0.0), self.t1 - self.t0)
        if self.bar is not None and d > self.done:
            self.bar.update(d - self.done)
        if self.callback is not None:
            self.callback(t, self.t1)
        self.done = max(self.done, d)

    def close(self) -> None:
        if self.bar is not None:
            self.bar.close()


# --------------------------------------------------------------------------- messages


class _Router:
    """Stands in for sys.stdout/sys.stderr while a capture is active: writes from a capturing
    thread go to that thread's buffer, every other thread's to the stream it replaced."""

    def __init__(self, base):
        self.base = base

    def write(self, text):
        buf = _ROUTES.get((id(self), threading.get_ident()))
        if buf is None and self.base is None:     # no stream at all (pythonw): nothing to write to
            return len(text)
        return (buf if buf is not None else self.base).write(text)

    def flush(self):
        if self.base is not None:
            self.base.flush()

    def __getattr__(self, name):
        return getattr(self.base, name)


_ROUTES: dict[tuple[int, int], io.StringIO] = {}
_ROUTE_LOCK = threading.Lock()
_ROUTERS: dict[str, list] = {}     # stream name -> [router, users]


@contextlib.contextmanager
def captured_messages():
    """Capture what CasADi and SUNDIALS print (they print through Python's sys.stdout and
    sys.stderr) from the calling thread only, into the StringIO yielded.

    Output of other threads passes through unchanged, concurrent captures in several threads
    do not interfere, and the streams are restored when the last capture ends (unless
    someone else replaced them meanwhile): no process-wide effect outlives a run."""
    buf = io.StringIO()
    me = threading.get_ident()
    with _ROUTE_LOCK:
        routers, previous = [], []
        for name in ("stdout", "stderr"):
            entry = _ROUTERS.get(name)
            if entry is None or getattr(sys, name) is not entry[0]:
                entry = [_Router(getattr(sys, name)), 0]
                _ROUTERS[name] = entry
                setattr(sys, name, entry[0])
            entry[1] += 1
            routers.append(entry)
            previous.append(_ROUTES.get((id(entry[0]), me)))     # a capture inside a capture
            _ROUTES[(id(entry[0]), me)] = buf
    try:
        yield buf
    finally:
        with _ROUTE_LOCK:
            for name, entry, prev in zip(("stdout", "stderr"), routers, previous):
                if prev is None:
                    _ROUTES.pop((id(entry[0]), me), None)
                else:
                    _ROUTES[(id(entry[0]), me)] = prev
                entry[1] -= 1
                if entry[1] == 0:
                    if getattr(sys, name) is entry[0]:
                        setattr(sys, name, entry[0].base)
                    if _ROUTERS.get(name) is entry:
                        del _ROUTERS[name]


# --------------------------------------------------------------------------- casadi


_DAE_CACHE: dict = {}
_CACHE_LOCK = threading.Lock()


def dae_function(ode):
    """Wrap an (t, x, u, p) -> xdot Function in CasADi's DAE scheme (t, x, z, p, u) -> (ode, alg, quad, zero).

    The scheme's parameter is [u; p]: the model's inputs are constant during one integration.

    Cached per ``ode`` Function: CasADi caches derivatives on the Function object, so later
    integrators over the same model reuse the Jacobian instead of rebuilding it (0.3-0.5 s on a
    30-link chain in the virtual machine)."""
    import casadi as ca

    key = id(ode)
    with _CACHE_LOCK:
        hit = _DAE_CACHE.get(key)
    if hit is not None and hit[0] is ode:
        return hit[1]

    t = ca.MX.sym("t")
    x = ca.MX.sym("x", ode.size1_in(1))
    nu = ode.size1_in(2)
    p = ca.MX.sym("p", nu + ode.size1_in(3))
    e = ca.MX(0, 1)
    # dense: a structurally zero component (a free coordinate: q'' = 0) makes CasADi refuse the integrator
    dae = ca.Function("dae", [t, x, e, p, e], [ca.densify(ode(t, x, p[:nu], p[nu:])), e, e, e], ca.dyn_in(),
                      ca.dyn_out())
    with _CACHE_LOCK:                # runs in several threads share the caches
        if len(_DAE_CACHE) > 64:
            _DAE_CACHE.clear()
        _DAE_CACHE[key] = (ode, dae)     # holding ode keeps its id unique while cached
    return dae


def casadi_options(plugin: str, base: dict, rtol: float, atol: float, max_steps: int, fixed_steps: int | None,
                   extra: dict, hmin: float = 0.0) -> dict:
    """The options of the CasADi integrator ``plugin``: ``base`` (the method's own, from the
    registry), the tolerances and budgets, then ``extra`` (the user's integrator_options).
    hmin: smallest step before the run is declared failed (CVODES, erk, rosenbrock; IDAS has no
    such option and relies on max_steps)."""
    opts = dict(base)
    if plugin in ("cvodes", "idas", "erk", "rosenbrock"):
        opts.update(reltol=rtol, abstol=atol, max_num_steps=int(max_steps))
    if plugin in ("cvodes", "erk", "rosenbrock") and hmin > 0:
        opts["min_step_size"] = float(hmin)
    if plugin == "cvodes":
        opts["disable_internal_warnings"] = True
    if plugin in FIXED_STEP_PLUGINS:
        opts["number_of_finite_elements"] = int(fixed_steps)
    opts.update(extra)
    return opts


def run_casadi(plugin: str, ode, grid: np.ndarray, x0: np.ndarray, p: np.ndarray, opts: dict,
               progress: Progress, u=None) -> Run:
    """Integrate ode(t, x, u, p) over ``grid`` with the CasADi integrator ``plugin``; u: the
    constant input values (None: none)."""
    integ = cached_integrator(plugin, ode, grid, opts)
    buf, ev = integ.buffer()
    nx = x0.size
    X = np.full((len(grid), nx), np.nan)
    xin = np.ascontiguousarray(x0, float)
    pin = np.ascontiguousarray(np.r_[np.zeros(0) if u is None else np.ravel(u), np.ravel(p)], float)
    buf.set_arg(0, memoryview(xin))
    buf.set_arg(2, memoryview(pin))
    buf.set_res(0, memoryview(X))
    box: dict[str, Any] = {}

    keep = (buf, X, xin, pin, integ)  # alive while the worker runs, even if the caller is interrupted

    def work():
        with captured_messages() as captured:   # what CasADi prints from this worker thread only
            try:
                assert keep
                ev()
            except Exception as e:  # noqa: BLE001 - reported as a failure, never raised
                box["error"] = str(e)
        box["messages"] = captured.getvalue()

    th = threading.Thread(target=work, name="mechdsl-integrator", daemon=True)
    seen = 0
    th.start()
    while th.is_alive():
        th.join(0.1)
        seen = _count_filled(X, seen)
        if seen:
            progress.update(float(grid[seen - 1]))
    seen = _count_filled(X, 0)
    progress.update(float(grid[seen - 1]) if seen else float(grid[0]))
    try:
        stats = dict(buf.stats())
    except Exception:  # noqa: BLE001 - stats unavailable after some failures
        stats = {}
    error = box.get("error")
    if error is None and seen < len(grid):
        bad = X[seen]
        if np.isnan(bad).any() and not np.isinf(bad).any() and np.isnan(bad).all():
            error = f"integrator stopped early (status {buf.ret()})"
        else:
            error = "non-finite state"
    run = Run(X=X, reached=seen, stats=_flat(stats), error=error, messages=box.get("messages", ""))
    if error is not None:
        run.fail_time = _parse_fail_time(run.messages + "\n" + error)
    return run


_INTEGRATOR_CACHE: dict = {}


def make_integrator(name: str, plugin: str, problem, t0: float, grid, opts: dict):
    """The one place a ``casadi.integrator`` is built (ODE runs, DAE formulations, benchmarks).

    ``problem`` is a CasADi DAE Function or dict; ``grid`` the output times (a float for one)."""
    import casadi as ca

    out = [float(v) for v in np.atleast_1d(grid)]
    return ca.integrator(name, plugin, problem, float(t0), out, opts)


def cached_integrator(plugin, ode, grid, opts):
    """casadi.integrator, cached per (model Function, plug-in, grid, options): building one
    derives its Jacobians (0.35 s for a 30-link chain in the VM), which parameter sweeps and
    repeated runs need not pay again.  Integrator Functions are stateless between calls."""
    tgrid = tuple(float(v) for v in grid)
    key = (id(ode), plugin, tgrid, repr(sorted(opts.items())))
    with _CACHE_LOCK:
        hit = _INTEGRATOR_CACHE.get(key)
    if hit is not None and hit[0] is ode:
        return hit[1]
    integ = make_integrator("sim", plugin, dae_function(ode), tgrid[0], tgrid, opts)
    with _CACHE_LOCK:
        if len(_INTEGRATOR_CACHE) >= 16:
            _INTEGRATOR_CACHE.pop(next(iter(_INTEGRATOR_CACHE)))
        _INTEGRATOR_CACHE[key] = (ode, integ)
    return integ


def _count_filled(X: np.ndarray, start: int) -> int:
    """Number of leading rows that are completely written (finite)."""
    i = start
    n = X.shape[0]
    while i < n and np.isfinite(X[i]).all():
        i += 1
    return i


def _parse_fail_time(text: str) -> float | None:
    import re

    m = re.search(r"[Aa]t t\s*=\s*([-+0-9.eE]+)", text)
    if m:
        try:
            return float(m.group(1))
        except ValueError:
            return None
    return None


def _flat(d: dict) -> dict:
    out = {}
    for k, v in d.items():
        if isinstance(v, (bool, int, float, str)) and not (isinstance(v, float) and math.isnan(v)):
            out[k] = v
    return out


def casadi_counts(plugin: str, raw: dict) -> dict:
    """Uniform statistics from a CasADi integrator's raw stats."""
    if plugin in ("cvodes", "idas"):
        return {"steps": raw.get("nsteps"), "rhs_evals": raw.get("nfevals"),
                "jac_evals": raw.get("n_call_jacF"), "error_test_failures": raw.get("netfails"),
                "nonlinear_iterations": raw.get("nniters"), "order_last": raw.get("qlast")}
    if plugin in ("erk", "rosenbrock"):
        return {"steps": raw.get("n_steps"), "rhs_evals": raw.get("n_rhs"), "jac_evals": raw.get("n_jac"),
                "rejected_steps": raw.get("n_reject")}
    if plugin == "rk":
        s = raw.get("n_call_step")
        return {"steps": s, "rhs_evals": None if s is None else 4 * s, "jac_evals": 0}
    if plugin == "collocation":
        return {"steps": raw.get("n_call_step"), "rhs_evals": None, "jac_evals": None}
    return {}


# --------------------------------------------------------------------------- scipy


def run_scipy(cls_name: str, rhs: Callable, jac: Callable | None, grid: np.ndarray, x0: np.ndarray,
              rtol: float, atol: float, max_steps: int, progress: Progress, extra: dict,
              hmin: float = 0.0) -> Run:
    """Step scipy's OdeSolver ``cls_name`` (RK45, DOP853, Radau, BDF, LSODA) over ``grid``.
    max_steps: per output interval (as for CasADi); hmin: smallest step before failing."""
    import scipy.integrate as si

    cls = getattr(si, cls_name)
    kw = dict(extra)
    if cls in (si.Radau, si.BDF, si.LSODA) and jac is not None:
        kw.setdefault("jac", jac)
    X = np.full((len(grid), x0.size), np.nan)
    X[0] = x0
    k = 1                      # next grid index to fill
    steps = 0
    steps_here = 0             # steps in the current output interval
    last_tick = time.perf_counter()
    error = None
    fail_state = None
    fail_time = None
    try:
        solver = cls(rhs, float(grid[0]), np.array(x0, float), float(grid[-1]), rtol=rtol, atol=atol, **kw)
    except Exception as e:  # noqa: BLE001
        return Run(X=X, reached=1, error=f"{type(e).__name__}: {e}", fail_time=float(grid[0]), fail_state=x0)
    while solver.status == "running" and k < len(grid):
        t_prev = solver.t
        try:
            with np.errstate(all="ignore"):
                msg = solver.step()
        except Exception as e:  # noqa: BLE001
            error, fail_time, fail_state = f"{type(e).__name__}: {e}", t_prev, np.array(solver.y)
            break
        steps += 1
        steps_here += 1
        if solver.status == "failed":
            error, fail_time, fail_state = msg or "step failed", solver.t, np.array(solver.y)
            break
        if not np.isfinite(solver.y).all():
            error, fail_time, fail_state = "non-finite state", solver.t, np.array(solver.y)
            break
        if k < len(grid) and grid[k] <= solver.t:
            dense = solver.dense_output()
            while k < len(grid) and grid[k] <= solver.t:
                X[k] = solver.y if grid[k] == solver.t else dense(grid[k])
                k += 1
            steps_here = 0
        if steps_here >= max_steps:
            error = f"more than {max_steps} steps in one output interval (max_num_steps)"
            fail_time, fail_state = solver.t, np.array(solver.y)
            break
        h = getattr(solver, "step_size", None)
        if hmin > 0 and h is not None and 0 < h < hmin and solver.t < grid[-1]:
            error = f"step size {h:.3g} below the minimum {hmin:.3g} (min_step_size)"
            fail_time, fail_state = solver.t, np.array(solver.y)
            break
        now = time.perf_counter()
        if now - last_tick > 0.1:
            progress.update(solver.t)
            last_tick = now
    progress.update(float(grid[k - 1]))
    stats = {"steps": steps, "rhs_evals": int(solver.nfev), "jac_evals": int(getattr(solver, "njev", 0)),
             "lu_decompositions": int(getattr(solver, "nlu", 0))}
    if error is None and k < len(grid):
        error = f"solver stopped at t = {solver.t} ({solver.status})"
        fail_time = solver.t
    return Run(X=X, reached=k, stats=stats, error=error, fail_time=fail_time, fail_state=fail_state)
