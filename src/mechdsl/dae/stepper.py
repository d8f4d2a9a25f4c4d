"""Common machinery of the formulations: segment integrators on a scaled time axis.

The driver advances a formulation chunk by chunk: ``advance(times)`` integrates from the
current state through the increasing, equally spaced ``times`` (several output times in
one integrator call, or a single time), and returns the states it accepts there.  Between
chunks the driver checks drift and conditioning; the formulation projects or
re-partitions.  Each CasADi integrator is built on the unit interval s in [0, 1] with
t = t_k + s h (t_k and h are parameters) and an output grid of K equal steps, so one
integrator per K serves every chunk (cached in :class:`GridIntegrators`).
"""
from __future__ import annotations

from ..integrators import make_integrator

import abc
import contextlib
from dataclasses import dataclass, field

import numpy as np

from .options import DaeOptions
from .system import ConstrainedSystem


class StepError(Exception):
    """A segment could not be integrated (the integrator or a Newton solve failed)."""


_STAT_KEYS = ("nsteps", "nfevals", "netfails", "nncfails", "nlinsetups")
_ERK_KEYS = {"n_steps": "nsteps", "n_rhs": "nfevals", "n_reject": "netfails"}


@dataclass
class Stepper(abc.ABC):
    system: ConstrainedSystem
    opts: DaeOptions
    t: float = 0.0
    q: np.ndarray | None = None
    qd: np.ndarray | None = None
    stats: dict = field(default_factory=dict)
    notes: list = field(default_factory=list)
    name: str = ""

    def reset(self, t: float, q: np.ndarray, qd: np.ndarray) -> None:
        self.t, self.q, self.qd = float(t), np.array(q, float), np.array(qd, float)

    @abc.abstractmethod
    def advance(self, times: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Integrate through ``times``; return (t, q, qd) of the accepted prefix (at least one)."""

    def after_segment(self) -> None:
        """Hook after a successful segment (projection, re-partitioning)."""

    # -- helpers ---------------------------------------------------------------------------
    def _count(self, integrator) -> None:
        st = integrator.stats()
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


def ode_plugin(opts: DaeOptions) -> str:
    """The CasADi plugin for the ODE formulations: CVODES (Adams/BDF) or the explicit RK 5(4)."""
    return "erk" if opts.method == "erk" else "cvodes"


def integrator_options(opts: DaeOptions, plugin: str) -> dict:
    if plugin == "erk":
        return {"abstol": opts.atol, "reltol": opts.rtol, "max_num_steps": opts.steps}
    o = {"abstol": opts.atol, "reltol": opts.rtol, "max_num_steps": opts.steps,
         "disable_internal_warnings": True}
    if plugin == "cvodes":
        o["linear_multistep_method"] = "adams" if opts.method == "adams" else "bdf"
        o["nonlinear_solver_iteration"] = "newton"
    return o


def call_integrator(F, **args):
    """Call a CasADi integrator; any failure becomes a StepError with the solver's message.

    CasADi and SUNDIALS print to Python's stdout/stderr while they retry (e.g. a Newton
    solve inside a right-hand side that did not converge); that is captured here and only
    its last line is kept, as the detail of a failure."""
    from ..integrators import captured_messages

    try:
        with captured_messages() as buf:    # this thread's output only (no global swap)
            return F(**args)
    except RuntimeError as e:
        msg = [ln.strip() for ln in str(e).strip().splitlines() if ln.strip()]
        solver = [ln for ln in msg if "returned" in ln or "flag" in ln.lower()]
        printed = [ln.strip() for ln in buf.getvalue().splitlines() if ln.strip().startswith("At t")]
        text = (solver[-1] if solver else (msg[-1] if msg else "integrator failed"))
        if printed:
            text += f"; {printed[-1]}"
        raise StepError(text[:400]) from None


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
        mechdsl.codegen for the tree models); the virtual machine when that is not possible."""
        import casadi as ca

        from ..codegen import compile_functions
        from ..integrators import dae_function

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

    def get(self, K: int):
        if K not in self._cache:
            import casadi as ca

            with build_timer(self.stats):
                grid = [float(x) for x in np.linspace(0.0, 1.0, K + 1)[1:]]
                self._cache[K] = make_integrator(f"{self.name}_{K}", self.plugin, self._problem, 0.0, grid,
                                                self.opts)
        return self._cache[K]


@contextlib.contextmanager
def build_timer(stats: dict):
    """Accumulate the CPU time spent building integrators into stats['build_cpu_time']."""
    import time

    c0 = time.process_time()
    try:
        yield
    finally:
        stats["build_cpu_time"] = stats.get("build_cpu_time", 0.0) + time.process_time() - c0


def chunk_span(t0: float, times: np.ndarray) -> tuple[float, int]:
    """(h, K) of a chunk from t0 through equally spaced times (h = times[-1] - t0)."""
    times = np.atleast_1d(np.asarray(times, float))
    return float(times[-1] - t0), len(times)
