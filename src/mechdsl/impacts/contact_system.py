"""Compiled functions and the numerics of one model with contacts (dynamics, constraints, projection).

Constraint rows, all functions of (q, t, p), stacked in this order:

    the model's holonomic constraints g (m rows, always active)
    one gap per contact (k rows, active while the contact is closed/persistent)
    three position rows per fixation (active after its time, anchored where the point was)

For the active rows c_S: A = dc/dq, c_t = dc/dt, cdot = A q' + c_t and
gamma = d(cdot)/dq q' + d(cdot)/dt, so that c_S'' = A q'' + gamma.  The constrained
accelerations solve  M q'' = bias + A^T lam,  A q'' + gamma = 0  (index 1; drift is
removed by projection, see :meth:`ContactSystem.project`).  A contact's multiplier is its
normal force: lam > 0 pushes the bodies apart.
"""
from __future__ import annotations

import numpy as np
from scipy.linalg.lapack import dpotrf as _POTRF, dpotrs as _POTRS

from ..diagnostics import Diagnostic, MechError
from ..eom.codegen import dense_function
from .fastfn import FastFunction
from .gaps import point_position


RANK_TOL = 1e-10


def contact_functions(eom, gaps, fixations) -> dict:
    """The CasADi Functions of a contact system (stateless, dense outputs): built once per
    model and set of contacts (``impacts.simulate`` keeps them in the EOM's workspace); each
    run wraps them in its own FastFunction buffers."""
    import casadi as ca


    q, qd, t, P = eom.q, eom.qd, eom.t, eom.p
    rows = []
    if eom.m:
        rows.append(ca.reshape(eom.g, -1, 1))
    rows += [ca.SX(g.gap) for g in gaps]
    rows += [ca.reshape(point_position(eom, f.point), 3, 1) for f in fixations]
    c = ca.vertcat(*rows) if rows else ca.SX.zeros(0, 1)
    A = ca.jacobian(c, q)
    ct = ca.jacobian(c, t)
    cdot = ca.mtimes(A, qd) + ct
    gamma = ca.mtimes(ca.jacobian(cdot, q), qd) + ca.jacobian(cdot, t)
    args, names = [t, q, qd, P], ["t", "q", "qd", "p"]
    gapv = ca.vertcat(*[ca.SX(g.gap) for g in gaps]) if gaps else ca.SX.zeros(0, 1)
    out = {"n_rows": int(c.numel()),
           "dyn": ca.Function("dyn", args, [eom.M, eom.bias], names, ["M", "bias"]),
           "qdd": ca.Function("qdd", args, [eom.qdd], names, ["qdd"]) if eom.qdd is not None else None,
           "cons": ca.Function("cons", args, [c, A, ct, gamma], names, ["c", "A", "ct", "gamma"]),
           "pos": ca.Function("pos", [t, q, P], [c, A, ct], ["t", "q", "p"], ["c", "A", "ct"]),
           "gap": ca.Function("gap", [t, q, P], [gapv], ["t", "q", "p"], ["gap"]),
           "energy": ca.Function("energy", args, [eom.T, eom.V], names, ["T", "V"]),
           "e": ca.Function("e", [P], [ca.vertcat(*[ca.SX(g.e) for g in gaps]) if gaps else ca.SX.zeros(0, 1)]),
           "friction": None}
    friction = [i for i, g in enumerate(gaps) if g.friction is not None]
    if friction:
        cols = [ca.SX(gaps[i].friction) for i in friction]
        out["friction"] = ca.Function("friction", args, [ca.horzcat(*cols)], names, ["W"])
    for k in ("dyn", "qdd", "cons", "pos", "energy", "friction"):
        if out[k] is not None:
            out[k] = dense_function(out[k])
    return out


MAP_SIZES = (1, 2, 4, 8, 16, 32, 64)     # the batch sizes of multipliers_at (padded up, chunked above)


