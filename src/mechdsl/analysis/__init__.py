"""Beyond simulation: equilibria and stability, linear models and modes, first integrals,
Hamilton's equations.

    from mechdsl.analysis import equilibria, linearize, first_integrals, hamiltonian
    eqs = equilibria(eom)                 # list[Equilibrium]
    lin = linearize(eom, at="equilibrium")
    lin.modes().frequencies               # rad/s, ascending

Constrained models (closed loops, constraint equations) are analysed on their constraint
manifold: equilibria with multipliers, the reduced linear model in independent coordinates
(analysis.reduced), RATTLE for symplectic integration (the simulation layer's fixed-step back end).

Design notes: docs/internals/analysis.md; user guide: docs/analysis.md.
"""
from __future__ import annotations

__all__ = ["equilibria", "Equilibrium", "linearize", "Linearization", "Modes", "first_integrals",
           "FirstIntegral", "integral_signals", "hamiltonian", "Hamiltonian", "format_hamiltonian"]

def __getattr__(name):
    # the package's face: each name is imported from its module on first use (an ODE run reads
    # integral_signals only when it searches first integrals, not on a warm run)
    if name in ("equilibria", "Equilibrium"):
        from . import equilibrium as module
    elif name == "linearize":
        from . import linearize as module
    elif name == "Linearization":
        from . import linear_model as module
    elif name == "Modes":
        from . import modes as module
    elif name in ("first_integrals", "FirstIntegral", "integral_signals"):
        from . import integrals as module
    elif name in ("hamiltonian", "Hamiltonian", "format_hamiltonian"):
        from . import hamilton as module
    else:
        raise AttributeError(name)
    return getattr(module, name)
