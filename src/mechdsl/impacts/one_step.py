"""One-step integration with dense output (scipy's ODE solvers driven step by step).

Event location needs every accepted step and an interpolant on it; CasADi's integrators
return only grid values, and its event support is experimental (see
benchmarks/impacts_casadi_events.py), so models with contacts are stepped here with
scipy's solvers on CasADi-generated right-hand sides.  Which method names step as which
class: the method registry (``mechdsl.simulation.registry``, ``MethodSpec.events``).
"""
from __future__ import annotations


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