class ContactSystem:
    def __init__(self, eom, gaps, fixations, p: np.ndarray, functions: dict | None = None):
        self.eom, self.gaps, self.fixations = eom, list(gaps), list(fixations)
        self.p = np.asarray(p, float)
        self.n, self.m, self.k = eom.n, eom.m, len(self.gaps)
        fs = functions if functions is not None else contact_functions(eom, self.gaps, self.fixations)
        self.n_rows = fs["n_rows"]
        self.f_dyn = FastFunction(fs["dyn"])
        self.f_qdd = FastFunction(fs["qdd"]) if fs["qdd"] is not None else None
        self.f_cons = FastFunction(fs["cons"])
        self.f_pos = FastFunction(fs["pos"])
        self._f_gap = fs["gap"]
        self.f_gap = FastFunction(self._f_gap)
        self.f_energy = FastFunction(fs["energy"])
        self.e = np.array(fs["e"](self.p), float).ravel()
        if np.any(self.e < 0) or np.any(self.e > 1):
            bad = [g.name for g, e in zip(self.gaps, self.e) if not 0 <= e <= 1]
            raise MechError(Diagnostic("E862", f"coefficient of restitution of '{bad[0]}' must be in [0, 1]"))
        # sliding friction of persistent contacts: column i = generalized force per unit normal force
        self.friction = [i for i, g in enumerate(self.gaps) if g.friction is not None]
        self.f_fric = FastFunction(fs["friction"]) if fs["friction"] is not None else None
        self.anchor = np.zeros(self.n_rows)
        self._fs = fs
        self._gap_maps: dict[int, object] = {}
        self._maps: dict[tuple, object] = {}
        self._f_jac = None
        self._jac_unavailable = False
        self.n_rhs = 0

    # ------------------------------------------------------------------ row bookkeeping
    def contact_row(self, i: int) -> int:
        return self.m + i

    def fix_rows(self, j: int) -> list[int]:
        b = self.m + self.k + 3 * j
        return [b, b + 1, b + 2]

    @property
    def model_rows(self) -> list[int]:
        return list(range(self.m))

    # ------------------------------------------------------------------ evaluations
    def dyn(self, t, q, qd):
        M, b = self.f_dyn(t, q, qd, self.p)
        return M.reshape(self.n, self.n), b

    def cons(self, t, q, qd):
        c, A, ct, g = self.f_cons(t, q, qd, self.p)
        return c - self.anchor, A.reshape(self.n_rows, self.n), ct, g

    def pos(self, t, q):
        """Raw constraint rows (without anchors), their Jacobian and time derivative."""
        c, A, ct = self.f_pos(t, q, self.p)
        return c, A.reshape(self.n_rows, self.n), ct

    def gap(self, t, q) -> np.ndarray:
        return self.f_gap(t, q, self.p)[0]

    def gaps_at(self, ts: np.ndarray, Q: np.ndarray) -> np.ndarray:
        """Gaps at many states: Q is (n, K); returns (k, K)."""
        K = Q.shape[1]
        f = self._gap_maps.get(K)
        if f is None:
            f = self._gap_maps[K] = FastFunction(self._f_gap.map(K))
        return f(ts.reshape(1, -1), Q, np.repeat(self.p.reshape(-1, 1), K, 1))[0].reshape(self.k, K)

    def _mapped(self, name: str, K: int):
        key = (name, K)
        f = self._maps.get(key)
        if f is None:
            f = self._maps[key] = FastFunction(self._fs[name].map(K))
        return f

    def multipliers_at(self, ts: np.ndarray, Y: np.ndarray, rows) -> np.ndarray | None:
        """The multipliers of the active ``rows`` at many states (Y: (2n, K)), as ``accel`` gives
        them one state at a time: (K, len(rows)); None with friction on an active row (the caller
        then asks ``accel`` per state).  One mapped call of the dynamics and the constraints and
        batched solves instead of K calls (the output rows of a resting phase)."""
        if self._friction_columns(ts[0], Y[:self.n, 0], Y[self.n:, 0], rows) is not None:
            return None
        if len(ts) > MAP_SIZES[-1]:
            step = MAP_SIZES[-1]
            return np.vstack([self.multipliers_at(ts[i:i + step], Y[:, i:i + step], rows)
                              for i in range(0, len(ts), step)])
        size = next(k for k in MAP_SIZES if k >= len(ts))     # a few mapped Functions, the last state repeated
        if size > len(ts):
            pad = size - len(ts)
            return self.multipliers_at(np.r_[ts, np.repeat(ts[-1:], pad)],
                                       np.hstack([Y, np.repeat(Y[:, -1:], pad, 1)]), rows)[:len(ts)]
        n, K = self.n, len(ts)
        t1, Q, QD, P = ts.reshape(1, -1), Y[:n], Y[n:], np.repeat(self.p.reshape(-1, 1), K, 1)
        M, b = self._mapped("dyn", K)(t1, Q, QD, P)
        c, A, ct, gam = self._mapped("cons", K)(t1, Q, QD, P)
        self.n_rhs += K
        M3 = np.asarray(M).reshape(n, K, n).transpose(1, 0, 2)
        A3 = np.asarray(A).reshape(self.n_rows, K, n).transpose(1, 0, 2)[:, rows, :]
        b3 = np.asarray(b).reshape(n, K).T[:, :, None]
        g3 = np.asarray(gam).reshape(self.n_rows, K).T[:, rows, None]
        a0 = np.linalg.solve(M3, b3)
        X = np.linalg.solve(M3, A3.transpose(0, 2, 1))
        lam = -np.linalg.solve(A3 @ X, A3 @ a0 + g3)
        return lam[:, :, 0]

    def normal_speeds(self, t, q, qd) -> np.ndarray:
        _, A, ct, _ = self.cons(t, q, qd)
        rows = [self.contact_row(i) for i in range(self.k)]
        return A[rows] @ qd + ct[rows]

    def kinetic(self, t, q, qd) -> float:
        return float(self.f_energy(t, q, qd, self.p)[0][0])

    # ------------------------------------------------------------------ accelerations
    def accel(self, t, q, qd, rows) -> tuple[np.ndarray, np.ndarray]:
        """q'' and the multipliers of the active rows."""
        self.n_rhs += 1
        if not rows:
            if self.f_qdd is not None:
                return self.f_qdd(t, q, qd, self.p)[0], np.zeros(0)
            M, b = self.dyn(t, q, qd)
            return _solve_spd(M, b), np.zeros(0)
        n = self.n
        M, b = self.f_dyn(t, q, qd, self.p)
        _, A, _, gam = self.f_cons(t, q, qd, self.p)
        A, gam = A.reshape(self.n_rows, n)[rows], gam[rows]
        cf = _cho(M.reshape(n, n))
        if self.f_fric is None:
            # what the general path below computes, with its checks (non-finite input: ValueError,
            # as _cho_solve raises it) and LAPACK calls, without the per-call wrapping: this runs
            # for every right-hand side and every release-event evaluation of a phase with
            # closed contacts (the same bits; tests/test_imp_batched_rows.py)
            c = cf[0]
            if not (np.isfinite(b).all() and np.isfinite(c).all() and np.isfinite(A).all()):
                raise ValueError("array must not contain infs or NaNs")
            a0, info = _POTRS(c, b, lower=1)
            X, info2 = _POTRS(c, A.T, lower=1)
            if info or info2:
                raise ValueError(f"illegal value in {-(info or info2)}th argument of internal potrs")
            lam = -_solve_sym(A @ X, A @ a0 + gam)
            return a0 + X @ lam, lam
        a0 = _cho_solve(cf, b)
        X = _cho_solve(cf, A.T)
        B = self._friction_columns(t, q, qd, rows)
        if B is None:
            lam = -_solve_sym(A @ X, A @ a0 + gam)
            return a0 + X @ lam, lam
        # M q'' = bias + (A' + B) lam: a contact's friction is proportional to its normal force
        XB = X + _cho_solve(cf, B)
        W = A @ XB
        try:
            lam = -np.linalg.solve(W, A @ a0 + gam)
        except np.linalg.LinAlgError:
            lam = -np.linalg.lstsq(W, A @ a0 + gam, rcond=1e-12)[0]
        return a0 + XB @ lam, lam

    def _friction_columns(self, t, q, qd, rows):
        """(n, len(rows)): the friction generalized force per unit multiplier of each active row
        (0 for rows without friction), or None when no active row has friction."""
        if self.f_fric is None:
            return None
        cols = {self.contact_row(i): j for j, i in enumerate(self.friction)}
        if not any(r in cols for r in rows):
            return None
        Wf = self.f_fric(t, q, qd, self.p)[0].reshape(self.n, len(self.friction), order="F")
        B = np.zeros((self.n, len(rows)))
        for j, r in enumerate(rows):
            if r in cols:
                B[:, j] = Wf[:, cols[r]]
        return B

    def rhs(self, rows):
        n = self.n

        def f(t, y):
            qdd, _ = self.accel(t, y[:n], y[n:], rows)
            return np.concatenate([y[n:], qdd])

        return f

    def jacobian(self, rows):
        """d(rhs)/dy for implicit methods: analytic (CasADi) in free flight when the forward
        dynamics are cheap to differentiate (explicit q'' or up to 12 coordinates), else None
        (the solver then differences)."""
        if rows or self._jac_unavailable:
            return None
        if self._f_jac is None:
            import casadi as ca

            eom = self.eom
            if eom.qdd is None and self.n > 12:
                self._jac_unavailable = True
                return None
            qdd = eom.qdd if eom.qdd is not None else ca.solve(eom.M, eom.bias)
            y = ca.vertcat(eom.q, eom.qd)
            J = ca.jacobian(ca.vertcat(eom.qd, qdd), y)
            self._f_jac = FastFunction(ca.Function("rhs_jacobian", [eom.t, eom.q, eom.qd, eom.p], [J]))
        n, f = self.n, self._f_jac

        def jac(t, y):
            return f(t, y[:n], y[n:], self.p)[0].reshape(2 * n, 2 * n)

        return jac

    def multipliers(self, t, q, qd, rows) -> np.ndarray:
        return self.accel(t, q, qd, rows)[1]

    # ------------------------------------------------------------------ constraint handling
    def independent(self, t, q, rows, keep=()) -> list[int]:
        """The rows (in the order given) whose Jacobian rows are linearly independent, greedily."""
        if not rows:
            return []
        _, A, _ = self.pos(t, q)
        M, _ = self.dyn(t, q, np.zeros(self.n))
        L = np.linalg.cholesky(M)
        chosen: list[int] = []
        basis = np.zeros((0, self.n))
        for r in rows:
            a = np.linalg.solve(L, A[r])          # row in the kinetic metric
            na = np.linalg.norm(a)
            if na == 0.0:
                continue
            res = a - basis.T @ (basis @ a) if len(basis) else a
            if np.linalg.norm(res) > RANK_TOL * na:
                chosen.append(r)
                basis = np.vstack([basis, res / np.linalg.norm(res)])
        return chosen

    def project(self, t, q, qd, rows, tol: float, one_sided=(), one_sided_tol: float = 0.0, iters: int = 8):
        """Project (q, qd) onto the active rows (positions then velocities) in the kinetic metric.

        ``one_sided`` rows (open contacts) are corrected only where they penetrate
        (c < -one_sided_tol), and then onto c = 0.
        """
        q, qd = np.array(q, float), np.array(qd, float)
        for _ in range(iters):
            c, A, _ = self.pos(t, q)
            c = c - self.anchor
            use = list(rows) + [r for r in one_sided if c[r] < -one_sided_tol]
            if not use or np.max(np.abs(c[use])) <= tol:
                break
            A = A[use]
            M, _ = self.dyn(t, q, qd)
            cf = _cho(M)
            X = _cho_solve(cf, A.T)
            q = q - X @ _solve_sym(A @ X, c[use])
        if rows:
            _, A, ct, _ = self.cons(t, q, qd)
            A, ct = A[rows], ct[rows]
            M, _ = self.dyn(t, q, qd)
            cf = _cho(M)
            X = _cho_solve(cf, A.T)
            qd = qd - X @ _solve_sym(A @ X, A @ qd + ct)
        return q, qd

    def drift(self, t, q, qd, rows) -> tuple[float, float]:
        if not rows:
            return 0.0, 0.0
        c, A, ct, _ = self.cons(t, q, qd)
        return float(np.max(np.abs(c[rows]))), float(np.max(np.abs(A[rows] @ qd + ct[rows])))


