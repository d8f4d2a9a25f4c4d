"""Index-1 ODE at acceleration level with Baumgarte stabilization ("baumgarte").

State (q, q').  The accelerations and multipliers come from the augmented system (see
:mod:`.system`) with the constraint rows

    G q'' = gamma - 2 alpha gdot - beta^2 g,

i.e. the constraint residual obeys g'' + 2 alpha g' + beta^2 g = 0 (critically damped for
alpha = beta = omega) instead of g'' = 0, whose solutions drift quadratically.

Choice of omega ("scaled to the problem").  The stabilization must act faster than the
mechanism moves, else it does not damp drift before it grows, but it adds a stiff mode of
rate omega that an Adams or explicit code must resolve.  We take

    omega = 10 * max(rho, 2 pi / T)

where rho is the spectral radius of the Jacobian of the unstabilized ODE at the start of
each segment (the fastest physical rate, which for a mechanism driven to high speed grows
during the run, hence per segment) and T the length of the run.  BDF (the default) is not
troubled by the added stiffness.  The user may give ``baumgarte = omega`` or
``baumgarte = (alpha, beta)``.
"""
from __future__ import annotations

import math

import numpy as np

from .segments import (GridIntegrators, NonFiniteError, PartialCall, SegmentInterrupted, StepError, Stepper,
                       call_integrator, chunk_span, integrator_options, ode_plugin, scaled_dae, state_names)


RATE_FACTOR = 10.0


def index1_dae(system) -> dict:
    """The index-1 ODE x = (q, q'), parameters (p, alpha, beta)."""
    import casadi as ca

    q, qd, t, p = system.symbols()
    Sym = type(q)
    alpha, beta = Sym.sym("alpha"), Sym.sym("beta")
    qdd, _ = system.fn["accel"](q, qd, t, p, alpha, beta)
    return {"x": ca.vertcat(q, qd), "t": t, "p": ca.vertcat(p, alpha, beta), "ode": ca.vertcat(qd, qdd)}


def automatic_rates(system, q, qd, t, span: float, factor: float = RATE_FACTOR) -> tuple[float, float]:
    rho = system.spectral_radius(q, qd, t)
    omega = factor * max(rho, 2 * math.pi / max(span, 1e-300))
    return omega, omega


class BaumgarteStepper(Stepper):
    """Integrates the Baumgarte-stabilized index-1 ODE with CVODES (BDF or Adams) or CasADi's
    explicit Runge-Kutta 5(4) (method "erk": no Jacobian, cheap steps for non-stiff mechanisms)."""

    rate_factor = RATE_FACTOR

    def __init__(self, system, opts, span: float):
        super().__init__(system=system, opts=opts, name="baumgarte")
        self.span = span
        plugin = ode_plugin(opts)
        iopts = integrator_options(opts, plugin)
        key = ("index1", plugin, tuple(sorted(iopts.items())), bool(opts.compiled))
        self.F = system.shared(key, lambda: GridIntegrators("index1", plugin, scaled_dae(index1_dae(system)),
                                                            iopts, {}, compiled=opts.compiled))
        self.F.stats = self.stats
        if self.F.note:
            self.notes.append(self.F.note)
        self.user_rates = _user_rates(opts.baumgarte)
        self.rates = (0.0, 0.0)

    def _rates(self):
        if self.user_rates is not None:
            return self.user_rates
        return automatic_rates(self.system, self.q, self.qd, self.t, self.span, self.rate_factor)

    def integrate(self, times, monitor=None):
        """States at ``times`` (increasing, after the current time): (n, K) arrays q, qd."""
        h, grid = chunk_span(self.t, times, monitor)
        K = len(np.atleast_1d(times))
        self.rates = self._rates()
        alpha, beta = self.rates
        p = np.concatenate([self.system.p, [alpha, beta, self.t, h]])
        F = self.F.get(grid, self.step_budget)
        try:
            r = call_integrator(F, x0=np.concatenate([self.q, self.qd]), p=p)
        except PartialCall as stop:     # Ctrl-C: the output times the call reached
            m, n = stop.columns, self.system.n
            x = np.asarray(stop.out["xf"], float).reshape(2 * n, K)[:, :m]
            raise SegmentInterrupted(np.atleast_1d(times)[:m], x[:n].T, x[n:].T) from None
        self._count(F)
        x = np.array(r["xf"], float).reshape(2 * self.system.n, K)
        if not np.all(np.isfinite(x)):
            j = int(np.argmax(~np.all(np.isfinite(x), axis=0)))       # first output with inf/nan
            which = int(np.argmax(~np.isfinite(x[:, j])))
            raise NonFiniteError(float(np.atleast_1d(times)[j]), state_names(self.system)[which])
        self.stats["baumgarte_alpha"] = alpha
        self.stats["baumgarte_beta"] = beta
        n = self.system.n
        return x[:n], x[n:]

    def advance(self, times, monitor=None):
        times = np.atleast_1d(np.asarray(times, float))
        Q, QD = self.integrate(times, monitor)
        self.t, self.q, self.qd = float(times[-1]), Q[:, -1].copy(), QD[:, -1].copy()
        return times, Q.T, QD.T


def _user_rates(value):
    if value is None:
        return None
    if isinstance(value, (int, float)):
        return float(value), float(value)
    a, b = value
    return float(a), float(b)
