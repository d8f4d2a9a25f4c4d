"""Impacts and unilateral contact (issue 6).

    from mechdsl.impacts import simulate_with_contacts, ContactGap, Fixation
    r = simulate_with_contacts(eom, None, 10.0, rtol=1e-10, atol=1e-12)   # contacts from eom.model
    r.events     # [{"time", "kind", "contact", "impulse", "energy_change", "speed_before", "speed_after"}, ...]

The contact mechanics, a library the simulation layer uses: gaps (gap functions from
ir.Contact), system (compiled functions, constrained accelerations, projection), impact_map
(Lagrange's impact equations, any number of contacts), rootfind (event location on dense
output), stepper (scipy one-step solvers), options (the settings group ``contacts``), table
(events summary).  The hybrid loop itself is the simulation layer's contact back end
(mechdsl.simulation.backends.events).  Design: docs/internals/impacts.md.
"""
from __future__ import annotations

__all__ = ["simulate_with_contacts", "ContactGap", "Fixation", "contact_gaps", "gap_from_ir", "gap_jacobian",
           "solve_impact", "ImpactSolution", "ImpactError", "events_table", "print_events", "has_contacts"]


def has_contacts(eom) -> bool:
    """True when a simulation of eom must go through simulate_with_contacts."""
    return bool(eom.model is not None and eom.model.contacts)


def __getattr__(name):
    # the package's face: each name is imported from its module on first use (reading the
    # options, which every run's settings hold, imports nothing else); the public entry of a
    # contact run is the simulation layer's (this package holds the contact mechanics)
    if name in ("ContactGap", "Fixation", "contact_gaps", "gap_from_ir", "gap_jacobian"):
        from . import gaps as module
    elif name in ("ImpactError", "ImpactSolution", "solve_impact"):
        from . import impact_map as module
    elif name in ("events_table", "print_events"):
        from . import table as module
    elif name == "simulate_with_contacts":
        from ..simulation import shims as module
    else:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    return getattr(module, name)
