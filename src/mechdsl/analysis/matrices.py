"""The second-order linear model about a state: M dq'' + C dq' + K dq = B du.

From Lagrange's equations M(q, t) qdd = bias(q, qd, t) about a reference state (q*, qd*, t*)
with reference acceleration a* (zero at an equilibrium):

    M = M(q*),  C = -d bias/d qd,  K = d(M a*)/dq - d bias/d q,   B = d bias/d u

C holds the damping (symmetric part: Rayleigh D and velocity-dependent forces) and the
gyroscopic terms (skew part, from T1 = b'qd: G = (db/dq)' - db/dq... as they appear in the
equations).  K holds the stiffness of the (effective) potential plus the geometric stiffness
of loaded equilibria, both exactly as AD differentiates the equations.
"""
from __future__ import annotations

import numpy as np

from ..diagnostics import Diagnostic, MechError
from .core import dense, parts


def second_order(eom, q, qd, t: float, pv, acc=None):
    """(M, C, K, bias) at the state; acc is the reference acceleration (None: M^-1 bias)."""
    pt = parts(eom)
    n = eom.n
    q = np.asarray(q, float)
    qd = np.asarray(qd, float)
    M, bias = pt.M_bias(q, qd, t, pv)
    if acc is None:
        acc = solve_mass(eom, M, bias) if n else np.zeros(0)
    M, bias, dbq, dbqd, dMa = (dense(o) for o in pt.fn("lin")(q, qd, t, pv, np.asarray(acc, float)))
    K = dMa - dbq + 0.0          # + 0.0: no negative zeros in tables
    C = 0.0 - dbqd
    return M, C, K, bias.ravel(), np.asarray(acc, float)


def solve_mass(eom, M, rhs) -> np.ndarray:
    """M^-1 rhs; a singular M is E910 naming the coordinates of its null direction."""
    w, V = np.linalg.eigh(sym(M))
    if w.size and w[0] > 1e-13 * max(abs(w[-1]), 1e-300):
        return np.linalg.solve(M, rhs)
    # singular: fine when no force acts along the null directions (they carry nothing at all)
    a = np.linalg.lstsq(M, rhs, rcond=1e-13)[0]
    if np.max(np.abs(M @ a - rhs), initial=0.0) <= 1e-9 * max(np.max(np.abs(rhs), initial=0.0), 1e-300):
        return a
    raise singular_mass_error(eom, V[:, 0] if w.size else None)


def singular_mass_error(eom, v, where: str = "at this state"):
    coords = getattr(eom, "coords", ())
    dirn = ""
    if v is not None and len(coords) == len(v):
        big = [f"{c}" for c, x in zip(coords, v) if abs(x) > 0.1 * np.max(np.abs(v))]
        dirn = f" (no inertia along {big[0]})" if len(big) == 1 else \
            f" (no inertia along a combination of {', '.join(big)})"
    return MechError(Diagnostic("E910", f"the mass matrix of '{getattr(eom, 'name', '?')}' is singular {where}"
                                        f"{dirn}: the equations of motion do not determine the accelerations",
                                help="give the bodies involved a mass and a moment of inertia, or use another "
                                     "state (Euler angles are singular at gimbal lock: use a quaternion joint)"))


def first_order(M, C, K) -> np.ndarray:
    """A of x' = A x with x = (dq, dq')."""
    n = M.shape[0]
    Minv = np.linalg.solve(M, np.eye(n))
    return np.block([[np.zeros((n, n)), np.eye(n)], [-Minv @ K, -Minv @ C]])


def reduced_first_order(M, C, K, N) -> np.ndarray:
    """A without the positions along the symmetry directions N (K N = 0).

    Coordinates x = N s + P z; s does not appear in the equations, so the state (z, v) with
    v = (s', z') is enough.  The double zero eigenvalue (Jordan block) of each free drift
    direction becomes a simple zero, which eig computes accurately.
    """
    n = M.shape[0]
    k = N.shape[1]
    if k == 0:
        return first_order(M, C, K)
    P = complement(N)
    Tm = np.hstack([N, P])
    Mt, Ct, Kt = Tm.T @ M @ Tm, Tm.T @ C @ Tm, Tm.T @ K @ Tm
    Kz = Kt[:, k:]
    Minv = np.linalg.solve(Mt, np.eye(n))
    m = n - k
    top = np.hstack([np.zeros((m, m)), np.zeros((m, k)), np.eye(m)])
    bot = np.hstack([-Minv @ Kz, -Minv @ Ct])
    return np.vstack([top, bot])


def complement(N: np.ndarray) -> np.ndarray:
    """Orthonormal basis of the orthogonal complement of span(N) (deterministic)."""
    n, k = N.shape
    if k == 0:
        return np.eye(n)
    Q, _ = np.linalg.qr(np.hstack([N, np.eye(n)]))
    P = Q[:, k:n]
    for j in range(P.shape[1]):
        i = int(np.argmax(np.abs(P[:, j])))
        if P[i, j] < 0:
            P[:, j] = -P[:, j]
    return P


def sym(A: np.ndarray) -> np.ndarray:
    return 0.5 * (A + A.T)


def skew(A: np.ndarray) -> np.ndarray:
    return 0.5 * (A - A.T)
