"""An SX Function of (..., p) that, called in an MX expression graph with p given as numbers,
calls its specialization to those numbers.

An optimizer written with CasADi's Opti (or any MX graph) calls ``m.casadi()["ode"]`` with the
model's parameter vector as numbers: ``ode(0, X[:, k], U[:, k], m.parameter_vector())``.  p is
then a constant node of the MX graph, but CasADi differentiates the call in every direction of
every input, p included, and cannot fold the SX operations on p alone (MX does no constant
folding): IPOPT's constraint Jacobian and exact Hessian paid again, in every call and
direction, the chain from p to the parameter combinations (the cart-pole's m l / 2, M + m, ...)
and the products of those combinations with the state (forward in 5 directions: 346
instructions against 243 for a hand-written model with its numbers built in).

``NumericP`` is the Function itself (same class name, instructions, derivatives, serialization:
every use as a CasADi object is unchanged); only its Python call is different when some
argument is MX and p is numbers (numpy, list, DM): it calls the Function with those numbers
built in (``eom.specialize``: what ``fixed_parameters`` builds; CasADi folds the
operations on the numbers, and the leaned, folded ode has 30 instructions, forward in 5
directions 187).  The values are the same to round-off (tests/test_numeric_p.py).  Nothing is
lost: p given as numbers is a constant of the graph, which nothing can differentiate; p given
as a symbol (``opti.parameter()``, ``MX.sym``) goes through the Function with its full
derivatives with respect to p.  An SX call folds the numbers by itself (SX does constant
folding), so SX and numeric calls go straight to the Function.  The specializations are kept
per parameter vector (the last KEPT).
"""
from __future__ import annotations

import numpy as np

import casadi as ca

KEPT = 8


def _numbers(v):
    """``v`` as a flat float array when it is numbers (not symbols), else None."""
    if isinstance(v, ca.DM):
        return np.array(v.full(), float).ravel(order="F")
    if isinstance(v, (ca.MX, ca.SX)):
        return None
    try:
        a = np.asarray(v, float)
    except (TypeError, ValueError):
        return None
    return a.ravel(order="F")


class NumericP(ca.Function):
    """``f`` (an SX Function with an input named "p"), specialized to p when called in an MX
    graph with p as numbers (see the module docstring)."""

    def __init__(self, f):
        super().__init__(f)
        self._special: dict = {}

    def __call__(self, *args, **kwargs):
        if kwargs or len(args) != self.n_in() or not any(isinstance(a, ca.MX) for a in args):
            return super().__call__(*args, **kwargs)
        k = self.name_in().index("p")
        v = _numbers(args[k])
        if v is None or v.size != self.nnz_in(k) or v.size == 0:
            return super().__call__(*args)
        g = self.specialized(v)
        rest = list(args)
        rest[k] = ca.DM(0, 1)
        return g(*rest)

    def specialized(self, v):
        """The Function with p = ``v`` built in (its input p empty), built once per vector."""
        from .specialize import shared_derivatives, specialize

        special = self.__dict__.setdefault("_special", {})
        key = np.asarray(v, float).tobytes()
        g = special.get(key)
        if g is None:
            g = shared_derivatives(specialize(ca.Function(self), list(enumerate(map(float, v))), len(v)))
            if len(special) >= KEPT:
                special.pop(next(iter(special)))
            special[key] = g
        return g


def numeric_p(f):
    """``f`` as a NumericP where that applies (an SX Function with a non-empty input "p"), else
    ``f``."""
    if isinstance(f, NumericP) or not f.is_a("SXFunction") or "p" not in f.name_in() \
            or f.nnz_in(f.name_in().index("p")) == 0:
        return f
    return NumericP(f)
