"""Impacts and unilateral contact (issue 6).

    from mechdsl.impacts import simulate_with_contacts, ContactGap, Fixation
    r = simulate_with_contacts(eom, None, 10.0, rtol=1e-10, atol=1e-12)   # contacts from eom.model
    r.events     # [{"time", "kind", "contact", "impulse", "energy_change", "speed_before", "speed_after"}, ...]

Modules: gaps (gap functions from ir.Contact), system (compiled functions, constrained
accelerations, projection), impact_map (Lagrange's impact equations, any number of
contacts), rootfind and run (event location on dense output and the hybrid loop),
stepper (scipy one-step solvers), table (events summary).  Design: docs/internals/impacts.md.
"""
from .gaps import ContactGap, Fixation, contact_gaps, gap_from_ir, gap_jacobian
from .impact_map import ImpactError, ImpactSolution, solve_impact
from .table import events_table, print_events


def __getattr__(name):
    # the public entry of a contact run is the simulation layer's (this package holds the
    # contact mechanics; the run itself lives in mechdsl.simulation)
    if name == "simulate_with_contacts":
        from ..simulation.entries import simulate_with_contacts

        return simulate_with_contacts
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")

__all__ = ["simulate_with_contacts", "ContactGap", "Fixation", "contact_gaps", "gap_from_ir", "gap_jacobian",
           "solve_impact",
           "ImpactSolution", "ImpactError", "events_table", "print_events", "has_contacts"]


def has_contacts(eom) -> bool:
    """True when a simulation of eom must go through simulate_with_contacts."""
    return bool(eom.model is not None and eom.model.contacts)
