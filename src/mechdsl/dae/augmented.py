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
1 + rho sigma^2 (10^6 for sigma = 0.1; after the 4 iterations 1e-8 at sigma = 1e-3); the
fixed point is the index-1 acceleration M a = bias - G^T lambda, G a = c.  Near a singular
configuration (sigma below ~1e-4 = rho^-1/2) the iteration leaves the near-singular mode
regularized instead of dividing by sigma: the
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
(``crosses_singular``); each passage (a minimum of sigma_min/sigma_max of the scaled G at
the checked states whose two sides, extrapolated linearly, meet below SINGULAR_EVENT) is
reported as an event of kind "singular" at the time where they meet.  The checks must
resolve the passage (five checked states around it: 2001 points over A02's 20 s do; the
61 checks of a 2-point run do not), else it is crossed without an event.
"""
from __future__ import annotations

import math

import numpy as np

from ..diagnostics import Diagnostic, MechError
from .baumgarte import _user_rates
from .dof import short_list
from .projection import ProjectionStepper
from .segments import GridIntegrators, StepError, Stepper, integrator_options, ode_plugin, scaled_dae


PENALTY = 1e8          # rho: penalty relative to the equilibrated mass matrix (cond(W) ~ rho)
ITERATIONS = 4         # augmented Lagrangian iterations of the accelerations
PROJECTION_ITERATIONS = 30
STALL = 3              # projections stop after this many iterations without halving the residual
SINGULAR_EVENT = 1e-2  # a minimum of the singular-value ratio extrapolated below this is reported ...
SINGULAR_NEAR = 0.2    # ... when the checked state nearest to it is below this


def band_order(system) -> tuple[list[int], list[int]]:
    """A band-reducing order of the coordinates (reverse Cuthill-McKee on the structure of
    M + G^T G) and, in that order, the envelope of W: first[i] = the first column of row i
    with a structural nonzero (the Cholesky factor has no fill outside the envelope)."""
    import casadi as ca
    from scipy.sparse import csr_matrix
    from scipy.sparse.csgraph import reverse_cuthill_mckee

    M, G = system.sym["M"], system.sym["G"]
    S = ca.DM(M.sparsity(), 1) + ca.mtimes(ca.DM(G.sparsity(), 1).T, ca.DM(G.sparsity(), 1))
    pattern = np.array(S, float) != 0
    pattern |= np.eye(system.n, dtype=bool)
    order = [int(i) for i in reverse_cuthill_mckee(csr_matrix(pattern), symmetric_mode=True)]
    P = pattern[np.ix_(order, order)]
    first = [int(np.argmax(P[i, :i + 1])) for i in range(system.n)]
    return order, first


def envelope_cholesky(A, first: list[int]) -> list[dict]:
    """Lower L with A = L L^T for A symmetric positive definite (SX), computed only inside
    the envelope (row i from column first[i]): L[i] is {column: SX}."""
    import casadi as ca

    n = len(first)
    L: list[dict] = [{} for _ in range(n)]
    for i in range(n):
        for j in range(first[i], i + 1):
            acc = A(i, j)
            for k in range(max(first[i], first[j]), j):
                acc = acc - L[i][k] * L[j][k]
            L[i][j] = ca.sqrt(acc) if i == j else acc / L[j][j]
    return L


def envelope_solve(L: list[dict], first: list[int], b: list) -> list:
    """x with L L^T x = b (forward then backward substitution inside the envelope)."""
    n = len(first)
    y = []
    for i in range(n):
        acc = b[i]
        for k in range(first[i], i):
            acc = acc - L[i][k] * y[k]
        y.append(acc / L[i][i])
    x = [None] * n
    for i in reversed(range(n)):
        acc = y[i]
        for k in range(i + 1, n):
            if first[k] <= i:
                acc = acc - L[k][i] * x[k]
        x[i] = acc / L[i][i]
    return x


def augmented_ode(system, row_scale: np.ndarray, rho: float = PENALTY, iterations: int = ITERATIONS) -> dict:
    """The ODE x = (q, q'), parameters (p, alpha, beta), accelerations by the augmented
    Lagrangian iteration (module docstring); the row scaling is a constant of the ODE."""
    import casadi as ca

    s = system.sym
    q, qd, t, p, M, G = s["q"], s["qd"], s["t"], s["p"], s["M"], s["G"]
    alpha, beta = s["alpha"], s["beta"]
    c = s["gamma"] - 2 * alpha * s["gdot"] - beta**2 * s["g"]
    A = ca.DM(rho * np.asarray(row_scale, float) ** 2)
    order, first = band_order(system)
    Wp = (M + ca.mtimes([G.T, ca.diag(A), G]))[order, order]
    L = envelope_cholesky(lambda i, j: Wp[i, j], first)
    inverse = [int(i) for i in np.argsort(order)]

    def solve(r):
        rp = r[order]
        return ca.vertcat(*envelope_solve(L, first, [rp[i] for i in range(system.n)]))[inverse]

    a = ca.SX.zeros(system.n)
    lam = ca.SX.zeros(system.m)
    for _ in range(iterations):
        a = a + solve(s["bias"] - ca.mtimes(M, a) - ca.mtimes(G.T, lam + A * (ca.mtimes(G, a) - c)))
        lam = lam + A * (ca.mtimes(G, a) - c)
    return {"x": ca.vertcat(q, qd), "t": t, "p": ca.vertcat(p, alpha, beta), "ode": ca.vertcat(qd, a)}


def shared_ode(system) -> dict:
    """augmented_ode for the system's frozen row scaling, built once per (EOM, active set,
    scaling) and kept with the system."""
    if system.row_scale is None:
        raise ValueError("the augmented formulation needs the frozen row scaling (system.fix_row_scale)")
    scale = np.asarray(system.row_scale, float)
    return system.shared(("augmented_ode", scale.tobytes(), PENALTY, ITERATIONS),
                         lambda: augmented_ode(system, scale))


def _penalty_solve(W_factor, r):
    from scipy.linalg import cho_solve

    return cho_solve(W_factor, r)


def _leading(system, q, t, A):
    from scipy.linalg import LinAlgError, cho_factor

    M = system.M(q, t)
    G = system.G(q, t)
    try:
        return M, G, cho_factor(M + G.T @ (A[:, None] * G))
    except (LinAlgError, ValueError):
        raise StepError("M + G^T A G is not positive definite here (a coordinate without inertia that no "
                        "constraint holds?)") from None


def project_positions(system, q0, t, A, tol: float) -> np.ndarray:
    """argmin (q - q0)^T M (q - q0) subject to g(q, t) = 0, by Gauss-Newton steps on the
    augmented Lagrangian 1/2 (q - q0)^T M (q - q0) + mu^T g + 1/2 g^T A g."""
    q0 = np.array(q0, float)
    q, mu = q0.copy(), np.zeros(system.m)
    last, stalled = np.inf, 0
    for _ in range(PROJECTION_ITERATIONS):
        g = system.g(q, t)
        if not np.all(np.isfinite(g)):
            raise StepError("position projection diverged")
        M, G, F = _leading(system, q, t, A)
        step = _penalty_solve(F, -(M @ (q - q0)) - G.T @ (mu + A * g))
        q = q + step
        g = system.g(q, t)
        mu = mu + A * g
        size = np.max(np.abs(g), initial=0.0)
        stalled = stalled + 1 if size > 0.5 * last else 0
        if size <= tol or stalled >= STALL:       # feasible, or no more progress (round-off)
            break
        last = min(last, size)
    if not np.all(np.isfinite(q)):
        raise StepError("position projection diverged")
    return q


def project_velocities(system, q, qd0, t, A, tol: float) -> np.ndarray:
    """argmin (v - qd0)^T M (v - qd0) subject to G v + g_t = 0 (augmented Lagrangian; the
    leading matrix is factored once)."""
    M, G, F = _leading(system, q, t, A)
    gt = system.gdot(q, np.zeros_like(qd0), t)
    v, mu = np.array(qd0, float), np.zeros(system.m)
    last, stalled = np.inf, 0
    for _ in range(PROJECTION_ITERATIONS):
        dv = _penalty_solve(F, -(M @ (v - qd0)) - G.T @ (mu + A * (G @ v + gt)))
        v = v + dv
        r = G @ v + gt
        mu = mu + A * r
        size = np.max(np.abs(r), initial=0.0)
        stalled = stalled + 1 if size > 0.5 * last else 0
        if size <= tol or stalled >= STALL:       # feasible, or no more progress (round-off)
            break
        last = min(last, size)
    return v


CODE_LEADING = "E840"


def check_leading(system, q, t, A) -> None:
    """E840 when M + G^T A G is singular at the start (coordinates without inertia that no
    constraint holds: the formulation would divide by zero where the KKT route does not)."""
    W = system.M(q, t) + system.G(q, t).T @ (A[:, None] * system.G(q, t))
    d = 1.0 / np.sqrt(np.maximum(np.abs(np.diag(W)), 1e-300))
    w, V = np.linalg.eigh(d[:, None] * W * d[None, :])
    if np.all(np.isfinite(w)) and w[0] > 1e-12 * max(w[-1], 1e-300):
        return
    v = np.abs(V[:, 0])
    names = [system.eom.coords[i] for i in range(system.n) if v[i] >= 0.3 * v.max()]
    raise MechError(Diagnostic(
        CODE_LEADING,
        "formulation \"augmented\" needs M + G^T A G positive definite, but it is singular at the start "
        f"along {short_list(names)}: coordinates without inertia that no constraint holds",
        help="use formulation = \"projection\" (its augmented system tolerates them), or give those "
             "coordinates inertia"))


class AugmentedStepper(ProjectionStepper):
    """The augmented Lagrangian ODE, integrated like the projection formulation's index-1
    ODE (same chunks, same projection rule), with the penalty projections of this module."""

    crosses_singular = True       # the driver does not stop at a loss of rank

    def __init__(self, system, opts, span: float, t0: float, q0):
        Stepper.__init__(self, system=system, opts=opts, name="augmented")
        self.span = span
        self.A = PENALTY * np.asarray(system.row_scale, float) ** 2
        check_leading(system, q0, t0, self.A)
        plugin = ode_plugin(opts)
        iopts = integrator_options(opts, plugin)
        key = ("augmented", plugin, tuple(sorted(iopts.items())), bool(opts.compiled),
               np.asarray(system.row_scale, float).tobytes(), PENALTY, ITERATIONS)
        self.F = system.shared(key, lambda: GridIntegrators(
            "augmented", plugin, scaled_dae(shared_ode(system)), iopts, {},
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

    def watch(self, t: float, ratio: float) -> None:
        """Called by the driver with sigma_min/sigma_max of the scaled G at every accepted
        state.  Reports each passage through a singular configuration, a strict minimum of
        the ratio below SINGULAR_EVENT in the middle of five states, as an event at the time
        where the line through the two states before it meets the line through the two
        after it (sigma_min falls and rises linearly through an isolated singularity)."""
        self._ratios = (self._ratios + [(float(t), float(ratio))])[-5:]
        if len(self._ratios) < 5:
            return
        (t0, r0), (t1, r1), (t2, r2), (t3, r3), (t4, r4) = self._ratios
        if not (r0 > r1 > r2 < r3 < r4 and r2 < SINGULAR_NEAR):
            return
        left, right = (r1 - r0) / (t1 - t0), (r4 - r3) / (t4 - t3)      # falling, rising
        tc = min(max((r3 - right * t3 - r1 + left * t1) / (left - right), t1), t3)
        low = r1 + left * (tc - t1)                                      # the lines' meeting value
        if low > SINGULAR_EVENT:
            return
        self.events.append({"time": tc, "kind": "singular", "contact": "-",
                            "detail": "crossed a singular configuration (sigma_min/sigma_max of the scaled "
                                      f"constraint Jacobian extrapolated to {max(low, 0.0):.1e}, {r2:.2e} at the "
                                      "nearest checked state)"})


def ode_eigenvalues(system, q, qd, t) -> np.ndarray:
    """Eigenvalues of the Jacobian of the augmented ODE without stabilization terms at (q, q'),
    by central differences in one mapped call (for the choice of method): 2 (2n) right-hand
    sides instead of the symbolic Jacobian of a large model."""
    import casadi as ca

    dae = shared_ode(system)
    f = ca.Function("augmented_ode", [dae["x"], dae["t"], dae["p"]], [dae["ode"]])
    x = np.concatenate([q, qd])
    N = x.size
    h = 1e-6 * np.maximum(1.0, np.abs(x))
    X = np.concatenate([x[:, None] + np.diag(h), x[:, None] - np.diag(h)], axis=1)
    P = np.repeat(np.concatenate([system.p, [0.0, 0.0]])[:, None], 2 * N, axis=1)
    F = np.array(f.map(2 * N)(X, np.full((1, 2 * N), float(t)), P), float)
    with np.errstate(all="ignore"):      # a singular W gives NaN here; E840 reports it next
        J = (F[:, :N] - F[:, N:]) / (2 * h)[None, :]
    if not np.all(np.isfinite(J)):
        return np.zeros(0)
    return np.linalg.eigvals(J)
