"""``mechdsl.simulate.simulate(eom, t_end, **settings) -> Result``: the keyword form of a run.

A shim over the one simulation layer (mechdsl.simulation): the keyword arguments become a
validated ``SimulationSettings`` (``settings.from_kwargs``), then ``simulation.simulate``
checks the start, formulates and solves, exactly as ``Model.simulate`` does.
"""
from __future__ import annotations

from .output.result import Result


def simulate(eom, t_end=None, *, progress=None, **kw) -> Result:
    """Integrate ``eom`` from t_start to t_end and sample it on ``points`` equidistant times.

    The keyword arguments are the fields of :class:`mechdsl.simulation.SimulationSettings`
    (t_start, rtol, atol, method, formulation, points, outputs, x0, p, dt, reactions,
    compiled, max_steps, integrator_options, rest_speed, impact_order, budget,
    estimate_error) and the options of its groups (dae: baumgarte, drift_bound, ...;
    contacts: gap_tol, max_events, ...; fixed_step: newton_tol, max_newton; ode:
    singularity_threshold, functions).  x0: full state [q; qd] (array) or a dict of
    overrides {coordinate: value, "der(c)": value}; p: parameter vector or dict of
    overrides {name: value} (dependent parameters are not re-evaluated: use
    Model.with_params for that).  t_end None: 10 s.  progress: True shows a bar on stderr
    for runs longer than 0.5 s, or a callable(t, t_end).
    """
    from .simulation import simulate as run
    from .simulation.settings import from_kwargs

    return run(eom, from_kwargs(t_end, **kw), progress=progress)
