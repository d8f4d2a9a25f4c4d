"""Integrator plug-ins of the ODE back end: one family of integrators behind one hook.

    advance(method, funcs, grid, x0, p, ...) -> integrators.Run    integrate over the output grid
    counts(method, raw) -> dict                                     raw statistics -> the schema's names
    zoom                                                            a failure can be located by
                                                                    re-integrating on finer grids

``CasadiPlugin`` runs CasADi's integrator plug-ins (cvodes, idas, erk, rosenbrock, rk,
collocation), ``ScipyPlugin`` scipy's OdeSolver classes, ``crk.CrkPlugin`` the compiled
stepping loop; ``plugin(method)`` picks the one of a method.  The runners themselves
(``run_casadi``, ``run_scipy``, ``make_integrator``) live in ``mechdsl.integrators``, below
this layer, so the DAE formulations use them too.
"""
from __future__ import annotations

import abc

import numpy as np

from ...eom.codegen import FastFunction
from ...integrators import Run, casadi_counts, casadi_options, run_casadi, run_scipy
from ..registry import spec
from . import crk, payback


class IntegratorPlugin(abc.ABC):
    """A family of ODE integrators behind one hook: ``advance`` integrates x' = ode(t, x, u, p)
    over the output grid and returns a :class:`Run`; ``counts`` maps its raw statistics to
    the schema's names; ``zoom``: a failure can be located by re-integrating on finer grids.

    How to add an integrator (docs/internals/simulation.md has the whole list):

    1. A ``MethodSpec`` in simulation/registry.py: name, family, plug-in name, options, order,
       needs_jacobian, fixed_step, kinds (and ``dae`` / ``events`` when the DAE or contact back
       end can run it under another name).
    2. If no family fits, a subclass here: ``advance`` never raises for a numerical failure
       (the Run keeps the rows reached, ``error`` and, when known, ``fail_time``/``fail_state``);
       ``counts`` maps its raw statistics to steps, rhs_evals, jac_evals, rejected_steps.
    3. Register the subclass in ``PLUGINS`` under the family name.
    4. A test that runs the method on a model with a closed form (tests/test_sim_methods.py).
    """

    zoom = False

    @abc.abstractmethod
    def advance(self, method, funcs, grid, x0, p, *, rtol, atol, max_steps, fixed_steps, extra, progress,
                hmin, u=None) -> Run:
        """Integrate over the output grid; the Run keeps what was reached and the error."""

    def counts(self, method: str, raw: dict) -> dict:
        return dict(raw)


class CasadiPlugin(IntegratorPlugin):
    zoom = True

    def advance(self, method, funcs, grid, x0, p, *, rtol, atol, max_steps, fixed_steps, extra, progress, hmin,
                u=None):
        m = spec(method)
        opts = casadi_options(m.plugin, m.options, rtol, atol, max_steps, fixed_steps, extra, hmin=hmin)
        return run_casadi(m.plugin, funcs["ode"], grid, x0, p, opts, progress, u=u)

    def counts(self, method, raw):
        return casadi_counts(spec(method).plugin, raw)


class ScipyPlugin(IntegratorPlugin):
    def advance(self, method, funcs, grid, x0, p, *, rtol, atol, max_steps, fixed_steps, extra, progress, hmin,
                u=None):
        uv = np.zeros(0) if u is None else np.ravel(u)
        rhs = FastFunction(funcs["ode"]).bind(u=uv, p=p)
        m = spec(method)
        jac = FastFunction(funcs["ode_jacobian"]).bind(u=uv, p=p) if m.needs_jacobian else None
        return run_scipy(m.plugin, rhs, jac, grid, x0, rtol, atol, max_steps, progress, extra, hmin=hmin)


class CrkPlugin(IntegratorPlugin):
    """Integrator plug-in of the compiled stepping loop (falls back to scipy in Python)."""

    def advance(self, method, funcs, grid, x0, p, *, rtol, atol, max_steps, fixed_steps, extra, progress, hmin,
                u=None):
        if extra:
            raise RuntimeError(f"{method} takes no integrator options (got {', '.join(sorted(extra))})")
        ode = crk.loop_ode(funcs)
        tag = getattr(getattr(funcs, "eom", None), "name", "model")
        loop = getattr(funcs, "loop", None)      # the setup's (with its recorder compiled beside the ode)
        if loop is None:
            loop, _ = crk.library(ode, tag=tag, engine=getattr(funcs, "engine", None))
        pay = None
        if loop is not None and loop.engine == "interpreted":     # too large to compile up front, or not yet:
            rented = getattr(loop, "rented", False)
            pay = payback.Payback(ode, tag, rented, again=getattr(funcs, "rented_runs", 0) > 0,   # (payback.py)
                                  extra=getattr(loop, "rent_extra", None))
            if rented and isinstance(funcs, crk.LoopFunctions):
                funcs.rented_runs = getattr(funcs, "rented_runs", 0) + 1
            loop = pay.compiled_now() or loop
        if loop is None:
            rhs = FastFunction(funcs["ode"]).bind(u=np.zeros(0) if u is None else np.ravel(u), p=p)
            run = run_scipy(spec(crk.scipy_name(method)).plugin, rhs, None, grid, x0, rtol, atol, max_steps,
                            progress, {}, hmin=hmin)
            run.stats = {"n_steps": run.stats.get("steps"), "n_rhs": run.stats.get("rhs_evals"),
                         "n_reject": None, "fallback": "scipy"}
            return run
        return crk.run_compiled(loop, method, grid, x0, p, u, rtol, atol, max_steps, hmin, progress,
                                drive=getattr(funcs, "drive", None), payback=pay)

    def counts(self, method, raw):
        return crk.counts(raw)


PLUGINS: dict[str, IntegratorPlugin] = {"casadi": CasadiPlugin(), "scipy": ScipyPlugin(), "crk": CrkPlugin()}


def plugin(method: str) -> IntegratorPlugin:
    """The plug-in that runs ``method`` (an ODE method of the registry)."""
    return PLUGINS[spec(method).family]
