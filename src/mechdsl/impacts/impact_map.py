"""Lagrange's impact equations for any number of simultaneous contacts.

At an impact the configuration q is fixed and the velocity jumps:

    M(q) (q'+ - q'-) = G^T Lambda + B^T mu
    B q'+ + b_t = 0                                   (bilateral rows: the model's constraints, fixations)
    u+ = G q'+ + g_t >= -e u-_approach,  Lambda >= 0,  Lambda_i (u+_i + e_i min(u-_i, 0)) = 0

(u = G q' + g_t the normal speeds of the candidate contacts, negative when approaching).
For contacts that all keep touching (every Lambda_i > 0) this is exactly
G q'+ = -e G q'- of Newton's law; the complementarity form only adds that no contact pulls.

Solved as the equivalent least-distance problem (Moreau, Gauss' principle for impulses):
q'+ minimizes the kinetic-metric distance 1/2 (q'+ - q'-)^T M (q'+ - q'-) under those
constraints.  With M = L L^T and w = L^T (q'+ - q'-), the bilateral rows are eliminated by
their null space and the remaining least-distance program  min |z|  s.t.  E z >= f  is
solved exactly by one non-negative least-squares problem (Lawson & Hanson, ch. 23), which
also gives the impulses Lambda (dependent contact rows are fine).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.linalg import blas
from scipy.optimize import nnls


class ImpactError(Exception):
    """The impact problem has no solution (contradictory constraints)."""


@dataclass(frozen=True, kw_only=True)
class ImpactSolution:
    qd: np.ndarray                 # q'+
    impulses: np.ndarray           # Lambda, one per candidate contact (>= 0)
    bilateral: np.ndarray          # mu, one per bilateral row
    speeds_before: np.ndarray      # u- of the candidates
    speeds_after: np.ndarray       # u+


def solve_impact(M, qd, G, gt, e, B=None, bt=None) -> ImpactSolution:
    """Post-impact velocities and impulses.

    M (n, n) mass matrix; qd (n,) pre-impact velocity; G (k, n), gt (k,) candidate contacts
    (normal speed u = G qd + gt); e (k,) restitution; B (r, n), bt (r,) bilateral rows
    (B qd+ + bt = 0 afterwards).
    """
    M = np.asarray(M, float)
    v = np.asarray(qd, float)
    n = v.size
    G = np.asarray(G, float).reshape(-1, n)
    gt = np.asarray(gt, float).reshape(-1)
    e = np.asarray(e, float).reshape(-1)
    B = np.zeros((0, n)) if B is None else np.asarray(B, float).reshape(-1, n)
    bt = np.zeros(B.shape[0]) if bt is None else np.asarray(bt, float).reshape(-1)
    u_minus = G @ v + gt
    h = -e * np.minimum(u_minus, 0.0)                 # required u+ (>=)
    if G.shape[0] == 1 and not B.shape[0]:
        single = _single(M, v, G[0], gt, h, u_minus)
        if single is not None:
            return single
    L = np.linalg.cholesky(M)
    if not (np.all(np.isfinite(L)) and np.all(np.isfinite(G)) and np.all(np.isfinite(B))):
        raise ImpactError("non-finite mass matrix or contact rows at the impact")
    Gt = _lower_solve(L, G)                         # G L^-T
    Bt = _lower_solve(L, B)
    # bilateral rows: w = w0 + N z, w0 in the row space of Bt
    if B.shape[0]:
        U, s, Vt = np.linalg.svd(Bt)
        rank = int(np.sum(s > 1e-12 * max(1.0, s[0]))) if s.size else 0
        rB = -bt - B @ v
        w0 = Vt[:rank].T @ ((U[:, :rank].T @ rB) / s[:rank])
        if np.linalg.norm(Bt @ w0 - rB) > 1e-9 * max(1.0, np.linalg.norm(rB)):
            raise ImpactError("the bilateral constraints cannot all hold after the impact")
        N = Vt[rank:].T
    else:
        w0, N = np.zeros(n), np.eye(n)
    E = Gt @ N
    f = h - gt - G @ v - Gt @ w0
    z, lam = ldp(E, f)
    w = w0 + N @ z
    v_plus = v + blas.dtrsv(L.T, w, lower=0, trans=0, diag=0)      # L^-T w
    mu = np.zeros(B.shape[0])
    if B.shape[0]:
        mu = np.linalg.lstsq(B.T, M @ (v_plus - v) - G.T @ lam, rcond=None)[0]
    return ImpactSolution(qd=v_plus, impulses=lam, bilateral=mu, speeds_before=u_minus,
                          speeds_after=G @ v_plus + gt)


def _lower_solve(L, R) -> np.ndarray:
    """(L^-1 R^T)^T = R L^-T for the Cholesky factor L (C order) and rows R: BLAS trsv/trsm
    on L^T, which is what scipy.linalg.solve_triangular(L, R.T, lower=True) computes through
    LAPACK trtrs with one thread (bit for bit: trtrs is trsv for one column, trsm for more).
    Not solve_triangular itself: OpenBLAS's trtrs wakes its worker threads for any size, and
    each wake-up left a thread spinning for tens of milliseconds of CPU after a 3 x 3 solve
    (the falling rod's CPU time doubled, and its cost depended on when its impacts fell);
    BLAS trsv/trsm stay on the calling thread below OpenBLAS's size thresholds."""
    k, n = R.shape
    if k == 0 or n == 0:
        return np.zeros((k, n))
    if k == 1:
        return blas.dtrsv(L.T, R[0], lower=0, trans=1, diag=0).reshape(1, n)
    return blas.dtrsm(1.0, L.T, np.array(R.T, order="F"), side=0, lower=0, trans_a=1, diag=0).T


def _single(M, v, g, gt, h, u_minus):
    """One contact, no bilateral rows: the least-distance problem in closed form,
    Lambda = max(0, h - u) / W with W = g M^-1 g^T, q'+ = q'- + M^-1 g^T Lambda (what the
    LDP gives for one row; the impact events of a lone contact, the common case, skip the
    factorizations and the NNLS).  None when W is not positive (the general path decides)."""
    try:
        x = np.linalg.solve(M, g)
    except np.linalg.LinAlgError:
        return None
    W = float(g @ x)
    if not (W > 0.0 and np.isfinite(W)):
        return None
    lam = np.array([max(0.0, float(h[0] - u_minus[0])) / W])
    v_plus = v + x * lam[0]
    return ImpactSolution(qd=v_plus, impulses=lam, bilateral=np.zeros(0), speeds_before=u_minus,
                          speeds_after=np.array([g @ v_plus]) + gt)


def ldp(E, f) -> tuple[np.ndarray, np.ndarray]:
    """min |z| subject to E z >= f (Lawson & Hanson's LDP via NNLS); returns z and the multipliers."""
    E = np.asarray(E, float)
    f = np.asarray(f, float)
    k, d = E.shape
    if k == 0 or np.all(f <= 0.0):
        return np.zeros(d), np.zeros(k)
    scale = max(1.0, float(np.max(np.abs(f))))
    Emat = np.vstack([E.T, f.reshape(1, -1) / scale])
    rhs = np.zeros(d + 1)
    rhs[-1] = 1.0
    u, _ = nnls(Emat, rhs, maxiter=50 * (k + d + 1))
    r = Emat @ u - rhs
    if abs(r[-1]) < 1e-14:
        raise ImpactError("the contact conditions after the impact are contradictory")
    z = -r[:d] / r[-1] * scale            # solution of the scaled problem (E, f/scale), scaled back
    lam = u / (-r[-1]) * scale
    return z, lam
