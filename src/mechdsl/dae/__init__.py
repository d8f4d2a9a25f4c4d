"""Constrained models as DAEs with multipliers (closed loops, explicit constraints).

    M(q, t) q'' = bias(q, q', t) - G^T lambda,    g(q, t) = 0,    G = dg/dq

Public API:
    simulate_dae(eom, t_end, **options) -> Result      (see docs/constraints.md)
    RunInterrupted                                      (Ctrl-C: a KeyboardInterrupt with .result)
    dof_report(eom, q=None, t=0.0, p=None) -> DofReport
    initialize(eom, q0=None, qd0=None, t=0.0, p=None) -> InitReport
    check_report(eom, p=None) -> list[str]              (lines for `mech check`)
    dae_index(dae, x0, z0, p0, t0) -> int               (index of a semi-explicit DAE)
    FORMULATIONS, DEFAULT_FORMULATION
"""
from ..output.result import RunInterrupted
from .dof import DofReport, dof_report
from .index import dae_index, guarded_idas
from .init import InitReport, check_report, initialize
from .options import DEFAULT_FORMULATION, FORMULATIONS


def __getattr__(name):
    # the public entry of a constrained run is the simulation layer's (this package holds the
    # mechanics of constrained systems; the run itself lives in mechdsl.simulation)
    if name == "simulate_dae":
        from ..simulation.entries import simulate_dae

        return simulate_dae
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")

__all__ = ["simulate_dae", "RunInterrupted", "dof_report", "DofReport", "initialize", "InitReport", "check_report",
           "dae_index", "guarded_idas", "FORMULATIONS", "DEFAULT_FORMULATION"]
