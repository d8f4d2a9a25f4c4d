"""Index-1 ODE plus coordinate projection ("projection", the default).

At the end of every chunk (one integrator call through one or more output times), and
before any output time at which the drift has grown past half the bound, the
state is projected back onto the constraint manifolds:

    positions   q <- q + dq,  min (dq^T M dq)  s.t.  g(q + dq, t) = 0     (Newton, fresh G)
    velocities  q' <- argmin (q' - q'_0)^T M (q' - q'_0)  s.t.  G q' + g_t = 0

The mass metric M makes the projection independent of units and is the natural metric of
mechanics (the velocity projection removes the kinetic energy of the constraint-violating
motion and nothing else).  Between projections the ODE carries mild Baumgarte terms
(omega = max(rho, 2 pi / T), a tenth of the "baumgarte" formulation's), which slow the
drift without adding a fast mode: measured on the Cartesian pendulum with Adams at
1e-10, omega = 500 made the error 15 times larger than omega = 0 or 5, because a stiff
stabilization mode costs accuracy at every restart.  The largest drift seen before a
projection is recorded in the statistics ("drift_before_projection").
"""
from __future__ import annotations

import numpy as np

from .baumgarte import BaumgarteStepper
from .constrained_system import kkt_solve
from .segments import StepError


def project_positions(system, q, t, tol: float, max_iter: int = 20) -> np.ndarray:
    """Newton iterations of the M-orthogonal projection onto g(q, t) = 0 (at most max_iter;
    they stop when ||g|| no longer decreases).  A StepError when ||g|| is still above
    1000 tol (the drift bound) at the end: the projection failed, the segment is redone."""
    q = np.array(q, float)
    g = system.g(q, t)
    last = np.inf
    gn = float(np.max(np.abs(g))) if g.size else 0.0
    for _ in range(max_iter):
        if gn <= tol or gn >= last:
            break
        last = gn
        dq, _ = kkt_solve(system.M(q, t), system.G(q, t), np.zeros_like(q), -g)
        q = q + dq
        g = system.g(q, t)
        gn = float(np.max(np.abs(g))) if g.size else 0.0
    if g.size and not np.all(np.isfinite(g)):
        raise StepError("position projection diverged")
    if gn > 1e3 * tol:
        raise StepError(f"position projection did not converge (max |g| = {gn:.3g} after at most {max_iter} "
                        "Newton iterations)")
    return q


def project_velocities(system, q, qd, t) -> np.ndarray:
    M = system.M(q, t)
    G = system.G(q, t)
    gt = system.gdot(q, np.zeros_like(qd), t)
    v, _ = kkt_solve(M, G, M @ qd, -gt)
    return v


def project(system, q, qd, t, tol: float) -> tuple[np.ndarray, np.ndarray]:
    q = project_positions(system, q, t, tol)
    return q, project_velocities(system, q, qd, t)


class ProjectionStepper(BaumgarteStepper):
    """Projects at the end of every chunk, and earlier where the drift asks for it.

    Within a chunk of several output times (one integrator call) the states are checked in
    order; the chunk is cut after the last state whose drift is below PROJECT_AT * bound,
    and that state is projected (at least the first state is always taken, projected).
    So every recorded state has drift below the bound, and the chunk length adapts."""

    PROJECT_AT = 0.5
    rate_factor = 1.0       # mild Baumgarte terms: projection does the work (see docs)

    def __init__(self, system, opts, span: float):
        super().__init__(system, opts, span)
        self.name = "projection"
        self.stats["drift_before_projection"] = 0.0
        self.stats["velocity_drift_before_projection"] = 0.0
        self.stats["projections"] = 0

    def project(self, q, qd, t, tol):
        return project(self.system, q, qd, t, tol)

    def for_record(self, t, q, qd):
        """An output state between projections, projected when its drift is above the level
        that triggers a projection (for the record only: the integration goes on unchanged)."""
        d, v = self.system.drift(q, qd, t)
        limit = self.PROJECT_AT * self.opts.bound
        if d > limit or v > limit:
            try:
                return self.project(q, qd, t, 1e-3 * self.opts.bound)
            except StepError:       # recorded as integrated; the drift statistics show it
                return q, qd
        return q, qd

    def advance(self, times, monitor=None):
        """``monitor`` (bool per time, default all) marks the checking times: only there is the
        drift judged and the chunk cut, so output times in between change nothing."""
        times = np.atleast_1d(np.asarray(times, float))
        mon = np.ones(len(times), bool) if monitor is None else np.asarray(monitor, bool)
        Q, QD = self.integrate(times, monitor)
        limit = self.PROJECT_AT * self.opts.bound
        keep = len(times)
        D, V = self.system.drift_many(Q, QD, times)       # one mapped call for the whole segment
        last_ok = None
        for i in np.flatnonzero(mon):
            d, v = float(D[i]), float(V[i])
            self.stats["drift_before_projection"] = max(self.stats["drift_before_projection"], d)
            self.stats["velocity_drift_before_projection"] = max(self.stats["velocity_drift_before_projection"], v)
            if d > limit or v > limit:
                # cut after the last checking time with a small drift (at least the first one)
                keep = (last_ok if last_ok is not None else i) + 1
                break
            last_ok = i
        times, Q, QD = times[:keep], Q[:, :keep].copy(), QD[:, :keep].copy()
        q, qd = self.project(Q[:, -1], QD[:, -1], times[-1], 1e-3 * self.opts.bound)
        self.stats["projections"] += 1
        Q[:, -1], QD[:, -1] = q, qd
        self.t, self.q, self.qd = float(times[-1]), q, qd
        return times, Q.T, QD.T
