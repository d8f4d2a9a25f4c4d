"""The keyword entry points of the constrained and contact runs, kept public:
``mechdsl.dae.simulate_dae`` and ``mechdsl.impacts.simulate_with_contacts`` (docs/contacts.md,
docs/constraints.md).  The packages ``dae`` and ``impacts`` hold the mechanics; they re-export
these names lazily from here, so neither imports the simulation layer.
"""
from __future__ import annotations

from .backends.dae import simulate_dae
from .backends.events import simulate_with_contacts

__all__ = ["simulate_dae", "simulate_with_contacts"]
