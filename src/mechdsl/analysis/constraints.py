"""Constrained models in the analyses: what equilibria and linearization need beyond the ODE.

    M(q) q'' = bias(q, q', t) - G(q)^T lambda,     g(q) = 0,     G = dg/dq

Only scleronomic constraints (g free of t) are analysed: a rest state of a moving constraint
does not exist in general.  The pieces (numpy out, CasADi Functions cached on the EOM):

- ``setup``: the checks, the consistent start and the *active* constraints -- an independent
  subset chosen by the DAE code (``mechdsl.dae.dof_report``: pivoted QR of the mass-scaled G),
  so redundant rows (the out-of-plane conditions of a planar loop, a constraint written twice)
  drop out; their multipliers are reported as 0;
- ``project``: a configuration moved onto g = 0 by the DAE's consistent initialization
  (``mechdsl.dae.initialize``: minimal change in the mass metric, chosen coordinates held);
- starting guesses on the manifold: :mod:`.manifold`;
- ``geometric_stiffness``: sum_l lambda_l d2g_l/dq2, the stiffness the constraint forces add;
- ``tangent_basis`` (orthonormal) and ``independent_basis`` (columns of the independent
  coordinates: dq = Z dz with dz the changes of those coordinates) of null(G);
- ``rest_multipliers``: acceleration and multipliers at a rest state (the DAE's KKT solve).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..dae.dof import dependent_columns, dof_report
from ..dae.init import initialize
from ..dae.constrained_system import kkt_solve, scale_jacobian
from ..diagnostics import Diagnostic, MechError
from .core import Probe, dense, null_space, vanishes


COND_MAX = 100.0           # independent-coordinate basis used while cond(Z) stays below this


def constrained(eom) -> bool:
    return eom.g is not None and eom.g.numel() > 0


class Fns:
    """Cached CasADi Functions of the constraints of one EOM."""

    def __init__(self, eom):
        import casadi as ca

        q, t, p = eom.q, eom.t, eom.p
        m = eom.m
        lam = ca.SX.sym("lam", m)
        G = ca.jacobian(eom.g, q)
        self.gG = ca.Function("gG", [q, t, p], [eom.g, G, ca.jacobian(eom.g, t)])
        H, _ = ca.hessian(ca.dot(lam, eom.g), q)
        self.hess = ca.Function("lam_g_hess", [q, t, p, lam], [H])
        self.m = m
        self.n = eom.n

    def g_G(self, q, t, pv) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        g, G, gt = self.gG(q, t, pv)
        return dense(g).ravel(), dense(G).reshape(self.m, self.n), dense(gt).ravel()


def fns(eom) -> Fns:
    # shared with the EOM.replace copies of the same constraints
    return eom.workspace.by_content(eom, ("g", "q", "t", "p"), "constraint_fns", lambda: Fns(eom))


@dataclass
class Setup:
    """What the analyses of one constrained EOM share (for one parameter vector and time)."""

    eom: object
    pv: np.ndarray
    t: float
    active: tuple[int, ...]                 # indices of the independent constraints
    q_start: np.ndarray                     # the start values on the constraint manifold
    row_norms: np.ndarray                   # ||dg_i/dq|| of the active rows at q_start
    notes: list[str] = field(default_factory=list)

    @property
    def names(self) -> tuple[str, ...]:
        return tuple(self.eom.constraint_names)

    @property
    def dropped(self) -> tuple[str, ...]:
        return tuple(c for i, c in enumerate(self.eom.constraint_names) if i not in self.active)

    @property
    def ma(self) -> int:
        return len(self.active)

    def g_G(self, q):
        """(g, G, g_t) of every constraint at q."""
        return fns(self.eom).g_G(q, self.t, self.pv)

    def G_active(self, q) -> np.ndarray:
        return self.g_G(q)[1][list(self.active)]

    def distances(self, q) -> np.ndarray:
        """|g_i| / ||dg_i/dq|| for every constraint (|g_i| where the gradient vanishes)."""
        g, G, _ = self.g_G(q)
        norms = np.linalg.norm(G, axis=1)
        return np.abs(g) / np.where(norms > 0, norms, 1.0)

    def full_multipliers(self, lam_active) -> np.ndarray:
        out = np.zeros(self.eom.m)
        out[list(self.active)] = lam_active
        return out

    def curvature_scale(self, q) -> float:
        """|sum_l d2g_l/dq2 / |dg_l/dq||: how strongly the constraints bend (for tolerances on
        the geometric stiffness, which is of the order force scale x this)."""
        G = self.G_active(q)
        norms = np.linalg.norm(G, axis=1)
        w = 1.0 / np.where(norms > 0, norms, 1.0)
        return float(np.max(np.abs(self.geometric_stiffness(q, w)), initial=0.0))

    def geometric_stiffness(self, q, lam_active) -> np.ndarray:
        """sum_l lambda_l d2g_l/dq2 (the Hessian of lambda'g), active constraints only."""
        lam = self.full_multipliers(lam_active)
        return dense(fns(self.eom).hess(q, self.t, self.pv, lam))


def setup(eom, pv, t: float, what: str) -> Setup:
    """Check that ``what`` applies (scleronomic constraints) and choose the active constraints
    at the consistent start."""
    _require_scleronomic(eom, pv, what)
    notes = []
    q0, _ = eom.start(pv)
    qs = project(eom, q0, t, pv, fixed=eom.fixed_q)
    if qs is None:
        qs = project(eom, q0, t, pv)
        if qs is None:
            qs = q0
            notes.append("the start values could not be brought onto the constraints; the redundancy "
                         "check used them as they are")
    rep = dof_report(eom, qs, t, pv)
    active = tuple(rep.independent)
    s = Setup(eom=eom, pv=pv, t=float(t), active=active, q_start=np.asarray(qs, float),
              row_norms=np.ones(len(active)), notes=notes)
    norms = np.linalg.norm(s.G_active(qs), axis=1)
    s.row_norms = np.where(norms > 0, norms, 1.0)
    if rep.redundant:
        s.notes.append(f"redundant constraint(s) {', '.join(s.dropped)} dropped (their multipliers are "
                       "reported as 0)")
    return s


def _require_scleronomic(eom, pv, what) -> None:
    import casadi as ca

    if not ca.depends_on(eom.g, eom.t):
        return
    f = ca.Function("g_t", [eom.q, eom.t, eom.p], [ca.jacobian(eom.g, eom.t), ca.jacobian(eom.g, eom.q)])
    pr = Probe.states(eom.n)
    gt, G = zip(*[(dense(a), dense(b)) for a, b in (f(pr.q[i], pr.t[i], pv) for i in range(len(pr)))])
    scale = max(max(float(np.max(np.abs(x), initial=0.0)) for x in G), 1e-300)
    if vanishes(list(gt), scale) is False:
        raise MechError(Diagnostic(
            "E901", f"{what} needs constraints that do not move: the constraints of '{eom.name}' "
                    f"depend on time ({', '.join(eom.constraint_names)}), so the model has no rest state",
            help="analyse the motion by simulation, or fix the prescribed motion (a constant value) "
                 "to study the mechanism at one configuration"))


def project(eom, q, t, pv, fixed=None) -> np.ndarray | None:
    """q moved onto g = 0 by the DAE's consistent initialization (mass metric, ``fixed``
    coordinates held; default all free); None when it cannot be done."""
    n = eom.n
    fixed = tuple(bool(f) for f in fixed) if fixed is not None and len(fixed) == n else (False,) * n
    try:
        rep = initialize(eom, q0=np.asarray(q, float), qd0=np.zeros(n), t=t, p=pv, fixed_q=fixed,
                         fixed_qd=(False,) * n)
    except (MechError, np.linalg.LinAlgError, ValueError):
        return None
    return rep.q if np.all(np.isfinite(rep.q)) else None


def independent_coordinates(eom, M, G) -> tuple[int, ...]:
    """Coordinates left free by a pivoted QR of the mass-scaled G (the best-conditioned
    dependent block goes to the others), in coordinate order."""
    n = G.shape[1]
    if G.shape[0] == 0:
        return tuple(range(n))
    dep = dependent_columns(scale_jacobian(G, M))
    return tuple(i for i in range(n) if i not in dep)


def tangent_basis(G: np.ndarray) -> np.ndarray:
    """Orthonormal basis of null(G), deterministic (coordinate axes first)."""
    n = G.shape[1]
    if G.shape[0] == 0:
        return np.eye(n)
    scale = np.linalg.norm(G, axis=1)
    Gs = G / np.where(scale > 0, scale, 1.0)[:, None]
    Z = null_space(Gs, rel=1e-9)
    return Z


def independent_basis(eom, M, G) -> tuple[np.ndarray, tuple[int, ...]]:
    """Z = dq/dz with z the independent coordinates: Z[indep] = I, Z[dep] = -G_dep^-1 G_indep.

    Returns (Z, indep); indep is () when that basis is ill-conditioned (cond > COND_MAX), in
    which case Z is the orthonormal basis of null(G)."""
    n = G.shape[1]
    indep = independent_coordinates(eom, M, G)
    if not indep:
        return np.zeros((n, 0)), ()
    dep = [i for i in range(n) if i not in indep]
    Z = np.zeros((n, len(indep)))
    Z[list(indep), range(len(indep))] = 1.0
    if dep:
        try:
            Z[dep] = -np.linalg.solve(G[:, dep], G[:, list(indep)])
        except np.linalg.LinAlgError:
            return tangent_basis(G), ()
    if not np.all(np.isfinite(Z)) or np.linalg.cond(Z) > COND_MAX:
        return tangent_basis(G), ()
    return Z, indep


def rest_multipliers(s: Setup, q, M, bias) -> tuple[np.ndarray, np.ndarray]:
    """(acceleration, active multipliers) at rest at q: the DAE's KKT solve with
    G q'' = gamma = 0 (scleronomic constraints at zero speed)."""
    G = s.G_active(q)
    a, lam = kkt_solve(M, G, bias, np.zeros(G.shape[0]))
    fs = max(float(np.max(np.abs(bias), initial=0.0)), 1e-300)
    lam = np.where(np.abs(lam) * np.linalg.norm(G, axis=1) <= 1e-12 * fs, 0.0, lam)   # round-off
    return a, lam


def least_squares_multipliers(s: Setup, q, bias) -> np.ndarray:
    """lambda minimizing |bias - G^T lambda| (a starting value for the equilibrium search)."""
    G = s.G_active(q)
    if G.shape[0] == 0:
        return np.zeros(0)
    return np.linalg.lstsq(G.T, bias, rcond=1e-12)[0]
