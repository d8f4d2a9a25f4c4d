"""Calling a model's Function from Python in a loop (``Model.fast_function``).

A plain call of a ``casadi.Function`` converts every argument to a DM and back: 30-120 us
whatever the model.  ``fast_function`` compiles the Function (sxcode's C through
``casadi_functions(compiled=True)``; the virtual machine without a compiler, or with
``compiled=False``) and wraps it in ``codegen.FastFunction``: the arguments are copied into
preallocated buffers and the Function evaluated through ``Function.buffer()``, with the
parameters and inputs bound once.  What remains per call is the copy in and out (about a
microsecond) and the evaluation itself (benchmarks/python_call.py: a 7-joint arm's ``ode``
against Pinocchio's ``aba``).
"""
from __future__ import annotations

import numpy as np

from .codegen import FastFunction, casadi_functions


class FastCall:
    """``f(*free inputs)`` -> the Function's output(s) as numpy arrays (new arrays each call)."""

    def __init__(self, function, fast, bound: dict, notes):
        self.function, self._call, self.bound, self.notes = function, fast, bound, list(notes)
        self.inputs = tuple(n for n in function.name_in() if n not in bound)

    def __call__(self, *args):
        return self._call(*args)

    def __repr__(self):
        return f"<FastCall {self.function.name()}({', '.join(self.inputs)}) {self.function.class_name()}>"


def fast_function(eom, name: str = "ode", *, compiled: bool = True, p=None, u=None) -> FastCall:
    """``name`` of ``casadi_functions(eom, sx=True)`` (compiled when asked and possible) with the
    inputs ``p`` and ``u`` bound (u: the inputs' defaults when not given)."""
    funcs = casadi_functions(eom, names=(name,), compiled=compiled, sx=True)
    f = funcs[name]
    names = f.name_in()
    bound = {}
    if "p" in names:
        bound["p"] = np.asarray(eom.param_values if p is None else p, float).ravel()
    if "u" in names:
        bound["u"] = np.asarray(eom.input_defaults if u is None else u, float).ravel()
    fast = FastFunction(f).bind(**bound)
    return FastCall(f, fast, bound, getattr(funcs, "notes", []))
