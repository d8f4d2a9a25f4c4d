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

The mechanics of constrained systems, a library the simulation layer uses: system (the
constrained accelerations, KKT routes), init (consistent initialization), dof (degrees of
freedom, redundant constraints), index (the numeric index check), stepper and the
formulations (projection, ggl, baumgarte, partitioning, augmented), options (the settings
group ``dae``).  The segment loop of a run is the simulation layer's DAE back end
(mechdsl.simulation.backends.dae); ``simulate_dae`` is its keyword entry.
"""
from __future__ import annotations

__all__ = ["simulate_dae", "RunInterrupted", "dof_report", "DofReport", "initialize", "InitReport", "check_report",
           "dae_index", "guarded_idas", "FORMULATIONS", "DEFAULT_FORMULATION"]


def __getattr__(name):
    # the package's face: each name is imported from its module on first use, so that reading
    # the options (dae.dae_run, which every run's settings hold) imports nothing else; the public
    # entry of a constrained run is the simulation layer's (this package holds the mechanics of
    # constrained systems; the run itself lives in mechdsl.simulation)
    if name in ("DofReport", "dof_report"):
        from . import dof as module
    elif name in ("dae_index", "guarded_idas"):
        from . import index as module
    elif name in ("InitReport", "check_report", "initialize"):
        from . import init as module
    elif name in ("DEFAULT_FORMULATION", "FORMULATIONS"):
        from . import dae_run as module
    elif name == "RunInterrupted":
        from ..output import result as module
    elif name == "simulate_dae":
        from ..simulation import shims as module
    else:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    return getattr(module, name)
