"""Common machinery of the formulations: segment integrators on a scaled time axis.

The driver advances a formulation chunk by chunk: ``advance(times, monitor)`` integrates
from the current state through the increasing ``times`` (several monitoring times in one
integrator call, or a single time, plus the output times in between, flagged False in
``monitor``), and returns the states it accepts there.  Between
chunks the driver checks drift and conditioning; the formulation projects or
re-partitions.  Each CasADi integrator is built on the unit interval s in [0, 1] with
t = t_k + s h (t_k and h are parameters) and an output grid of K equal steps, so one
integrator per K serves every chunk (cached in :class:`GridIntegrators`); chunks with
output times in between get an integrator per pattern of fractions.
"""
from __future__ import annotations

import abc
import contextlib
from dataclasses import dataclass, field

import numpy as np

from ..eom.codegen import compile_functions
from ..integrators import captured_messages, dae_function, make_integrator
from ..interrupts import check_interrupt
from .constrained_system import ConstrainedSystem
from .dae_run import DaeRun


class StepError(Exception):
    """A segment could not be integrated (the integrator or a Newton solve failed)."""


class NonFiniteError(StepError):
    """The integrated state became inf/nan: when (first output time with one) and where."""

    def __init__(self, t: float, name: str):
        self.t, self.name = float(t), name
        super().__init__(f"{name} became non-finite by t = {t:.10g}")


def state_names(system) -> list[str]:
    """Names of the state (q, q') entries: the coordinates, then der(coordinate)."""
    c = list(system.eom.coords)
    return c + [f"der({x})" for x in c]


def locate_nonfinite(system, t: float, q: np.ndarray, qd: np.ndarray, h: float) -> tuple[float, str] | None:
    """Where the equations first give inf/nan after the state (t, q, q'): the accelerations at
    that state, at t and at times t + h 10^-k (k = 12 .. 0) and then along the linear motion.
    Returns (time, name) or None.  Used to explain an integrator failure."""
    names = [f"der(der({x}))" for x in system.eom.coords] + [f"lambda[{x}]" for x in system.names]
    ts = [t] + [t + h * 10.0 ** -k for k in range(12, -1, -1)]
    for moving in (False, True):
        for tk in ts:
            qk = q + (tk - t) * qd if moving else q
            try:
                a, lam = system.accel(qk, qd, tk)
            except Exception:  # noqa: BLE001 -- a failing evaluation is not a finding
                continue
            v = np.concatenate([a, lam])
            if not np.all(np.isfinite(v)):
                return float(tk), names[int(np.argmax(~np.isfinite(v)))]
    return None


_STAT_KEYS = ("nsteps", "nfevals", "netfails", "nncfails", "nlinsetups")
_ERK_KEYS = {"n_steps": "nsteps", "n_rhs": "nfevals", "n_reject": "netfails"}


