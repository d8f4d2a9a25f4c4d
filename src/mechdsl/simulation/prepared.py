"""A problem with what its run builds, built once: ``prepare(problem) -> Prepared``.

    prep = prepare(problem)          the back end's setup: Functions, method (auto resolved at the
                                     problem's start), integrator options, output grid
    solve(prep)                      the same numbers as solve(problem)
    solve(prep.at(p=pv, x0=xs))      other parameters and start values, nothing built again
    prep.integrator()                the CasADi integrator a run integrates with (sweeps map it)
    prep.interval_function(funcs)    one interval of that integrator as (t0, x0, u, p) -> xf
                                     (Model.integrator: multiple shooting)
    prep.trajectory(times, integrals)  the run as one differentiable Function (x0, p) -> the
                                     recorded signals (trajectory.py): sensitivities, fits

Every run goes through it: ``solve(problem)`` prepares inside the timed run, sweeps prepare
once per model and solve each run ``at`` its values (the vectorized scheduler maps
``integrator()``), ``--estimate-error`` prepares the tighter problem, ``mech bench`` runs
through ``solve``.  The method of ``auto`` is chosen once, at ``prepare``, from the problem's
start: a run ``at`` other values keeps it (a direct run of those values might choose another).
The Functions a problem's runs integrate are those ``Model.casadi`` returns
(``functions.problem_functions``: a constrained model's index-1 ODE with the multipliers
solved, mechdsl.dae.functions).
"""
from __future__ import annotations

import dataclasses

import casadi as ca

from .. import integrators as I
from ..diagnostics import UsageError
from ..eom import parameter_vector
from ..eom.start import start_vector
from ..model.records import record
from .backends import backend
from .backends.ode import setup_environment
from .choose import default_inputs, fixed_step_count, min_step
from .problem import Problem
from .registry import METHODS, spec
from .trajectory import cached_trajectory


@record
class Prepared:
    problem: Problem
    setup: object = None               # the back end's (OdeSetup for ODE problems; None: nothing kept)
    environment: object = dataclasses.field(default=None, compare=False)    # what the setup was built with (unchanged)

    @property
    def method(self) -> str:
        """The method runs of this preparation use (auto resolved, ODE problems)."""
        m = getattr(self.setup, "method", None)
        return m if m is not None else self.problem.settings.method

    def at(self, p=None, x0=None) -> "Prepared":
        """The same preparation for other parameter values ``p`` (vector or {name: value}) and
        start values ``x0`` (as ``simulate`` takes them); None keeps the problem's."""
        s = self.problem.settings
        s = s.replace(p=s.p if p is None else p, x0=s.x0 if x0 is None else x0)
        pv = parameter_vector(self.problem.eom, s.p)
        problem = dataclasses.replace(self.problem, settings=s,
                                      parameters=tuple((n, float(v)) for n, v in zip(self.problem.eom.params, pv)))
        return Prepared(problem, self.setup, self.environment)

    def integrator(self):
        """The casadi.integrator over the output grid that runs of this preparation use."""
        if self.setup is None or not hasattr(self.setup, "integrator"):
            raise UsageError(f"a {self.problem.kind} problem has no integrator Function over its grid")
        return self.setup.integrator()

    def interval_function(self, funcs, steps: int | None = None):
        """This preparation's integrator over one interval of length t_end - t_start, as a
        Function ``(t0, x0, u, p) -> xf`` of the Functions ``funcs`` (an SX ``ode``, parameters
        fixed, ...): the method and options of the runs, the inputs u held constant.  steps: fixed
        steps a call of "rk" / "collocation" (default: from rtol at the start values)."""
        setup = self.setup
        m = spec(self.method)
        if m.family != "casadi":
            casadi_methods = [k for k, v in METHODS.items() if v.family == "casadi"]
            raise UsageError(f"method '{self.method}' has no CasADi integrator plug-in; choose one of "
                             f"{', '.join(casadi_methods)}")
        s, eom = self.problem.settings, self.problem.eom
        span = s.t_end - s.t_start
        if m.fixed_step and steps is None:
            pv = parameter_vector(eom, s.p)
            steps, _ = fixed_step_count(self.method, setup.funcs, start_vector(eom, s.x0, pv), pv, 0.0, span,
                                        s.rtol, None, u=default_inputs(eom, setup.drive.vector(s.t_start)))
        opts = setup.options(fixed_steps=steps, hmin=min_step(0.0, span))
        ode = funcs["ode"]
        nu = ode.size1_in(2)
        t0, x0 = ca.MX.sym("t0"), ca.MX.sym("x0", ode.size1_in(1))
        u, p = ca.MX.sym("u", nu), ca.MX.sym("p", ode.size1_in(3))
        if ode.is_a("SXFunction") and not ca.depends_on(ode.call(ode.sx_in())[0], ode.sx_in(0)):
            shifted, args = ode, ca.vertcat(u, p)               # autonomous: t0 changes nothing
        else:                                                  # the interval starts at t0: ode(t0 + s, ...)
            ts, xs, us, ps = (ca.MX.sym(nm, ode.sparsity_in(i) if i != 2 else ca.Sparsity.dense(nu + 1, 1))
                              for i, nm in enumerate(("t", "x", "u", "p")))
            shifted = ca.Function("ode", [ts, xs, us, ps], [ode(ts + us[nu], xs, us[:nu], ps)],
                                  ["t", "x", "u", "p"], ["xdot"])
            args = ca.vertcat(u, t0, p)
        integ = I.make_integrator("integrator", m.plugin, I.dae_function(shifted), 0.0, span, opts)
        xf = integ(x0=x0, p=args)["xf"]
        return ca.Function("integrator", [t0, x0, u, p], [xf], ["t0", "x0", "u", "p"], ["xf"])


    def trajectory(self, times=None, integrals=()):
        """The run as one differentiable CasADi Function of the start and the parameters, with
        what it records (coordinates, speeds, outputs, energies) on its output grid or on
        ``times``, and the running integrals of the signals named in ``integrals``
        (simulation.trajectory.Trajectory: its forward and adjoint derivatives are CasADi's
        sensitivities of this preparation's integrator).  ODE and constrained problems."""
        if self.problem.kind not in ("ode", "dae"):
            raise UsageError(f"a {self.problem.kind} problem has no differentiable trajectory Function "
                             f"({'contacts make the motion jump at impacts' if self.problem.kind == 'hybrid' else 'the fixed-step canonical methods are not CasADi integrators'})")
        return cached_trajectory(self.problem, self.setup, times, tuple(integrals))


def prepare(problem: Problem) -> Prepared:
    """Build what runs of ``problem`` need once (see the module docstring)."""
    return Prepared(problem, backend(problem.backend).prepare(problem), _environment(problem))


def unchanged(prepared: Prepared) -> bool:
    """Whether what ``prepared``'s setup was built from still holds (an ODE setup: the compiler,
    the compile threshold, the caches of its Functions: backends/ode.setup_environment); a kept
    preparation that fails this is prepared again."""
    return prepared.environment == _environment(prepared.problem)


def _environment(problem: Problem):
    return setup_environment() if problem.backend == "ode" else None