def _cho(M):
    """scipy.linalg.cho_factor(M, lower=True, check_finite=False): the same LAPACK call (potrf),
    without scipy's per-call wrapping, which cost more than the factorization of these small
    matrices (accel runs for every right-hand side of a contact run)."""
    c, info = _POTRF(np.asarray(M, dtype=float), lower=1, clean=0)
    if info > 0:
        raise np.linalg.LinAlgError(f"{info}-th leading minor of the array is not positive definite")
    if info < 0:
        raise ValueError(f'LAPACK reported an illegal value in {-info}-th argument on entry to "POTRF".')
    return c, True


def _cho_solve(cf, b, check_finite: bool = True):
    """scipy.linalg.cho_solve(cf, b, check_finite=...) of a lower factor from _cho: the same
    LAPACK call (potrs) and the same refusal of non-finite input (ValueError)."""
    c, _ = cf
    b = np.asarray(b, dtype=float)
    if check_finite and not (np.isfinite(b).all() and np.isfinite(c).all()):
        raise ValueError("array must not contain infs or NaNs")
    if b.size == 0:
        return np.empty_like(b)
    x, info = _POTRS(c, b, lower=1)
    if info != 0:
        raise ValueError(f"illegal value in {-info}th argument of internal potrs")
    return x


def _solve_spd(M, b):
    try:
        return _cho_solve(_cho(M), b, check_finite=False)
    except np.linalg.LinAlgError:
        return np.linalg.solve(M, b)


def _solve_sym(W, r):
    """Solve W x = r for a symmetric positive (semi)definite W; minimum norm when singular."""
    try:
        return _cho_solve(_cho(W), r, check_finite=False)
    except np.linalg.LinAlgError:
        return np.linalg.lstsq(W, r, rcond=1e-12)[0]
