"""Augmented Lagrangian formulation with mass-orthogonal projections ("augmented").

Crosses isolated singular configurations, where the constraint Jacobian G loses rank (the
N-four-bar of IFToMM A02 with all its cranks horizontal), which the other formulations
detect and stop at.  It is the formulation of Bayo & Ledesma (Nonlinear Dynamics 9, 1996):
an ODE in (q, q') whose accelerations come from the augmented Lagrangian iteration, and
mass-orthogonal projections of positions and velocities, also by augmented Lagrangian
iterations.  None of them needs a full-rank G: the leading matrix

    W = M + G^T A G,         A = rho diag(s)^2     (s: the frozen row scaling of G)

stays positive definite whatever the rank of G (rho = PENALTY: the penalty relative to the
equilibrated mass matrix, so W's condition number is ~rho, independent of units).

Accelerations (a fixed number of iterations, unrolled in SX; W factored once, by a
Cholesky factorization in a band-reducing order, which the SX zeros make sparse):

    a_0 = 0, lambda_0 = 0
    a_(k+1) = a_k + W^-1 (bias - M a_k - G^T (lambda_k + A (G a_k - c)))
    lambda_(k+1) = lambda_k + A (G a_(k+1) - c),         c = gamma - 2 alpha gdot - beta^2 g

Each iteration divides the error of a mode of G with scaled singular value sigma by
1 + rho sigma^2 (10^6 for sigma = 0.1); the fixed point is the index-1 acceleration
M a = bias - G^T lambda, G a = c.  Near a singular configuration (sigma < rho^-1/2) the
iteration leaves the near-singular mode regularized instead of dividing by sigma: the
acceleration stays bounded, and its error there is M-orthogonal to the tangent of the
motion's branch (both the exact and the regularized constraint forces are), so it does
not change the motion along the branch; the velocity projection removes it once G is
well conditioned again.

Projections (after every integrator call, and where the drift reaches half the bound, as
in the "projection" formulation): positions q <- argmin (q - q0)^T M (q - q0) subject to
g(q) = 0 by Gauss-Newton steps on the augmented Lagrangian, velocities likewise for
G q' + g_t = 0; both converge to the M-orthogonal projection where G has full rank and
stay bounded where it does not.  The integrator is CasADi's erk (or CVODES), so the
tolerances mean what they mean for the other ODE formulations.

The driver does not stop at a singular configuration for this formulation
(``crosses_singular``); each passage (a local minimum of sigma_min/sigma_max of the scaled
G below SINGULAR_EVENT) is reported as an event of kind "singular" with the time
estimated from the two sides of the minimum.
"""
from __future__ import annotations

import math

import numpy as np

from .baumgarte import _user_rates
from .projection import ProjectionStepper
from .stepper import GridIntegrators, Stepper, StepError, integrator_options, ode_plugin, scaled_dae
from .system import _backward, _cholesky, _forward

PENALTY = 1e8          # rho: penalty relative to the equilibrated mass matrix (cond(W) ~ rho)
ITERATIONS = 4         # augmented Lagrangian iterations of the accelerations
PROJECTION_ITERATIONS = 30
SINGULAR_EVENT = 1e-2  # a local minimum of the singular-value ratio below this is reported


def band_order(system) -> list[int]:
    """A band-reducing order of the coordinates for the Cholesky factor of W (reverse
    Cuthill-McKee on the structure of M + G^T G; declaration order breaks ties)."""
    import casadi as ca
    from scipy.sparse import csr_matrix
    from scipy.sparse.csgraph import reverse_cuthill_mckee

    M, G = system.sym["M"], system.sym["G"]
    S = ca.DM(M.sparsity(), 1) + ca.mtimes(ca.DM(G.sparsity(), 1).T, ca.DM(G.sparsity(), 1))
    pattern = csr_matrix(np.array(S, float) != 0)
    return [int(i) for i in reverse_cuthill_mckee(pattern, symmetric_mode=True)]


