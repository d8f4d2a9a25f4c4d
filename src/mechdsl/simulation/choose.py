"""Method choice and step counts from the model at the start of a run.

``choose_method`` (method = auto: stiffness from the Jacobian's eigenvalues), the fixed step
count of the fixed-step plug-ins, the model's time scale, and the smallest step a run may take.
Used by the ODE back end, the prepared problem, sweeps, ``mech bench`` and the compiled
loop's cost estimate (backends/crk.py).
"""
from __future__ import annotations

import math
from typing import Any

import numpy as np

from ..diagnostics import UsageError
from ..eom.codegen import FastFunction
from .registry import spec


NO_U = np.zeros(0)                   # the input vector u of a model without inputs


def choose_method(eom, funcs, x0, pv, t0, t1, rtol, u=NO_U) -> tuple[str, str, dict]:
    """method=auto: stiffness from the Jacobian's eigenvalues at the start, then the tolerance.

    Rules (docs/internals/numerics.md): stiff (a decay rate much faster than the slowest
    time scale and than the horizon) -> cvodes-bdf; otherwise erk (adaptive explicit
    Runge-Kutta 5(4)), which beat cvodes-adams, idas and scipy at every tolerance from 1e-4
    to 1e-12 on the work-precision benchmark.
    """
    span = t1 - t0
    info: dict[str, Any] = {}
    u = default_inputs(eom, u)
    try:
        J = FastFunction(funcs["ode_jacobian"])(t0, x0, u, pv)
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
            J = FastFunction(funcs["ode_jacobian"])(t0, x0, u, pv)
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

