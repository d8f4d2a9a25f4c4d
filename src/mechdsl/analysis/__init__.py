"""Beyond simulation: equilibria and stability, linear models and modes, first integrals,
Hamilton's equations.

    from mechdsl.analysis import equilibria, linearize, first_integrals, hamiltonian
    eqs = equilibria(eom)                 # list[Equilibrium]
    lin = linearize(eom, at="equilibrium")
    lin.modes().frequencies               # rad/s, ascending

Constrained models (closed loops, constraint equations) are analysed on their constraint
manifold: equilibria with multipliers, the reduced linear model in independent coordinates
(analysis.reduced), RATTLE for symplectic integration (mechdsl.rattle).

Design notes: docs/internals/analysis.md; user guide: docs/analysis.md.
"""
from __future__ import annotations

__all__ = ["equilibria", "Equilibrium", "linearize", "Linearization", "Modes", "first_integrals",
           "FirstIntegral", "integral_signals", "hamiltonian", "Hamiltonian", "format_hamiltonian"]

_WHERE = {"equilibria": "equilibrium", "Equilibrium": "equilibrium", "linearize": "linearize",
          "Linearization": "linearize", "Modes": "modes", "first_integrals": "integrals",
          "FirstIntegral": "integrals", "integral_signals": "integrals", "hamiltonian": "hamilton",
          "Hamiltonian": "hamilton", "format_hamiltonian": "hamilton"}


def __getattr__(name):
    if name in _WHERE:
        import importlib

        return getattr(importlib.import_module(f".{_WHERE[name]}", __name__), name)
    raise AttributeError(name)
