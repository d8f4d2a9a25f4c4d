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
from ...integrators import (METHODS, NO_JACOBIAN, Run, casadi_counts, casadi_options, run_casadi,
                            run_scipy)
from . import crk


class IntegratorPlugin(abc.ABC):
    """A family of ODE integrators behind one hook: ``advance`` integrates x' = ode(t, x, p)
    over the output grid and returns a :class:`Run`; ``counts`` maps its raw statistics to
    the schema's names; ``zoom``: a failure can be located by re-integrating on finer grids."""

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
        opts = casadi_options(method, rtol, atol, max_steps, fixed_steps, extra, hmin=hmin)
        return run_casadi(method, funcs["ode"], grid, x0, p, opts, progress, u=u)

    def counts(self, method, raw):
        return casadi_counts(method, raw)


class ScipyPlugin(IntegratorPlugin):
    def advance(self, method, funcs, grid, x0, p, *, rtol, atol, max_steps, fixed_steps, extra, progress, hmin,
                u=None):
        uv = np.zeros(0) if u is None else np.ravel(u)
        rhs = FastFunction(funcs["ode"]).bind(u=uv, p=p)
        jac = None if method in NO_JACOBIAN else FastFunction(funcs["ode_jacobian"]).bind(u=uv, p=p)
        return run_scipy(method, rhs, jac, grid, x0, rtol, atol, max_steps, progress, extra, hmin=hmin)


class CrkPlugin(IntegratorPlugin):
    """Integrator plug-in of the compiled stepping loop (falls back to scipy in Python)."""

    def advance(self, method, funcs, grid, x0, p, *, rtol, atol, max_steps, fixed_steps, extra, progress, hmin,
                u=None):
        if extra:
            raise RuntimeError(f"{method} takes no integrator options (got {', '.join(sorted(extra))})")
        ode = funcs["ode"]
        fn, _ = crk.library(ode, tag=getattr(getattr(funcs, "eom", None), "name", "model"))
        if fn is None:
            rhs = FastFunction(ode).bind(u=np.zeros(0) if u is None else np.ravel(u), p=p)
            run = run_scipy(crk.scipy_name(method), rhs, None, grid, x0, rtol, atol, max_steps, progress, {},
                              hmin=hmin)
            run.stats = {"n_steps": run.stats.get("steps"), "n_rhs": run.stats.get("rhs_evals"),
                         "n_reject": None, "fallback": "scipy"}
            return run
        return crk.run_compiled(fn, method, grid, x0, p, u, rtol, atol, max_steps, hmin, progress)

    def counts(self, method, raw):
        return {"steps": raw.get("n_steps"), "rhs_evals": raw.get("n_rhs"), "jac_evals": 0,
                "rejected_steps": raw.get("n_reject")}


PLUGINS: dict[str, IntegratorPlugin] = {"casadi": CasadiPlugin(), "scipy": ScipyPlugin(), "crk": CrkPlugin()}



def plugin(method: str) -> IntegratorPlugin:
    """The plug-in that runs ``method`` (a name of METHODS)."""
    kind = METHODS[method][0]
    return PLUGINS[kind]
