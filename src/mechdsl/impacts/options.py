"""Options of simulations with contacts (defaults documented in docs/contacts.md)."""
from __future__ import annotations

from dataclasses import dataclass

from ..diagnostics import UsageError

IMPACT_ORDERS = ("simultaneous", "sequential")


@dataclass(frozen=True, kw_only=True)
class ContactOptions:
    rtol: float = 1e-8
    atol: float = 1e-10
    rest_speed: float = 1e-3        # m/s: an impact leaving a contact slower than this ends in persistent contact
    gap_tol: float | None = None    # m: contacts this close take part in an impact (default max(1e-9, 100 atol))
    event_offset: float | None = None   # m: events fire at gap = -event_offset (default atol)
    impact_order: str = "simultaneous"
    max_events: int = 100000
    max_steps: int = 200_000        # steps in one run (Python steps cost ~0.1-0.5 ms, compiled free flight
                                    # ~1 us): a collapsed step size, or a run estimated to need more, fails
    max_step: float | None = None
    proj_tol: float | None = None   # drift of active constraints that triggers a projection (default 100 atol)
    samples: int = 4                # sub-intervals per step on which event functions are sampled
    acc_tol: float = 1e-8           # m/s2: contact accelerations below this count as zero (relative to max(1, |a|))

    def __post_init__(self):
        if self.impact_order not in IMPACT_ORDERS:
            raise UsageError(f"impact order must be one of {', '.join(IMPACT_ORDERS)}, got '{self.impact_order}'")
        for name in ("rtol", "atol", "rest_speed"):
            v = getattr(self, name)
            if isinstance(v, bool) or not (isinstance(v, (int, float)) and 0 < v < float("inf")):
                raise UsageError(f"{name} must be a positive number, got {v!r}")
        if self.samples < 1:
            raise UsageError("samples must be at least 1")

    @property
    def offset(self) -> float:
        return self.atol if self.event_offset is None else self.event_offset

    @property
    def touch(self) -> float:
        return max(1e-9, 100 * self.atol, 2 * self.offset) if self.gap_tol is None else self.gap_tol

    @property
    def drift_tol(self) -> float:
        return 100 * self.atol if self.proj_tol is None else self.proj_tol

    @property
    def v_eps(self) -> float:
        """Normal speeds smaller than this are neither approach nor separation."""
        return 1e-6 * self.rest_speed
