"""Options of a run with contacts as the event loop reads them: ``ContactRun``, the run's
tolerances with the settings group ``contacts`` (``simulation.settings.ContactOptions``, whose
defaults are documented in docs/contacts.md and written there only)."""
from __future__ import annotations


class ContactRun:
    """What the event loop reads during one run: rtol and atol of the run, the group's options,
    and the tolerances derived from them."""

    def __init__(self, options, rtol: float, atol: float):
        self.options, self.rtol, self.atol = options, float(rtol), float(atol)

    def __getattr__(self, name):             # the group's options: rest_speed, max_events, ...
        if name.startswith("__") or name == "options":
            raise AttributeError(name)
        return getattr(self.options, name)

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
