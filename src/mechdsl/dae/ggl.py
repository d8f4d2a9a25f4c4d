"""Stabilized index-2 formulation of Gear, Gupta and Leimkuhler ("ggl"), solved by IDAS.

    q' = v - G^T mu
    v' = a
    0  = M a - bias(q, v, t) + G^T lambda
    0  = G v + g_t                        (velocity constraints)
    0  = g(q, t)                          (position constraints)

Differential variables x = (q, v), algebraic z = (a, lambda, mu).  The extra multiplier mu
keeps the position constraints satisfied without differentiating them; on the exact
solution mu = 0.  The system is of Hessenberg index 2, so IDAS runs with the algebraic
variables excluded from the error test (suppress_algebraic) and with consistent initial
values computed here (the IDAS initial-value routine assumes index 1).  Before IDAS is
called the index is computed (:func:`.index.dae_index`); anything above 2 is refused.
"""
from __future__ import annotations

import numpy as np

from .index import check_for_idas
from .segments import (GridIntegrators, PartialCall, SegmentInterrupted, StepError, Stepper, call_integrator, chunk_span,
                       integrator_options, scaled_dae)


def ggl_dae(system) -> dict:
    import casadi as ca

    S = system.sym
    n, m = system.n, system.m
    v = ca.SX.sym("v", n)
    a = ca.SX.sym("a", n)
    lam = ca.SX.sym("lam", m)
    mu = ca.SX.sym("mu", m)
    sub = lambda e: ca.substitute(e, S["qd"], v)  # noqa: E731
    G = S["G"]
    return {"x": ca.vertcat(S["q"], v), "z": ca.vertcat(a, lam, mu), "t": S["t"], "p": S["p"],
            "ode": ca.vertcat(v - ca.mtimes(G.T, mu), a),
            "alg": ca.vertcat(ca.mtimes(S["M"], a) - sub(S["bias"]) + ca.mtimes(G.T, lam),
                              sub(S["gdot"]), S["g"])}


def raw_index3_dae(system) -> dict:
    """The plain index-3 form (q' = v, v' = a, M a = bias - G^T lambda, g = 0).

    Only for demonstrating the index guard; never integrated by the package."""
    import casadi as ca

    S = system.sym
    n, m = system.n, system.m
    v = ca.SX.sym("v", n)
    a = ca.SX.sym("a", n)
    lam = ca.SX.sym("lam", m)
    sub = lambda e: ca.substitute(e, S["qd"], v)  # noqa: E731
    return {"x": ca.vertcat(S["q"], v), "z": ca.vertcat(a, lam), "t": S["t"], "p": S["p"],
            "ode": ca.vertcat(v, a),
            "alg": ca.vertcat(ca.mtimes(S["M"], a) - sub(S["bias"]) + ca.mtimes(S["G"].T, lam), S["g"])}


def deviation_dae(dae: dict) -> dict:
    """Integrate the scaled deviation from the segment's linear start motion.

    CasADi's IDAS takes the initial x' from a construction-time option (zero by default),
    and the index-2 system rules out IDAS's own initial-value computation.  Writing

        x(s) = x0 + s xdot0 + w * e(s),     w_i = rtol |x0_i| + atol

    with xdot0 = dx/ds at the segment start makes e(0) = 0, e'(0) = 0 consistent for every
    segment.  With abstol 1 and reltol 0 on e, IDAS's local error test
    ||error in x_i / w_i|| <= 1 is its usual test with weights frozen at the chunk start.  x0, xdot0 and w are
    parameters."""
    import casadi as ca

    x = dae["x"]
    nx = x.numel()
    e = ca.SX.sym("e", nx)
    x0 = ca.SX.sym("x0", nx)
    xd0 = ca.SX.sym("xd0", nx)
    w = ca.SX.sym("w", nx)
    s = dae["t"]
    xs = x0 + s * xd0 + w * e
    out = {"x": e, "t": s, "p": ca.vertcat(dae["p"], x0, xd0, w),
           "ode": (ca.substitute(dae["ode"], x, xs) - xd0) / w}
    if "z" in dae:
        out["z"] = dae["z"]
        out["alg"] = ca.substitute(dae["alg"], x, xs)
    return out


STEP0 = 1e-6          # first step, as a fraction of the chunk
NEWTON_COEFF = 0.01   # IDAS Newton convergence coefficient (default 0.33): the constraints
                      # are algebraic equations here, so their residual (the drift) is as
                      # small as the Newton iteration makes it


class GGLStepper(Stepper):
    def __init__(self, system, opts, t0, q0, qd0):
        super().__init__(system=system, opts=opts, name="ggl")
        dae = deviation_dae(scaled_dae(ggl_dae(system)))
        io = integrator_options(opts, "idas")
        nz = system.n + 2 * system.m
        io.update({"suppress_algebraic": True, "calc_ic": False, "abstol": 1.0, "reltol": 0.0, "step0": STEP0,
                   "nonlin_conv_coeff": NEWTON_COEFF,
                   "abstolv": [1.0] * (2 * system.n + nz), "linear_solver": "csparse"})
        self.index = check_for_idas(dae, np.zeros(2 * system.n), self._z0(t0, q0, qd0),
                                    self._p(t0, 1.0, q0, qd0), 0.0, io, allowed_index=2,
                                    what="the GGL system", force=opts.force_index)
        self.F = GridIntegrators("ggl", "idas", dae, io, self.stats)
        self.stats["dae_index"] = self.index

    def _z0(self, t, q, qd):
        a0, lam0 = self.system.accel(q, qd, t)
        return np.concatenate([a0, lam0, np.zeros(self.system.m)])

    def _p(self, t, h, q, qd):
        a0, _ = self.system.accel(q, qd, t)
        x0 = np.concatenate([q, qd])
        xd0 = h * np.concatenate([qd, a0])
        w = self.opts.rtol * np.abs(x0) + self.opts.atol
        return np.concatenate([self.system.p, [t, h], x0, xd0, w])

    def advance(self, times, monitor=None):
        times = np.atleast_1d(np.asarray(times, float))
        h, grid = chunk_span(self.t, times, monitor)
        K = len(times)
        n = self.system.n
        p = self._p(self.t, h, self.q, self.qd)
        F = self.F.get(grid, self.step_budget)
        x0, xd0, w = p[-6 * n:-4 * n], p[-4 * n:-2 * n], p[-2 * n:]
        s = np.linspace(0.0, 1.0, K + 1)[1:] if isinstance(grid, int) else np.array(grid)
        try:
            r = call_integrator(F, x0=np.zeros(2 * n), z0=self._z0(self.t, self.q, self.qd), p=p)
        except PartialCall as stop:     # Ctrl-C: the output times the call reached
            m = stop.columns
            e = np.asarray(stop.out["xf"], float).reshape(2 * n, K)[:, :m]
            X = x0[:, None] + xd0[:, None] * s[None, :m] + w[:, None] * e
            raise SegmentInterrupted(times[:m], X[:n].T, X[n:].T) from None
        self._count(F)
        e = np.array(r["xf"], float).reshape(2 * n, K)
        X = x0[:, None] + xd0[:, None] * s[None, :] + w[:, None] * e
        if not np.all(np.isfinite(X)):
            raise StepError("the state became non-finite")
        self.t, self.q, self.qd = float(times[-1]), X[:n, -1].copy(), X[n:, -1].copy()
        return times, X[:n].T, X[n:].T
