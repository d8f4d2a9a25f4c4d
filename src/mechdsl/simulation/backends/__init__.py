"""Back ends: one plug-in per problem kind, each with two hooks.

    run(problem, progress) -> Result          integrate (reads problem.settings: the common
                                              fields and its own option groups)
    describe(result) -> dict                  what actually ran: formulation, integrator, method

The template in ``mechdsl.simulation.solve`` calls them in a fixed order and does everything
common to all runs itself (settings, progress bar, non-finite check, statistics schema,
accuracy report, metadata, versions).  One module each:

    ode.py          minimal-coordinate ODEs: integrator plug-ins (plugins.py), the compiled
                    stepping loop (crk.py + crk.c)
    dae.py          constrained models: the segment loop over the formulations of mechdsl.dae
    events.py       contacts: the hybrid event loop (event_loop.py) over mechdsl.impacts, free
                    flight in the compiled loop (event_flight.py)
    fixed_step.py   fixed-step canonical integration and RATTLE (step functions: schemes.py)

This module is the layer's face for the back ends: each back end's module is imported when
a run first needs it (``backend(name)``), so an ODE run never imports the contact loop
(scipy) or the DAE formulations.  How to add a back end: docs/internals/simulation.md.
"""
from __future__ import annotations

import abc
import dataclasses

from ...diagnostics import UsageError
from ...output.result import Result
from ..settings import GROUPS

BACKENDS = ("ode", "dae", "events", "fixed-step")    # names; each module is imported on first use
_LOADED: dict[str, "Backend"] = {}


class Backend(abc.ABC):
    name = ""
    noun = ""                                 # "an ODE", "a DAE", ...: the problem it solves, in notes
    groups: tuple[str, ...] = ()              # option groups of SimulationSettings it reads
    ignores: tuple[str, ...] = ()             # common settings without effect here
    accepts: dict[str, tuple] = {}            # values of other groups' settings that mean nothing to note
    fixed_step = False                        # fixed step (accuracy report and error estimate differ)

    def prepare(self, problem):
        """What a run builds before it integrates, built once for several runs that differ only
        in parameters and start values (``simulation.prepared``); None: nothing to keep (the
        back end's Functions are kept in the EOM's workspace anyway)."""
        return None

    @abc.abstractmethod
    def run(self, problem, progress, setup=None) -> Result:
        """Integrate the problem (with ``setup`` from ``prepare`` when given); a failure is kept
        in Result.failure, never raised."""

    def describe(self, result: Result) -> dict:
        return {}

    def integration(self, problem, setup, pv, xs):
        """(method, Functions, why): the ODE a run of ``problem`` integrates and the ODE method
        it integrates it with, for its differentiable trajectory (simulation/trajectory.py)."""
        raise UsageError(f"{self.noun} problem has no differentiable trajectory")

    def start(self, problem, xs, pv, x0):
        """(x, dx/dx_given, dx/dp): the start a run of ``problem`` begins from, given the start
        values ``xs`` (overrides ``x0`` applied) at the parameters ``pv``, and its
        linearization; without constraints the start values as given."""
        import numpy as np

        return xs, np.eye(xs.size), np.zeros((xs.size, np.size(pv)))


def backend(name: str) -> Backend:
    """The back end called ``name`` (its module imported on first use)."""
    hit = _LOADED.get(name)
    if hit is None:
        if name == "ode":
            from .ode import OdeBackend as cls
        elif name == "dae":
            from .dae import DaeBackend as cls
        elif name == "events":
            from .events import EventsBackend as cls
        elif name == "fixed-step":
            from .fixed_step import FixedStepBackend as cls
        else:
            raise KeyError(name)
        hit = _LOADED[name] = cls()
    return hit


def python_signals(problem) -> tuple[str, ...]:
    """Inputs driven by Python callables: call nodes in the equations, which C cannot hold."""
    drive = problem.drive
    return tuple(sg.name for sg in drive.signals if sg.kind == "callable") if drive is not None else ()


def compiled_setting(problem) -> tuple[bool, str | None]:
    """compiled as asked, unless Python signals are in the equations (then a note why not)."""
    s = problem.settings
    names = python_signals(problem) if problem.kind != "ode" else ()
    if s.compiled and names:
        return False, (f"compiled = true not applied: the input signal(s) {', '.join(names)} are Python "
                       "functions, which compiled code cannot call; the run used the virtual machine")
    return bool(s.compiled), None


def ignored_settings(b: Backend, settings) -> list[str]:
    """The settings a run was given that its back end does not use: common fields it ignores,
    and the fields of other back ends' groups that differ from their defaults."""
    out = []
    defaults = {f.name: f.default for f in dataclasses.fields(settings)}
    for name in b.ignores:
        v = getattr(settings, name)
        if v not in (None, False, {}, "auto") and v != defaults[name]:
            out.append(f"{name} = {v!r}")
    other = []
    for g, cls in GROUPS.items():
        if g in b.groups:
            continue
        group, default = getattr(settings, g), cls()
        for f in dataclasses.fields(group):
            v = getattr(group, f.name)
            if v != getattr(default, f.name) and v not in b.accepts.get(f.name, ()):
                other.append(f"{f.name} = {v!r}")
    return out + sorted(other)
