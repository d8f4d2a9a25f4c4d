"""Equilibria of a model with unilateral contacts (issue 23): the equilibrium conditions are those
of the model without its contacts, so each equilibrium found is checked against them and says so,
and the search says that resting on a contact was not looked for (`mech equilibrium` used to
ignore contacts without a word)."""
from __future__ import annotations

import casadi as ca
import numpy as np

from ..impacts.gaps import contact_gaps

TOUCH = 1e-9        # |gap| below this (m, relative to the sizes): the state touches the contact


def contact_notes(eom, eqs, pv, t: float) -> list[str]:
    """Add to each equilibrium's notes whether it penetrates or touches a contact (and
    ``admissible`` = False when it penetrates); returns the search-level notes."""
    model = getattr(eom, "model", None)
    if model is None or not model.contacts:
        return []
    gaps, fixes = contact_gaps(eom)
    out = []
    if gaps:
        fn = eom.workspace.memo("equilibrium_gaps", lambda: ca.Function(
            "gaps", [eom.q, eom.t, eom.p], [ca.vertcat(*[ca.SX(g.gap) for g in gaps])]))
        out.append(f"contact(s) {', '.join(g.name for g in gaps)} are unilateral: the equilibria are those of "
                   "the model without them, each checked against them; a state resting on a contact (held by "
                   "its force) is not searched")
        for e in eqs:
            values = np.array(fn(e.q, t, pv), float).ravel()
            size = 1.0 + float(np.max(np.abs(e.q), initial=0.0))
            for g, v in zip(gaps, values):
                if v < -TOUCH * size:
                    e.notes.append(f"penetrates contact '{g.name}' (gap {v:.4g} m): not a state the contact allows")
                    e.admissible = False
                elif v <= TOUCH * size:
                    e.notes.append(f"touches contact '{g.name}' (gap {v:.2g} m) without a contact force")
    if fixes:
        out.append(f"fixation(s) {', '.join(f.label for f in fixes)} act at given times during a run: not part "
                   "of the equilibrium conditions")
    return out