def augmented_ode(system, row_scale: np.ndarray, rho: float = PENALTY, iterations: int = ITERATIONS) -> dict:
    """The ODE x = (q, q'), parameters (p, alpha, beta), accelerations by the augmented
    Lagrangian iteration (module docstring); the row scaling is a constant of the ODE."""
    import casadi as ca

    s = system.sym
    q, qd, t, p, M, G = s["q"], s["qd"], s["t"], s["p"], s["M"], s["G"]
    alpha, beta = s["alpha"], s["beta"]
    c = s["gamma"] - 2 * alpha * s["gdot"] - beta**2 * s["g"]
    A = ca.DM(rho * np.asarray(row_scale, float) ** 2)
    W = M + ca.mtimes([G.T, ca.diag(A), G])
    order = band_order(system)
    Wp = W[order, order]
    L = _cholesky([[Wp[i, j] for j in range(len(order))] for i in range(len(order))])
    inverse = np.argsort(order)

    def solve(r):
        rp = r[order]
        y = _backward(L, _forward(L, [rp[i] for i in range(len(order))]))
        return ca.vertcat(*y)[list(inverse)]

    a = ca.SX.zeros(system.n)
    lam = ca.SX.zeros(system.m)
    for _ in range(iterations):
        a = a + solve(s["bias"] - ca.mtimes(M, a) - ca.mtimes(G.T, lam + A * (ca.mtimes(G, a) - c)))
        lam = lam + A * (ca.mtimes(G, a) - c)
    return {"x": ca.vertcat(q, qd), "t": t, "p": ca.vertcat(p, alpha, beta), "ode": ca.vertcat(qd, a)}


def _penalty_solve(W_factor, r):
    from scipy.linalg import cho_solve

    return cho_solve(W_factor, r)


def _leading(system, q, t, A):
    from scipy.linalg import cho_factor

    M = system.M(q, t)
    G = system.G(q, t)
    return M, G, cho_factor(M + G.T @ (A[:, None] * G))


def project_positions(system, q0, t, A, tol: float) -> np.ndarray:
    """argmin (q - q0)^T M (q - q0) subject to g(q, t) = 0, by Gauss-Newton steps on the
    augmented Lagrangian 1/2 (q - q0)^T M (q - q0) + mu^T g + 1/2 g^T A g."""
    q0 = np.array(q0, float)
    q, mu = q0.copy(), np.zeros(system.m)
    for _ in range(PROJECTION_ITERATIONS):
        g = system.g(q, t)
        if not np.all(np.isfinite(g)):
            raise StepError("position projection diverged")
        M, G, F = _leading(system, q, t, A)
        step = _penalty_solve(F, -(M @ (q - q0)) - G.T @ (mu + A * g))
        q = q + step
        g = system.g(q, t)
        mu = mu + A * g
        if np.max(np.abs(g), initial=0.0) <= tol and np.max(np.abs(step)) <= 1e-3 * tol * (1 + np.max(np.abs(q))):
            break
    if not np.all(np.isfinite(q)):
        raise StepError("position projection diverged")
    return q


def project_velocities(system, q, qd0, t, A, tol: float) -> np.ndarray:
    """argmin (v - qd0)^T M (v - qd0) subject to G v + g_t = 0 (augmented Lagrangian; the
    leading matrix is factored once)."""
    M, G, F = _leading(system, q, t, A)
    gt = system.gdot(q, np.zeros_like(qd0), t)
    v, mu = np.array(qd0, float), np.zeros(system.m)
    for _ in range(PROJECTION_ITERATIONS):
        dv = _penalty_solve(F, -(M @ (v - qd0)) - G.T @ (mu + A * (G @ v + gt)))
        v = v + dv
        r = G @ v + gt
        mu = mu + A * r
        if np.max(np.abs(r), initial=0.0) <= tol and np.max(np.abs(dv)) <= tol * (1 + np.max(np.abs(v))):
            break
    return v


