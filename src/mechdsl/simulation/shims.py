"""The keyword entry points of constrained and contact runs, kept public:
``mechdsl.dae.simulate_dae`` and ``mechdsl.impacts.simulate_with_contacts`` (docs/constraints.md,
docs/contacts.md).

Thin shims: the keyword arguments become one validated ``SimulationSettings``
(``settings.from_kwargs``, the same names and checks as ``Model.simulate``), and the run goes
through the one layer (``template.simulate``: the start check, formulate, solve), so these
entries give the same checks, defaults and metadata as every other run.  The packages ``dae``
and ``impacts`` hold the mechanics; they re-export these names lazily from here, so neither
imports the simulation layer.
"""
from __future__ import annotations

import numpy as np

from ..diagnostics import UsageError
from ..eom import parameter_vector
from ..eom.start import start_vector
from ..output.result import Result
from .settings import from_kwargs
from .template import simulate


def simulate_dae(eom, t_end=None, *, progress=None, **kw) -> Result:
    """Simulate a model with constraints (``eom.g``) as a DAE with multipliers.

    The keyword arguments are those of ``mechdsl.simulate.simulate``: formulation ('auto' =
    'projection' | 'ggl' | 'baumgarte' | 'partitioning' | 'augmented'), rtol, atol, method
    ('auto' | 'bdf' | 'adams' | 'erk' for the ODE formulations, 'idas' for ggl), points,
    t_start, p (vector or {name: value}), x0, reactions (bool), outputs (names), and the dae
    group's baumgarte (omega or (alpha, beta)), singular_tol, max_interval, drift_bound,
    max_steps.  See docs/constraints.md.
    """
    if eom.g is None or getattr(eom, "m", 0) == 0:
        raise UsageError("simulate_dae needs a model with constraints; use mechdsl.simulate for ODEs")
    return simulate(eom, from_kwargs(t_end, **kw), progress=progress)


def simulate_with_contacts(eom, contacts=None, t_end=None, *, q0=None, qd0=None, fixations=(), progress=None,
                           **kw) -> Result:
    """Simulate eom with unilateral contacts from t_start to t_end; output on a uniform grid.

    contacts: ``ir.Contact`` / ``ContactGap`` / ``Fixation`` objects (default: the model's);
    fixations: more :class:`Fixation` objects.  x0 ([q; qd] or {name: value, "der(name)": value})
    and p (vector or {name: value}) as for ``mechdsl.simulate.simulate``; q0/qd0 override the
    start values directly.  progress: a callable(t, t_end).  The other keyword arguments are
    those of ``mechdsl.simulate.simulate`` (the contacts group: rest_speed (m/s, default 1e-3),
    impact_order ("simultaneous" | "sequential"), output_events, gap_tol, event_offset,
    max_events, max_step, samples; see docs/contacts.md).  The events are in ``result.events``.
    """
    model = getattr(eom, "model", None)
    if contacts is None and not (model is not None and model.contacts) and not fixations:
        raise UsageError("simulate_with_contacts needs contacts (the model has none; pass ContactGap objects) "
                         "or use mechdsl.simulate")
    if q0 is not None or qd0 is not None:     # start values given directly: the full state
        xs = start_vector(eom, kw.get("x0"), parameter_vector(eom, kw.get("p")))
        if q0 is not None:
            xs[:eom.n] = np.asarray(q0, float).ravel()
        if qd0 is not None:
            xs[eom.n:] = np.asarray(qd0, float).ravel()
        kw["x0"] = xs
    kw["contacts"] = None if contacts is None else tuple(contacts)
    kw["fixations"] = tuple(fixations)
    return simulate(eom, from_kwargs(t_end, **kw), progress=progress)


__all__ = ["simulate_dae", "simulate_with_contacts"]
