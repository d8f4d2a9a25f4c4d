"""Method choice and step counts from the model at the start of a run.

``choose_method`` (method = auto: stiffness from the Jacobian's eigenvalues), the fixed step
count of the fixed-step plug-ins, the model's time scale, and the smallest step a run may take.
Used by the ODE back end, the prepared problem, sweeps, ``mech bench`` and the compiled
loop's cost estimate (backends/crk.py).
"""
from __future__ import annotations

import math
import threading
from typing import Any

import numpy as np

from ..diagnostics import UsageError
from ..eom.codegen import FastFunction
from .registry import spec


NO_U = np.zeros(0)                   # the input vector u of a model without inputs


_CHOICES: dict = {}
_CHOICES_MAX = 64


def choose_method(eom, funcs, x0, pv, t0, t1, rtol, u=NO_U, rows=None) -> tuple[str, str, dict]:
    """method=auto: stiffness from the Jacobian's eigenvalues at the start.

    Rules (docs/internals/numerics.md): stiff (a decay rate much faster than the slowest
    time scale and than the horizon) -> cvodes-bdf; otherwise erk, which the ODE back end
    replaces by the stepping loop where it can (backends/crk.auto_choice).  The answer is kept
    for the same right-hand side, start, parameters and span (a repeated run decides nothing
    again); it does not depend on rtol.  ``rows``: evaluates ``funcs["ode"]`` at many points
    with the same bits (see ``numeric_jacobian``), or None.
    """
    u = default_inputs(eom, u)
    if getattr(funcs, "tables_only", False):      # tables: the model's own ode at the inputs' values at t0
        funcs, u = funcs.base, funcs.drive.vector_at(t0)
    ode = funcs["ode"]
    key = (id(ode), float(t0), float(t1), np.asarray(x0, float).tobytes(), np.asarray(pv, float).tobytes(),
           np.asarray(u, float).tobytes())
    hit = _CHOICES.get(key)
    if hit is not None and hit[0] is ode:
        return hit[1][0], hit[1][1], dict(hit[1][2])
    out = _choose(ode, x0, pv, t0, t1, u, rows)
    if len(_CHOICES) >= _CHOICES_MAX:
        _CHOICES.pop(next(iter(_CHOICES)))
    _CHOICES[key] = (ode, out)       # the Function kept: its id stays unique
    return out[0], out[1], dict(out[2])


def _choose(ode, x0, pv, t0, t1, u, rows=None) -> tuple[str, str, dict]:
    span = t1 - t0
    info: dict[str, Any] = {}
    try:
        J = numeric_jacobian(ode, t0, x0, u, pv, rows)
        lam = jacobian_eigenvalues(J) if np.isfinite(J).all() else None
    except Exception:  # noqa: BLE001
        lam = None
    if lam is None:
        return "cvodes-bdf", "the Jacobian at the start is not finite; BDF is the most robust choice", info
    mag = np.abs(lam)
    rho = float(mag.max()) if mag.size else 0.0
    decay = float(max(0.0, (-lam.real).max())) if lam.size else 0.0
    nonzero = mag[mag > 1e-9 * max(rho, 1.0)]
    slow = max(1.0 / span, float(nonzero.min()) if nonzero.size else 0.0)
    ratio = decay / slow
    info.update(spectral_radius=rho, fastest_decay_rate=decay, slowest_rate=slow, stiffness_ratio=ratio,
                horizon=span)
    if ratio > 1e3 and decay * span > 1e2:
        return ("cvodes-bdf",
                f"stiff: the fastest mode decays at {decay:.3g}/s, {ratio:.3g} times the slowest rate "
                f"{slow:.3g}/s (Jacobian eigenvalues at t = {t0:g}); BDF takes steps the explicit methods cannot", info)
    return ("erk", f"not stiff (stiffness ratio {ratio:.3g} < 1e3 from the Jacobian at t = {t0:g}); the adaptive "
            f"explicit Runge-Kutta 5(4) needs no Jacobian and was fastest for a given accuracy in "
            f"benchmarks/integrators.py", info)


def numeric_jacobian(ode, t0, x0, u, pv, rows=None) -> np.ndarray:
    """d xdot / dx at (t0, x0) by central differences of ``ode`` (one mapped call of 4n
    evaluations, steps cbrt(eps) max(1, |x_j|)), not from a symbolic Jacobian: the dense
    Jacobian of the 200-link chain took 12-16 s to build and gcc 30 s, for a stiffness test
    that needs its eigenvalues to a few digits.  Where xdot = (qd, ...) (every model's ode) the
    rows of qd are set exactly ([0, I]), so ``jacobian_eigenvalues`` can halve its work.
    ``rows(t0, X, u, pv)``: the values (nx, k) at the columns of X by another evaluator of
    ``ode`` with the same bits (a large model's interpreter program, which its run then uses:
    3-6x cheaper than CasADi's virtual machine), or None."""
    x0 = np.asarray(x0, float)
    nx = x0.size
    h = np.cbrt(np.finfo(float).eps) * np.maximum(1.0, np.abs(x0))
    X = np.repeat(x0[:, None], 2 * nx + 1, axis=1)
    idx = np.arange(nx)
    X[idx, 1 + idx] += h
    X[idx, 1 + nx + idx] -= h
    k = X.shape[1]
    if rows is not None:
        F = rows(float(t0), X, np.asarray(u, float), np.asarray(pv, float))
    else:
        with _MAPPED_LOCK:
            F = _mapped(ode, k)(np.full((1, k), float(t0)), X, np.repeat(np.reshape(u, (-1, 1)), k, axis=1),
                                np.repeat(np.reshape(pv, (-1, 1)), k, axis=1))
    F = np.reshape(F, (nx, k), order="F") if F.ndim == 1 else F
    J = (F[:, 1:1 + nx] - F[:, 1 + nx:]) / (2 * h)
    n = nx // 2
    if nx == 2 * n and np.array_equal(F[:n, 0], x0[n:]):
        J[:n] = 0.0
        J[:n, n:] = np.eye(n)
    return J


