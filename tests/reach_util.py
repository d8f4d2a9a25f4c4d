"""Helpers of the issue-17 language tests: evaluate a derived model's quantities numerically."""
from __future__ import annotations

import casadi as ca
import numpy as np


def evaluator(eom, *exprs):
    """A function (q, qd, t=0) -> list of numpy arrays of the given SX expressions, with the
    model's parameter values (and its inputs at their defaults)."""
    args = [eom.q, eom.qd, eom.t, eom.p] + ([eom.u] if eom.u is not None else [])
    f = ca.Function("f", args, [ca.SX(e) for e in exprs], {"allow_free": True})

    def call(q, qd, t=0.0):
        extra = [np.array(eom.input_defaults, float)] if eom.u is not None else []
        out = f(np.asarray(q, float), np.asarray(qd, float), t, eom.param_values, *extra)
        out = out if isinstance(out, (list, tuple)) else [out]
        return [np.array(o, float).reshape(-1) for o in out]

    return call


def output_values(model, q, qd, names, t=0.0):
    """The named outputs of an api.Model at a state, as a dict of numpy arrays."""
    e = model.eom
    vals = evaluator(e, *[e.outputs[n] for n in names])(q, qd, t)
    return dict(zip(names, vals))


def accelerations(eom):
    """(q, qd) -> qdd of an unconstrained model: the explicit forward dynamics, or M^-1 bias."""
    if eom.qdd is not None:
        f = evaluator(eom, eom.qdd)
        return lambda q, qd, t=0.0: f(q, qd, t)[0]
    f = evaluator(eom, eom.M, eom.bias)
    n = len(eom.coords)

    def call(q, qd, t=0.0):
        M, b = f(q, qd, t)
        return np.linalg.solve(M.reshape(n, n, order="F"), b)

    return call
