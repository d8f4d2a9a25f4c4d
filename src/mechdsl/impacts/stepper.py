"""One-step integration with dense output (scipy's ODE solvers driven step by step).

Event location needs every accepted step and an interpolant on it; CasADi's integrators
return only grid values, and its event support is experimental (see
benchmarks/impacts_casadi_events.py), so models with contacts are stepped here with
scipy's solvers on CasADi-generated right-hand sides.
"""
from __future__ import annotations

from ..diagnostics import UsageError

SCIPY_METHODS = {"dop853": "DOP853", "rk45": "RK45", "rk23": "RK23", "radau": "Radau", "bdf": "BDF",
                 "lsoda": "LSODA"}
# the ODE simulator's method names (mechdsl.integrators) -> the closest one-step solver here
ALIASES = {"auto": "dop853", "erk": "dop853", "dopri5": "rk45", "cvodes-adams": "dop853", "rk": "dop853",
           "cvodes": "bdf", "cvodes-bdf": "bdf", "idas": "bdf", "rosenbrock": "radau", "collocation": "radau",
           **{f"scipy-{k}": k for k in SCIPY_METHODS}}
SYMPLECTIC = ("stormer-verlet", "implicit-midpoint", "gauss-legendre")
# steps a period of an oscillation take at tolerance rtol: about c rtol^(-1/order), measured on a
# pendulum swinging 1 rad (rtol 1e-3 .. 1e-12; c measured 1.25-1.42 for the explicit pairs,
# 2.2-5.9 Radau, 2.6-4.9 BDF, 5.3-13 LSODA read as order 12); (order, c) here are lower bounds
PERIOD_STEPS = {"DOP853": (8, 1.0), "RK45": (5, 1.0), "RK23": (3, 1.0), "Radau": (5, 2.0), "BDF": (5, 2.0),
                "LSODA": (12, 5.0)}
IMPLICIT = ("Radau", "BDF", "LSODA")


def steps_per_period(cls_name: str, rtol: float) -> float:
    """The fewest steps the one-step solver ``cls_name`` takes to follow one oscillation at
    tolerance ``rtol`` (a lower bound: the work estimate refuses a run only when it must fail)."""
    order, c = PERIOD_STEPS.get(cls_name, (8, 1.0))
    return max(1.0, c * rtol ** (-1.0 / order))


def resolve_method(method: str | None) -> tuple[str, str]:
    """(scipy class name, note) for a method name; notes say when a name was mapped."""
    name = (method or "auto").lower()
    if name in SCIPY_METHODS:
        return SCIPY_METHODS[name], ""
    if name in ALIASES:
        target = ALIASES[name]
        note = ""
        if name != "auto" and not name.startswith("scipy-"):
            note = (f"method '{method}' is stepped as '{target}' for event location "
                    "(models with contacts run scipy's one-step methods; dop853 and rk45 compiled between events)")
        return SCIPY_METHODS[target], note
    if name in SYMPLECTIC:
        raise UsageError(f"the symplectic method '{method}' cannot step over impacts; "
                         "use a method with error control (e.g. auto, dop853, radau)")
    raise UsageError(f"unknown method '{method}' for a model with contacts; methods: "
                     + ", ".join(dict.fromkeys(["auto", *SCIPY_METHODS, *ALIASES])))


def make_solver(cls_name: str, fun, t0: float, y0, t_bound: float, rtol: float, atol: float,
                max_step: float | None = None, first_step: float | None = None, jac=None):
    import numpy as np
    from scipy import integrate

    cls = getattr(integrate, cls_name)
    kw = {}
    if max_step is not None:
        kw["max_step"] = max_step
    if first_step is not None and first_step < (t_bound - t0):
        kw["first_step"] = first_step
    if jac is not None and cls_name in ("Radau", "BDF", "LSODA"):
        kw["jac"] = jac
    return cls(fun, t0, np.asarray(y0, float), t_bound, rtol=rtol, atol=atol, **kw)
