"""The CasADi Functions of the problem a run solves, for other tools (``Model.casadi``).

An unconstrained model's are its own (``codegen.casadi_functions``); a constrained model's are
the formulated problem's, the index-1 ODE with the multipliers solved and the DAE pieces by
name (mechdsl.dae.functions).  A module of its own: an ODE run does not import the DAE
package (tests/test_sim_layer.py).
"""
from __future__ import annotations

from ..dae.functions import ConstrainedFunctionSet
from ..eom.codegen import casadi_functions


def problem_functions(eom, *, compiled: bool = False, derivatives: int = 0, sx: bool = False, fixed=(),
                      names=None, each: bool = False, budget: int | None = None):
    """The CasADi Functions of the problem a run of ``eom`` solves (lazy mapping, built on first
    use; ``codegen.casadi_functions``): a constrained model's are those of its index-1 ODE with
    the multipliers solved, and its DAE pieces by name (mechdsl.dae.functions)."""
    kind = ConstrainedFunctionSet if eom.g is not None and getattr(eom, "m", 0) > 0 else None
    return casadi_functions(eom, compiled=compiled, derivatives=derivatives, sx=sx, fixed=fixed, names=names,
                            each=each, budget=budget, kind=kind)
