"""Back ends: one plug-in per problem kind, each with two hooks.

    run(problem, progress) -> Result          integrate (the back end's own driver)
    describe(result) -> dict                  what actually ran: formulation, integrator, method

The template in ``mechdsl.simulation.solve`` calls them in a fixed order and does everything
common to all runs itself (settings, progress bar, non-finite check, statistics schema,
accuracy report, metadata).  The drivers stay where their numerics live: ODE in
``mechdsl.simulate`` (+ ``integrators``), DAE in ``mechdsl.dae``, contacts in
``mechdsl.impacts``, fixed step in ``mechdsl.symplectic`` (+ ``rattle``).
"""
from __future__ import annotations

import abc

from ...output.result import Result


class Backend(abc.ABC):
    name = ""
    ignores: tuple[str, ...] = ()       # settings without effect here (noted in the metadata when set)

    @abc.abstractmethod
    def run(self, problem, progress) -> Result:
        """Integrate the problem; a failure is kept in Result.failure, never raised."""

    def describe(self, result: Result) -> dict:
        return {}


class OdeBackend(Backend):
    name = "ode"
    ignores = ("rest_speed", "impact_order", "output_events")

    def run(self, problem, progress):
        from .ode import simulate_ode

        return simulate_ode(problem.eom, problem.settings, progress, drive=problem.drive)

    def describe(self, r):
        from ... import integrators as I

        method = r.metadata.get("method")
        row = I.METHODS.get(method)
        plugin = "none" if row is None else f"{row[0]}:{row[1]}"
        return {"formulation": "ode", "integrator": plugin, "method": method}


def python_signals(problem) -> tuple[str, ...]:
    """Inputs driven by Python callables: call nodes in the equations, which C cannot hold."""
    drive = problem.drive
    return tuple(sg.name for sg in drive.signals if sg.kind == "callable") if drive is not None else ()


def _compiled(problem) -> tuple[bool, str | None]:
    """compiled as asked, unless Python signals are in the equations (then a note why not)."""
    s = problem.settings
    names = python_signals(problem) if problem.kind != "ode" else ()
    if s.compiled and names:
        return False, (f"compiled = true not applied: the input signal(s) {', '.join(names)} are Python "
                       "functions, which compiled code cannot call; the run used the virtual machine")
    return bool(s.compiled), None


def _noted(r: Result, note: str | None) -> Result:
    if note:
        r.metadata.setdefault("notes", []).append(note)
    return r


class DaeBackend(Backend):
    name = "dae"
    ignores = ("rest_speed", "impact_order", "output_events")

    def run(self, problem, progress):
        from .dae import simulate_dae

        s = problem.settings
        kw = dict(s.extra)
        for key in ("dt", "integrator_options"):
            if getattr(s, key):
                kw[key] = getattr(s, key)
        compiled, note = _compiled(problem)
        return _noted(simulate_dae(problem.eom, s.t_end, t_start=s.t_start, rtol=s.rtol, atol=s.atol,
                                   method=s.method, points=s.points, outputs=s.outputs, x0=s.x0, p=s.p,
                                   progress=progress, formulation=s.formulation, reactions=s.reactions,
                                   compiled=compiled, max_steps=s.max_steps, **kw), note)

    def describe(self, r):
        f = r.metadata.get("formulation")
        m = (r.metadata.get("options") or {}).get("method")
        plugin = "casadi:idas" if f == "ggl" else ("casadi:erk" if m == "erk" else "casadi:cvodes")
        return {"formulation": f, "integrator": plugin, "method": m}


class EventsBackend(Backend):
    name = "events"
    ignores = ("dt", "max_steps", "integrator_options", "formulation", "reactions")

    def run(self, problem, progress):
        from .events import simulate_with_contacts

        s = problem.settings
        kw = dict(s.extra)
        for key in ("dt", "max_steps", "integrator_options"):
            if getattr(s, key):
                kw[key] = getattr(s, key)
        if s.formulation not in ("auto",):
            kw["formulation"] = s.formulation
        if s.reactions:
            kw["reactions"] = True
        if s.compiled is not None:      # False: all in Python; otherwise free flight compiled when it can be
            kw["compiled"] = bool(s.compiled)
        return simulate_with_contacts(problem.eom, None, s.t_end, t_start=s.t_start, rtol=s.rtol, atol=s.atol,
                                      method=s.method, points=s.points, outputs=s.outputs, x0=s.x0, p=s.p,
                                      progress=progress, rest_speed=s.rest_speed, impact_order=s.impact_order,
                                      output_events=s.output_events, **kw)

    def describe(self, r):
        from ...impacts.stepper import SCIPY_METHODS

        m = r.metadata.get("method")
        python = f"scipy:{SCIPY_METHODS.get(m, m)}"
        stats = r.stats or {}
        compiled, in_python = stats.get("compiled_segments", 0), stats.get("python_segments", 0)
        # name what ran: free flight in the compiled loop, the rest (or all) in scipy's stepper
        parts = ([f"crk:{m}"] if compiled else []) + ([python] if in_python or not compiled else [])
        return {"formulation": "events", "integrator": "+".join(parts), "method": m}


class FixedStepBackend(Backend):
    name = "fixed-step"
    ignores = ("max_steps", "integrator_options", "rest_speed", "impact_order", "output_events")

    def run(self, problem, progress):
        from .fixed_step import simulate_symplectic

        s = problem.settings
        kw = dict(s.extra)
        ignored = {}
        if s.formulation != "auto":
            ignored["formulation"] = s.formulation
        for key in ("reactions", "compiled"):
            if getattr(s, key):
                ignored[key] = True
        return simulate_symplectic(problem.eom, s.t_end, method=s.method, dt=s.dt, t_start=s.t_start, p=s.p,
                                   x0=s.x0, points=s.points, outputs=s.outputs, progress=progress,
                                   step_eom=problem.step_eom, **ignored, **kw)

    def describe(self, r):
        m = r.metadata.get("method")
        return {"formulation": "canonical", "integrator": f"mechdsl:{m}", "method": m}


def ignored_settings(backend: Backend, settings) -> list[str]:
    """The settings a run was given that its back end does not use."""
    out = []
    for name in backend.ignores:
        v = getattr(settings, name)
        if v not in (None, False, {}, "auto"):
            out.append(f"{name} = {v!r}")
    return out


BACKENDS: dict[str, Backend] = {b.name: b for b in (OdeBackend(), DaeBackend(), EventsBackend(), FixedStepBackend())}
