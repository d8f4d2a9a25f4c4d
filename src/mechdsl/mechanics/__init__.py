"""Mechanics: from a resolved model (ir.Model) to equations of motion (eom.EOM).

    from mechdsl.mechanics import derive
    eom = derive(model)                 # route chosen automatically ('aba' | 'crba' | 'lagrange')

Design notes: docs/internals/mechanics.md.
"""
from .derive import ROUTES, derive

__all__ = ["derive", "ROUTES"]