@dataclass
class Stepper(abc.ABC):
    system: ConstrainedSystem
    opts: DaeRun
    t: float = 0.0
    q: np.ndarray | None = None
    qd: np.ndarray | None = None
    stats: dict = field(default_factory=dict)
    notes: list = field(default_factory=list)
    name: str = ""
    step_budget: int | None = None     # most integrator steps per output interval of the next call (driver)

    def reset(self, t: float, q: np.ndarray, qd: np.ndarray) -> None:
        self.t, self.q, self.qd = float(t), np.array(q, float), np.array(qd, float)

    @abc.abstractmethod
    def advance(self, times: np.ndarray, monitor=None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Integrate through ``times``; return (t, q, qd) of the accepted prefix (at least one).
        ``monitor`` (bool per time) marks the driver's checking times; the others are output
        times, which must not change the integration (no cut, no projection there)."""

    def for_record(self, t: float, q: np.ndarray, qd: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The state recorded at an output time between the monitoring times (as integrated)."""
        return q, qd

    def after_segment(self) -> None:
        """Hook after a successful segment (projection, re-partitioning)."""

    # -- helpers ---------------------------------------------------------------------------
    def _count(self, integrator) -> None:
        self.count_stats(call_stats(integrator))

    def count_stats(self, st: dict) -> None:
        """Add an integrator call's statistics (CVODES/IDAS or erk names) to self.stats."""
        st = dict(st)
        for src, k in _ERK_KEYS.items():          # CasADi's erk names its counts differently
            if src in st and k not in st:
                st[k] = st[src]
        for k in _STAT_KEYS:
            if k in st:
                self.stats[k] = self.stats.get(k, 0) + int(st[k])
        self.stats["segments"] = self.stats.get("segments", 0) + 1


def scaled_dae(dae: dict, extra_p=None) -> dict:
    """Rewrite a DAE in t to one in s in [0, 1]: t = t0 + s h, d/ds = h d/dt.

    The new parameter vector is [p; t0; h; extra_p]."""
    import casadi as ca

    Sym = type(dae["x"])            # SX or MX, as the DAE is built
    s = Sym.sym("s")
    t0 = Sym.sym("t0")
    h = Sym.sym("h")
    t = dae["t"]
    extra = Sym.zeros(0, 1) if extra_p is None else extra_p
    sub = t0 + s * h
    out = {"x": dae["x"], "t": s, "p": ca.vertcat(dae["p"], t0, h, extra),
           "ode": h * ca.substitute(dae["ode"], t, sub)}
    if "z" in dae and dae["z"].numel():
        out["z"] = dae["z"]
        out["alg"] = ca.substitute(dae["alg"], t, sub)
    return out


def ode_plugin(opts: DaeRun) -> str:
    """The CasADi plugin for the ODE formulations: CVODES (Adams/BDF) or the explicit RK 5(4)."""
    return "erk" if opts.method == "erk" else "cvodes"


def integrator_options(opts: DaeRun, plugin: str) -> dict:
    if plugin == "erk":
        return {"abstol": opts.atol, "reltol": opts.rtol, "max_num_steps": opts.steps}
    o = {"abstol": opts.atol, "reltol": opts.rtol, "max_num_steps": opts.steps,
         "disable_internal_warnings": True}
    if plugin == "cvodes":
        o["linear_multistep_method"] = "adams" if opts.method == "adams" else "bdf"
        o["nonlinear_solver_iteration"] = "newton"
    return o


class PartialCall(KeyboardInterrupt):
    """Ctrl-C inside an integrator call: ``out`` holds the outputs with the columns (output
    times) written before it, ``columns`` how many of ``xf``'s are complete."""

    def __init__(self, out: dict, columns: int):
        super().__init__("interrupted")
        self.out, self.columns = out, columns


class SegmentInterrupted(KeyboardInterrupt):
    """Ctrl-C inside a segment: the states the formulation reached at its first output times
    (``times``, ``Q``, ``QD``: rows per time), for the driver to record before it stops."""

    def __init__(self, times, Q, QD):
        super().__init__("interrupted")
        self.times, self.Q, self.QD = times, Q, QD


_LAST_STATS: dict = {}        # id(F) -> (F, statistics of its last call through a buffer)


def call_stats(F) -> dict:
    """The statistics of the last call of the integrator ``F`` through call_integrator."""
    hit = _LAST_STATS.get(id(F))
    return dict(hit[1]) if hit is not None and hit[0] is F else dict(F.stats())


def _buffered(F, args: dict):
    """``F(**args)`` through a FunctionBuffer whose outputs are numpy arrays: the columns an
    integrator writes as it reaches each output time stay there when Ctrl-C stops it (then
    PartialCall).  None when the call does not fit (another thread, sparse outputs)."""
    from ..interrupts import in_main_thread, noted

    if not in_main_thread():
        return None
    ins = []
    for name, value in args.items():
        i = F.index_in(name)
        a = np.asarray(value, float).ravel(order="F")
        if a.size != F.numel_in(i):
            return None
        ins.append((i, np.ascontiguousarray(a)))
    if not all(F.sparsity_out(i).is_dense() for i in range(F.n_out())):
        return None
    outs = {F.name_out(i): np.full(F.size_out(i)[::-1], np.nan) for i in range(F.n_out())}  # column-major
    fb, ev = F.buffer()
    for i, a in ins:
        fb.set_arg(i, memoryview(a))
    for name, a in outs.items():
        fb.set_res(F.index_out(name), memoryview(a))
    out = {name: a.T for name, a in outs.items()}
    try:
        ev()
    except KeyboardInterrupt:
        raise PartialCall(out, _complete_columns(out.get("xf"))) from None
    except RuntimeError:
        _LAST_STATS[id(F)] = (F, _stats(fb))
        if noted():
            raise PartialCall(out, _complete_columns(out.get("xf"))) from None
        raise
    if fb.ret() != 0:           # a failure the buffer reports only by its status: the ordinary
        return None             # call gives it with the solver's message (StepError)
    _LAST_STATS[id(F)] = (F, _stats(fb))
    return out


def _stats(fb) -> dict:
    if len(_LAST_STATS) > 64:        # (integrators of runs gone: kept only while in use)
        _LAST_STATS.clear()
    try:
        return dict(fb.stats())
    except Exception:  # noqa: BLE001 - no statistics after some failures
        return {}


def _complete_columns(xf) -> int:
    if xf is None:
        return 0
    ok = np.all(np.isfinite(xf), axis=0)
    return int(np.argmin(ok)) if not ok.all() else int(ok.size)


def call_integrator(F, **args):
    """Call a CasADi integrator; any failure becomes a StepError with the solver's message.

    CasADi and SUNDIALS print to Python's stdout/stderr while they retry (e.g. a Newton
    solve inside a right-hand side that did not converge); that is captured here and only
    its last line is kept, as the detail of a failure.  In the main thread the call goes
    through a buffer: Ctrl-C then raises PartialCall with the output times reached."""
    try:
        with captured_messages() as buf:    # this thread's output only (no global swap)
            out = _buffered(F, args)
            if out is None:
                out = F(**args)
                _LAST_STATS.pop(id(F), None)
        check_interrupt()
        return out
    except RuntimeError as e:
        check_interrupt()
        if "KeyboardInterrupt" in str(e):
            # CasADi checks for Ctrl-C while it integrates, consumes Python's pending signal and
            # reports it as a RuntimeError: give it back as what it is
            raise KeyboardInterrupt from None
        msg = [ln.strip() for ln in str(e).strip().splitlines() if ln.strip()]
        solver = [ln for ln in msg if "returned" in ln or "flag" in ln.lower()]
        printed = [ln.strip() for ln in buf.getvalue().splitlines() if ln.strip().startswith("At t")]
        text = (solver[-1] if solver else (msg[-1] if msg else "integrator failed"))
        if printed:
            text += f"; {printed[-1]}"
        text = f"{text}; {_work_done(F)}" if _work_done(F) else text
        err = StepError(text[:400])
        try:
            err.stats = call_stats(F)         # the work of the failed call (counted by the driver)
        except Exception:  # noqa: BLE001
            pass
        raise err from None


def _work_done(F) -> str:
    """'N steps accepted, R rejected' of a failed call (the erk plugin's only explanation)."""
    try:
        st = call_stats(F)
    except Exception:  # noqa: BLE001 -- no statistics after this failure
        return ""
    n = st.get("nsteps", st.get("n_steps"))
    r = st.get("netfails", st.get("n_reject"))
    if n is None:
        return ""
    return f"{int(n)} steps accepted" + (f", {int(r)} rejected" if r is not None else "")


class GridIntegrators:
    """CasADi integrators of one DAE on s in [0, 1] with K equal output steps, built on demand."""

    def __init__(self, name: str, plugin: str, dae: dict, opts: dict, stats: dict | None = None,
                 compiled: bool = False):
        self.name, self.plugin, self.dae, self.opts = name, plugin, dae, opts
        self.stats = stats if stats is not None else {}
        self._cache: dict[int, object] = {}
        self.compiled = False              # True once the right-hand side runs as native code
        self.note: str | None = None       # why compiled code is not used, when it was asked for
        self._problem = self.dae
        if compiled:
            self._compile()

    def _compile(self) -> None:
        """The ODE right-hand side as C, compiled and loaded (cached by the code's hash, like
        mechdsl.eom.codegen for the tree models); the virtual machine when that is not possible."""
        import casadi as ca


        d = self.dae
        if "z" in d and d["z"].numel():
            self.note = "compiled code is used for the ODE formulations only; this one runs in the virtual machine"
            return
        with build_timer(self.stats):
            u = ca.SX(0, 1) if isinstance(d["x"], ca.SX) else ca.MX(0, 1)    # codegen's (t, x, u, p)
            f = ca.Function("ode", [d["t"], d["x"], u, d["p"]], [d["ode"]], ["t", "x", "u", "p"], ["xdot"])
            funcs, note, _lib = compile_functions([f], tag=self.name, jacobian=self.plugin != "erk")
        if not funcs or funcs.get("ode") is None:
            self.note = note or "compiled code unavailable"
            return
        self._problem = dae_function(funcs["ode"])
        self.compiled = True

    MAX_PATTERNS = 256     # integrators kept for non-uniform grids (output times between checks)

    def get(self, K, budget: int | None = None):
        """The integrator through K equal steps of [0, 1], or (K a tuple) through those
        fractions, with at most ``budget`` steps per output interval (CasADi's max_num_steps
        counts per output time; rounded up to a power of 2 so that few integrators are built;
        default: the options' max_num_steps)."""
        if budget is not None and "max_num_steps" in self.opts:
            budget = 1 << max(10, int(np.ceil(np.log2(max(int(budget), 1)))))
        key = (K, budget)
        if key not in self._cache:
            if len(self._cache) > self.MAX_PATTERNS:
                for k in [k for k in self._cache if not isinstance(k[0], (int, np.integer))]:
                    del self._cache[k]
            with build_timer(self.stats):
                if isinstance(K, (int, np.integer)):
                    grid = [float(x) for x in np.linspace(0.0, 1.0, K + 1)[1:]]
                else:
                    grid = list(K)
                opts = dict(self.opts)
                if "max_num_steps" in opts:
                    opts["max_num_steps"] = budget if budget is not None else int(opts["max_num_steps"])
                label = K if isinstance(K, (int, np.integer)) else f"g{len(grid)}"
                self._cache[key] = make_integrator(f"{self.name}_{label}_{len(self._cache)}", self.plugin,
                                                   self._problem, 0.0, grid, opts)
        return self._cache[key]


@contextlib.contextmanager
def build_timer(stats: dict):
    """Accumulate the CPU time spent building integrators into stats['build_cpu_time']."""
    import time

    c0 = time.process_time()
    try:
        yield
    finally:
        stats["build_cpu_time"] = stats.get("build_cpu_time", 0.0) + time.process_time() - c0


def chunk_span(t0: float, times: np.ndarray, monitor=None) -> tuple[float, int | tuple[float, ...]]:
    """(h, grid) of a chunk from t0 through increasing times (h = times[-1] - t0): grid is K
    when the times are equally spaced, else their fractions s = (t - t0) / h.

    ``monitor`` marks the chunk's own times (equally spaced; the others are output times in
    between).  Their fractions are exactly those of the equally spaced grid, so that the
    integrator passes through the same monitoring states with or without output times in
    between; the output fractions are rounded to 12 digits so that chunks of the same
    pattern share one integrator."""
    times = np.atleast_1d(np.asarray(times, float))
    h = float(times[-1] - t0)
    K = len(times)
    s = (times - t0) / h
    uniform = np.linspace(0.0, 1.0, K + 1)[1:]
    if np.all(np.abs(s - uniform) <= 1e-12):
        return h, K
    s = np.round(s, 12)
    if monitor is not None:
        mon = np.asarray(monitor, bool)
        Km = int(np.sum(mon))
        um = np.linspace(0.0, 1.0, Km + 1)[1:]
        if np.all(np.abs(s[mon] - um) <= 1e-9):
            s[mon] = um
    s[-1] = 1.0
    return h, tuple(float(x) for x in s)