_MAPPED: dict = {}
_MAPPED_LOCK = threading.Lock()       # a FastFunction's buffers are not shared between threads


def _mapped(ode, k):
    """FastFunction of ``ode.map(k)``, kept per Function (building the map costs ~0.5 ms)."""
    hit = _MAPPED.get((id(ode), k))
    if hit is not None and hit[0] is ode:
        return hit[1]
    fast = FastFunction(ode.map(k))
    if len(_MAPPED) >= 16:
        _MAPPED.pop(next(iter(_MAPPED)))
    _MAPPED[(id(ode), k)] = (ode, fast)
    return fast


def jacobian_eigenvalues(J: np.ndarray) -> np.ndarray:
    """Eigenvalues of the Jacobian of x' = (qd, qdd(q, qd)).  When d qdd / d qd vanishes (no
    damping, at rest: every conservative model's start from rest) J = [[0, I], [A, 0]] and its
    eigenvalues are +-sqrt(mu) for the eigenvalues mu of A: a decomposition of half the size,
    8x less work (a 400 x 400 eigen decomposition costs 0.05-0.5 s of CPU on a loaded machine,
    most of it the BLAS threads' spinning)."""
    n = J.shape[0] // 2
    if (J.shape[0] == 2 * n and n > 0 and not J[:n, :n].any() and not J[n:, n:].any()
            and np.array_equal(J[:n, n:], np.eye(n))):
        root = np.sqrt(np.linalg.eigvals(J[n:, :n]).astype(complex))
        return np.concatenate([root, -root])
    return np.linalg.eigvals(J)


def default_inputs(eom, u):
    """u as given, or the model's input defaults when none was given (NO_U)."""
    if u is NO_U and eom is not None and getattr(eom, "inputs", ()):
        return np.asarray(eom.input_defaults, float)
    return u


def fixed_step_count(method, funcs, x0, pv, t0, t1, rtol, dt, budget=10_000_000, u=NO_U) -> tuple[int, str]:
    """Steps for the fixed-step methods: h = dt, or h * omega = 0.5 rtol^(1/order), omega the
    fastest rate seen at the start: the spectral radius of the Jacobian, sqrt(max |qdd|) and
    max |qd| (coordinates in units of order 1), and 2 pi / horizon."""
    span = t1 - t0
    if dt is not None:
        dt = float(dt)
        if not dt > 0:
            raise UsageError(f"dt must be positive (got {dt})")
        return max(1, math.ceil(span / dt - 1e-9)), f"dt = {dt:g} given"
    omega, rho = time_scale(funcs, x0, pv, t0, t1, u)
    h = 0.5 * rtol ** (1.0 / spec(method).order) / omega
    steps = min(max(1, math.ceil(span / h)), int(budget))
    return steps, ("(capped at the budget) " if steps == int(budget) else "") + (f"h = {span / steps:.3g} from rtol = {rtol:g} and the time scale 1/{omega:.3g} s at the start "
                   f"(Jacobian spectral radius {rho:.3g}/s, sqrt(|qdd|), |qd|)")


def time_scale(funcs, x0, pv, t0, t1, u=NO_U, rho=None) -> tuple[float, float]:
    """(omega, rho): the fastest rate seen at the start, max of the Jacobian's spectral radius
    rho, sqrt(max |qdd|) and max |qd| (coordinates in units of order one: the Jacobian alone is
    ~0 for a pendulum released from the horizontal), and 2 pi / horizon.  ``rho``: the spectral
    radius when known (choose_method computed it; eigenvalues of a 400 x 400 Jacobian cost
    0.05-0.5 s of CPU)."""
    span = t1 - t0
    omega_acc = 0.0
    u = default_inputs(getattr(funcs, "eom", None), u)
    try:
        if rho is None:
            rho = 0.0
            J = numeric_jacobian(funcs["ode"], t0, x0, u, pv)
            rho = float(np.abs(jacobian_eigenvalues(J)).max()) if np.isfinite(J).all() else 0.0
        f = FastFunction(funcs["ode"])(t0, x0, u, pv)
        n = len(x0) // 2
        if np.isfinite(f).all():  # time scales of the motion itself: sqrt(|qdd|) and |qd| (units of 1)
            omega_acc = max(float(np.sqrt(np.abs(f[n:]).max(initial=0.0))), float(np.abs(x0[n:]).max(initial=0.0)))
    except Exception:  # noqa: BLE001
        pass
    return max(rho, omega_acc, 2 * math.pi / span), rho



def min_step(t0, t1) -> float:
    """Steps below this are noise in double precision: the run is declared failed instead."""
    return 1e-12 * max(t1 - t0, abs(t0), abs(t1))

