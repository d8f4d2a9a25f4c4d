"""The one simulation layer: ``simulate(eom, settings) -> Result`` = formulate, then solve.

    settings (SimulationSettings, validated once)  -- settings.py
      -> formulate(eom, settings) -> Problem         -- problem.py (mech compile --emit problem)
      -> solve(problem) -> Result                    -- template.py: the run template
           progress -> backend.run -> non-finite check -> statistics schema
           -> accuracy report -> metadata (what ran) -> versions -> [error estimate]

The package's face: its names are imported from their modules on first use, so that a
command that only resolves settings (``mech check``) does not import the back ends.
See docs/internals/simulation.md.
"""
from __future__ import annotations

__all__ = ["SimulationSettings", "Problem", "formulate", "solve", "simulate", "resolve", "from_kwargs", "dump"]


def __getattr__(name):
    if name in ("SimulationSettings", "resolve", "from_kwargs"):
        from . import settings as module
    elif name in ("Problem", "formulate", "dump"):
        from . import problem as module
    elif name in ("simulate", "solve"):
        from . import template as module
    else:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    return getattr(module, name)