class AugmentedStepper(ProjectionStepper):
    """The augmented Lagrangian ODE, integrated like the projection formulation's index-1
    ODE (same chunks, same projection rule), with the penalty projections of this module."""

    crosses_singular = True       # the driver does not stop at a loss of rank

    def __init__(self, system, opts, span: float):
        Stepper.__init__(self, system=system, opts=opts, name="augmented")
        self.span = span
        if system.row_scale is None:
            raise ValueError("AugmentedStepper needs the frozen row scaling (system.fix_row_scale)")
        self.A = PENALTY * np.asarray(system.row_scale, float) ** 2
        plugin = ode_plugin(opts)
        iopts = integrator_options(opts, plugin)
        key = ("augmented", plugin, tuple(sorted(iopts.items())), bool(opts.compiled),
               np.asarray(system.row_scale, float).tobytes(), PENALTY, ITERATIONS)
        self.F = system.shared(key, lambda: GridIntegrators(
            "augmented", plugin, scaled_dae(augmented_ode(system, system.row_scale)), iopts, {},
            compiled=opts.compiled))
        self.F.stats = self.stats
        if self.F.note:
            self.notes.append(self.F.note)
        self.user_rates = _user_rates(opts.baumgarte)
        self.rates = (0.0, 0.0)
        self.stats.update(drift_before_projection=0.0, velocity_drift_before_projection=0.0, projections=0)
        self.events: list[dict] = []
        self._ratios: list[tuple[float, float]] = []     # (t, ratio) of the last three accepted states

    def _rates(self):
        """Mild Baumgarte terms, omega = 2 pi / T: the projections keep the drift; a fast
        stabilization mode would only limit the explicit integrator's steps."""
        if self.user_rates is not None:
            return self.user_rates
        omega = 2 * math.pi / max(self.span, 1e-300)
        return omega, omega

    def project(self, q, qd, t, tol):
        q = project_positions(self.system, q, t, self.A, tol)
        return q, project_velocities(self.system, q, qd, t, self.A, tol)

    def reset(self, t, q, qd) -> None:
        super().reset(t, q, qd)
        if getattr(self, "_ratios", None) and self._ratios[-1][0] > t:
            self._ratios = [r for r in self._ratios if r[0] <= t]

    def advance(self, times):
        T, Q, QD = super().advance(times)
        self._watch(T, Q)
        return T, Q, QD

    def _watch(self, T, Q) -> None:
        """Report each passage through a singular configuration: a local minimum of the
        scaled singular-value ratio below SINGULAR_EVENT, its time from the intersection of
        the lines through the two states on each side."""
        from .dof import singular_ratio

        for t, q in zip(T, Q):
            self._ratios.append((float(t), singular_ratio(self.system.scaled_G(q, t), self.system.m)))
            if len(self._ratios) < 4:
                continue
            (t0, r0), (t1, r1), (t2, r2), (t3, r3) = self._ratios[-4:]
            self._ratios = self._ratios[-4:]
            if not (r1 < r0 and r2 < r3 and min(r1, r2) < SINGULAR_EVENT):
                continue
            left = (r1 - r0) / (t1 - t0)        # < 0
            right = (r3 - r2) / (t3 - t2)       # > 0
            # the two lines r1 + left (t - t1) and r2 + right (t - t2) meet at the passage
            tc = (r2 - right * t2 - r1 + left * t1) / (left - right)
            tc = min(max(tc, t1), t2)
            if any(abs(e["time"] - tc) <= (t2 - t1) for e in self.events):
                continue
            self.events.append({"time": tc, "kind": "singular", "contact": "-",
                                "detail": f"crossed a singular configuration (sigma_min/sigma_max of the scaled "
                                          f"constraint Jacobian {min(r1, r2):.2e} at the nearest checked state)"})
