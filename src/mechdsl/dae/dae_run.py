"""Options of a constrained run as the formulations read them: ``DaeRun``.

The user's options are the settings group ``dae`` of ``mechdsl.simulation.SimulationSettings``
(``DaeOptions``, validated once with the settings; its defaults are written there and nowhere
else).  The DAE back end (mechdsl.simulation.backends.dae) builds one ``DaeRun`` from the
validated settings: the formulation and method resolved, the run's tolerances and the group.
Nothing is parsed from keyword arguments here.
"""
from __future__ import annotations

from typing import Any

from ..model.records import record


FORMULATIONS = ("projection", "ggl", "baumgarte", "partitioning", "augmented")
DEFAULT_FORMULATION = "projection"
STEPS_PER_INTERVAL = 5000     # default step budget per monitoring interval (>= 60 intervals per run)


def resolve_formulation(name: str) -> str:
    """The formulation a name runs (auto and dae: the default; index1: baumgarte)."""
    if name in ("auto", "dae"):
        return DEFAULT_FORMULATION
    if name == "index1":
        return "baumgarte"
    return name


@record(frozen=False)
class DaeRun:
    """What the formulations (steppers) and the segment loop read during one constrained run:
    the run's tolerances and step budget, the formulation and method (resolved by the back
    end: ``method`` is a CVODES multistep method, ``erk`` or ``idas``) and the group's options."""

    formulation: str
    method: str
    rtol: float
    atol: float
    max_steps: int | None
    compiled: bool
    options: Any                     # the settings group (simulation.settings.DaeOptions)

    def __getattr__(self, name):             # the group's options: baumgarte, singular_tol, ...
        if name.startswith("__") or name == "options":
            raise AttributeError(name)
        return getattr(self.options, name)

    @property
    def bound(self) -> float:
        return self.options.bound(self.atol)

    @property
    def steps(self) -> int:
        """Integrator steps allowed per output interval of an integrator call until a segment
        succeeded; then also up to 8 times the steps per unit time seen (see the driver)."""
        return int(self.max_steps or STEPS_PER_INTERVAL)
