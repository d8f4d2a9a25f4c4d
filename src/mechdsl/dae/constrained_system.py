"""A constrained system compiled from an EOM: the pieces every formulation needs.

    M(q, t) q'' = bias(q, q', t) - G^T lambda,     g(q, t) = 0,     G = dg/dq

with, by automatic differentiation (CasADi SX),

    gdot  = G q' + g_t                              (velocity-level residual)
    gamma = -(d gdot/dq) q' - d gdot/dt             (so that G q'' = gamma on the manifold)

Only the *active* constraints (an independent subset chosen by :mod:`.dof`) enter the
equations; the full set is kept for monitoring and reporting.

Linear algebra.  The augmented (KKT) system

    [ M   G^T ] [ q''    ]   [ bias                               ]
    [ G   0   ] [ lambda ] = [ gamma - 2 alpha gdot - beta^2 g    ]

is solved after a symmetric equilibration: D = diag(M)^(-1/2) on the coordinates and
S = 1/||row of G D|| on the constraints -- symbolically (CasADi's SX ``solve``, an unpivoted
QR) up to n + m = SX_KKT_MAX, numerically (sparse QR inside an MX Function) above.  Without it the unpivoted QR loses up to 8 digits on badly scaled problems
such as Andrews' squeezer (M ~ 1e-5, G ~ 1e-2); with it the result agrees with a pivoted
dense solve to ~1e-15 (tests/test_dae_system.py).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..eom import EOM
from ..eom.codegen import FastFunction


def _sx():
    import casadi as ca

    return ca


SX_KKT_MAX = 12   # up to this n + m the augmented system is solved symbolically (SX), above numerically
SCHUR_MAX_N = 60  # above SX_KKT_MAX: Cholesky + Schur complement in SX up to this n, when M is positive definite
SCHUR_MIN_RCOND = 1e-8   # least lambda_min/lambda_max of the equilibrated M at the start for the Schur route


def _cholesky(A: list[list]) -> list[list]:
    """Lower L with A = L L^T, in SX scalars (A symmetric positive definite: no pivoting needed)."""
    ca = _sx()
    n = len(A)
    L = [[None] * n for _ in range(n)]
    for j in range(n):
        s = A[j][j] - sum((L[j][k] * L[j][k] for k in range(j)), ca.SX(0))
        L[j][j] = ca.sqrt(s)
        for i in range(j + 1, n):
            L[i][j] = (A[i][j] - sum((L[i][k] * L[j][k] for k in range(j)), ca.SX(0))) / L[j][j]
    return L


def _forward(L, b: list) -> list:
    ca = _sx()
    y = []
    for i in range(len(b)):
        y.append((b[i] - sum((L[i][k] * y[k] for k in range(i)), ca.SX(0))) / L[i][i])
    return y


def _backward(L, b: list) -> list:
    ca = _sx()
    n = len(b)
    x = [None] * n
    for i in reversed(range(n)):
        x[i] = (b[i] - sum((L[k][i] * x[k] for k in range(i + 1, n)), ca.SX(0))) / L[i][i]
    return x


def schur_kkt_solve(M, G, rhs_q, rhs_c):
    """The equilibrated augmented system solved by its Schur complement, in SX:
    Ms = L L^T (Cholesky), Y = L^-1 Gs^T, (Y^T Y) mu = Y^T L^-1 bq - bc, y = L^-T (L^-1 bq - Y mu).
    Cost ~ n^3/6 + n^2 m + m^3/6 operations, no pivoting: both factors are of positive definite
    matrices (the equilibrated mass matrix; the Schur complement with independent constraints)."""
    ca = _sx()
    n, m = M.shape[0], G.shape[0]
    K, b, d, s = equilibrated_kkt(M, G, rhs_q, rhs_c)
    A = [[K[i, j] for j in range(n)] for i in range(n)]
    L = _cholesky(A)
    cols = [_forward(L, [K[n + r, i] for i in range(n)]) for r in range(m)]     # Y's columns: L^-1 Gs^T
    z = _forward(L, [b[i] for i in range(n)])
    dot = lambda u, v: sum((ui * vi for ui, vi in zip(u, v)), ca.SX(0))      # noqa: E731
    S = [[dot(cols[r], cols[c]) for c in range(m)] for r in range(m)]
    R = _cholesky(S)
    mu = _backward(R, _forward(R, [dot(cols[r], z) - b[n + r] for r in range(m)]))
    w = [z[i] - sum((cols[r][i] * mu[r] for r in range(m)), ca.SX(0)) for i in range(n)]
    y = _backward(L, w)
    return d * ca.vertcat(*y), s * (ca.vertcat(*mu) if mu else ca.SX(0, 1))


def _kkt_route(eom: EOM, pv: np.ndarray, m: int) -> str:
    """'sx' (small), 'schur' (mid-size with a well-conditioned mass matrix) or 'mx' (numeric QR)."""
    n = eom.n
    if n + m <= SX_KKT_MAX:
        return "sx"
    if n > SCHUR_MAX_N or m == 0:
        return "mx"
    ca = _sx()
    try:
        q0 = eom.start(pv)[0] if eom.q0 is not None else np.zeros(n)
        fM = eom.workspace.memo("M", lambda: ca.Function("M", [eom.q, eom.t, eom.p], [eom.M]))
        M = np.array(fM(q0, 0.0, pv), float)
        d = 1.0 / np.sqrt(np.abs(np.diag(M)) + 1e-300)
        ev = np.linalg.eigvalsh(d[:, None] * M * d[None, :])
    except Exception:  # noqa: BLE001 - cannot judge: the route that needs no assumption
        return "mx"
    return "schur" if np.all(np.isfinite(ev)) and ev[0] > SCHUR_MIN_RCOND * ev[-1] else "mx"


def equilibrated_kkt(M, G, rhs_q, rhs_c):
    """The equilibrated augmented system: (K, b, d, s) with
    [[D M D, D G^T S], [S G D, 0]] [y; mu] = [D rhs_q; S rhs_c],  q'' = D y,  lambda = S mu."""
    ca = _sx()
    m = G.shape[0]
    d = 1.0 / ca.sqrt(ca.fabs(ca.diag(M)) + 1e-300)
    D = ca.diag(d)
    Ms = ca.mtimes([D, M, D])
    GD = ca.mtimes(G, D)
    s = 1.0 / ca.sqrt(ca.sum2(GD * GD) + 1e-300)
    Gs = ca.mtimes(ca.diag(s), GD)
    K = ca.blockcat([[Ms, Gs.T], [Gs, ca.SX.zeros(m, m)]])
    b = ca.vertcat(d * rhs_q, s * rhs_c)
    return K, b, d, s


def equilibrated_kkt_solve(M, G, rhs_q, rhs_c):
    """Symbolic solve of [[M, G^T], [G, 0]] [x; y] = [rhs_q; rhs_c] with equilibration."""
    ca = _sx()
    n = M.shape[0]
    K, b, d, s = equilibrated_kkt(M, G, rhs_q, rhs_c)
    x = ca.solve(K, b)
    return d * x[:n, 0], s * x[n:, 0]          # 2-d slices: x[n:] of a column is 1x0 when m = 0


SYSTEM_FIELDS = ("q", "qd", "t", "p", "M", "bias", "g")     # what ConstrainedSystem._build reads

@dataclass
class ConstrainedSystem:
    """Symbolic and compiled pieces of an EOM with constraints, for numeric parameters p."""

    eom: EOM
    p: np.ndarray
    active: tuple[int, ...]
    sym: dict = field(default_factory=dict)
    fn: dict = field(default_factory=dict)
    row_scale: np.ndarray | None = None     # fixed constraint-row scaling (see fix_row_scale)
    route: str = "sx"                       # 'sx' symbolic KKT solve | 'schur' SX Cholesky + Schur | 'mx' numeric QR

    fast: dict = field(default_factory=dict)   # buffer-call wrappers of fn entries (codegen.FastFunction)

    # -- construction -------------------------------------------------------------------
    @staticmethod
    def build(eom: EOM, p: np.ndarray | None = None, active: tuple[int, ...] | None = None) -> "ConstrainedSystem":
        """The system for these parameter values.  The symbolic pieces and Functions do not
        depend on p (it is an input): they are built once per (EOM, active set) and shared."""
        if eom.g is None:
            raise ValueError("ConstrainedSystem needs an EOM with constraints (eom.g)")
        pv = eom.param_values if p is None else np.asarray(p, float)
        active = tuple(range(eom.m)) if active is None else tuple(active)
        route = eom.workspace.memo(("kkt_route", len(active), pv.tobytes(), SX_KKT_MAX, SCHUR_MAX_N),
                           lambda: _kkt_route(eom, pv, len(active)))
        # the active set and the linear-algebra route; shared with EOM.replace copies of the
        # same equations (not with Drive.close_eom's, whose M, bias and g read the signals)
        base = eom.workspace.by_content(eom, SYSTEM_FIELDS, ("constrained_system", active, route),
                                        lambda: ConstrainedSystem._build(eom, pv, active, route))
        return ConstrainedSystem(eom=eom, p=pv, active=active, sym=base.sym, fn=base.fn, route=base.route,
                                 fast=base.fast)

    @staticmethod
    def _build(eom: EOM, pv: np.ndarray, active: tuple[int, ...], route: str) -> "ConstrainedSystem":
        ca = _sx()
        q, qd, t, pp = eom.q, eom.qd, eom.t, eom.p
        g_all = eom.g
        g = g_all[list(active)] if active else ca.SX.zeros(0, 1)
        G = ca.jacobian(g, q)
        gt = ca.jacobian(g, t)
        gdot = ca.mtimes(G, qd) + gt
        gamma = -(ca.jtimes(gdot, q, qd) + ca.jacobian(gdot, t))
        G_all = ca.jacobian(g_all, q)
        gdot_all = ca.mtimes(G_all, qd) + ca.jacobian(g_all, t)
        alpha = ca.SX.sym("alpha")
        beta = ca.SX.sym("beta")
        M = eom.M
        bias = eom.bias
        rhs_c = gamma - 2 * alpha * gdot - beta**2 * g
        n, m = eom.n, len(active)
        if route in ("sx", "schur"):
            solve = equilibrated_kkt_solve if route == "sx" else schur_kkt_solve
            qdd, lam = solve(M, G, bias, rhs_c)
            accel = ca.Function("accel", [q, qd, t, pp, alpha, beta], [qdd, lam])
        else:
            # numeric sparse QR at every call (an MX Function around the SX pieces): symbolic
            # elimination grows as (n + m)^3 and loses accuracy with size
            parts = ca.Function("kkt", [q, qd, t, pp, alpha, beta], list(equilibrated_kkt(M, G, bias, rhs_c)))
            Q, QD, TT, P, A, B = (ca.MX.sym(k, *x.shape) for k, x in
                                  (("q", q), ("qd", qd), ("t", t), ("p", pp), ("alpha", alpha), ("beta", beta)))
            K, b, d, sc = parts(Q, QD, TT, P, A, B)
            x = ca.solve(K, b, "qr")
            accel = ca.Function("accel", [Q, QD, TT, P, A, B], [d * x[:n, 0], sc * x[n:, 0]])
            qdd = lam = None
        sym = dict(q=q, qd=qd, t=t, p=pp, g=g, G=G, gt=gt, gdot=gdot, gamma=gamma, M=M, bias=bias,
                   alpha=alpha, beta=beta, qdd=qdd, lam=lam, g_all=g_all, G_all=G_all, gdot_all=gdot_all)
        fn = {
            "g": ca.Function("g", [q, t, pp], [g]),
            "G": ca.Function("G", [q, t, pp], [G]),
            "gt": ca.Function("gt", [q, t, pp], [gt]),
            "geometry": ca.Function("geometry", [q, t, pp], [g, G, gt]),
            "gdot": ca.Function("gdot", [q, qd, t, pp], [gdot]),
            "M": ca.Function("M", [q, t, pp], [M]),
            "accel": accel,
            "drift_all": ca.Function("drift_all", [q, qd, t, pp], [g_all, gdot_all]),
            "G_all": ca.Function("G_all", [q, t, pp], [G_all]),
            "monitor": ca.Function("monitor", [q, qd, t, pp], [g_all, gdot_all, G, ca.diag(M)]),
        }
        fn["ode_jac"] = None      # built on first use (_jac): seconds for a large model on the MX route
        return ConstrainedSystem(eom=eom, p=pv, active=active, sym=sym, fn=fn, route=route)

    def symbols(self):
        """Fresh symbols (q, qd, t, p) of the kind the accelerations are built on (SX or MX)."""
        ca = _sx()
        Sym = ca.SX if self.route in ("sx", "schur") else ca.MX
        n = self.n
        return Sym.sym("q", n), Sym.sym("qd", n), Sym.sym("t"), Sym.sym("p", self.eom.p.numel())

    # -- sizes and names ------------------------------------------------------------------
    @property
    def n(self) -> int:
        return self.eom.n

    @property
    def m(self) -> int:
        return len(self.active)

    @property
    def names(self) -> tuple[str, ...]:
        return tuple(self.eom.constraint_names[i] for i in self.active)

    # -- numeric helpers (numpy in, numpy out) ---------------------------------------------
    def g(self, q, t) -> np.ndarray:
        return np.array(self.fn["g"](q, t, self.p), float).ravel()

    def G(self, q, t) -> np.ndarray:
        return np.array(self.fn["G"](q, t, self.p), float).reshape(self.m, self.n)

    def geometry(self, q, t) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(g, G, g_t) of the active constraints in one (buffer) call."""
        g, G, gt = self._call_fast("geometry", q, t, self.p)
        return np.ravel(g).copy(), np.asarray(G, float).reshape(self.m, self.n).copy(), np.ravel(gt).copy()

    def gdot(self, q, qd, t) -> np.ndarray:
        return np.array(self.fn["gdot"](q, qd, t, self.p), float).ravel()

    def M(self, q, t) -> np.ndarray:
        return np.array(self.fn["M"](q, t, self.p), float).reshape(self.n, self.n)

    def accel(self, q, qd, t, alpha=0.0, beta=0.0) -> tuple[np.ndarray, np.ndarray]:
        a, lam = self.fn["accel"](q, qd, t, self.p, alpha, beta)
        return np.array(a, float).ravel(), np.array(lam, float).ravel()

    def drift(self, q, qd, t) -> tuple[float, float]:
        """(||g||_inf, ||G q' + g_t||_inf) over *all* constraints (dropped redundant ones too)."""
        g, gd = self._call_fast("drift_all", q, qd, t, self.p)
        g = np.ravel(g)
        gd = np.ravel(gd)
        return (float(np.max(np.abs(g))) if g.size else 0.0, float(np.max(np.abs(gd))) if gd.size else 0.0)

    def shared(self, key, build):
        """An object built once per (EOM, active set) and kept for later runs (e.g. the CasADi
        integrators of a formulation, which cost ~0.5 ms each to build)."""
        obj = self.fast.get(("shared", key))
        if obj is None:
            obj = self.fast[("shared", key)] = build()
        return obj

    def _call_fast(self, name: str, *args):
        """Evaluate fn[name] through Function.buffer (the driver calls these at every check)."""
        f = self.fast.get(name)
        if f is None:
            f = self.fast[name] = FastFunction(self.fn[name])
        out = f(*args)
        return out if isinstance(out, tuple) else (out,)

    def monitor(self, q, qd, t) -> tuple[float, float, np.ndarray]:
        """One evaluation for the driver's checks: (||g||_inf, ||G q' + g_t||_inf) over all
        constraints, and the scaled Jacobian of the active ones (as :meth:`scaled_G`)."""
        g, gd, G, dM = self._call_fast("monitor", q, qd, t, self.p)
        g = np.ravel(g)
        gd = np.ravel(gd)
        G = np.asarray(G, float).reshape(self.m, self.n)
        d = 1.0 / np.sqrt(np.maximum(np.abs(np.ravel(dM)), 1e-300))
        GD = G * d[None, :]
        if self.row_scale is None:
            norms = np.linalg.norm(GD, axis=1)
            Gs = GD / np.where(norms > 0, norms, 1.0)[:, None]
        else:
            Gs = GD * self.row_scale[:, None]
        return (float(np.max(np.abs(g))) if g.size else 0.0, float(np.max(np.abs(gd))) if gd.size else 0.0, Gs)

    def _mapped(self, name: str, K: int):
        key = f"{name}_map_{K}"
        f = self.fast.get(key)
        if f is None:
            f = self.fast[key] = FastFunction(self.fn[name].map(K))
        return f

    def drift_many(self, Q: np.ndarray, QD: np.ndarray, T: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`drift` at K states (columns of Q, QD) in one mapped call: arrays (K,), (K,)."""
        K = len(T)
        P = np.repeat(np.asarray(self.p, float).reshape(-1, 1), K, axis=1)
        g, gd = self._mapped("drift_all", K)(np.asarray(Q, float), np.asarray(QD, float),
                                              np.asarray(T, float).reshape(1, K), P)
        g = np.asarray(g, float).reshape(-1, K)
        gd = np.asarray(gd, float).reshape(-1, K)
        return (np.max(np.abs(g), axis=0) if g.size else np.zeros(K),
                np.max(np.abs(gd), axis=0) if gd.size else np.zeros(K))

    def monitor_many(self, Q: np.ndarray, QD: np.ndarray, T: np.ndarray):
        """:meth:`monitor` at K states at once (one mapped CasADi call): arrays d (K,), v (K,)
        and the scaled Jacobians (K, m, n)."""
        K = len(T)
        f = self._mapped("monitor", K)
        P = np.repeat(np.asarray(self.p, float).reshape(-1, 1), K, axis=1)
        g, gd, G, dM = f(np.asarray(Q, float).T, np.asarray(QD, float).T, np.asarray(T, float).reshape(1, K), P)
        g = np.asarray(g, float).reshape(-1, K)
        gd = np.asarray(gd, float).reshape(-1, K)
        d_ = np.max(np.abs(g), axis=0) if g.size else np.zeros(K)
        v_ = np.max(np.abs(gd), axis=0) if gd.size else np.zeros(K)
        m, n = self.m, self.n
        Gk = np.asarray(G, float).reshape(m, n, K, order="F").transpose(2, 0, 1) if m else np.zeros((K, 0, n))
        dinv = 1.0 / np.sqrt(np.maximum(np.abs(np.asarray(dM, float).reshape(n, K)), 1e-300))   # (n, K)
        GD = Gk * dinv.T[:, None, :]
        if self.row_scale is None:
            norms = np.linalg.norm(GD, axis=2)
            Gs = GD / np.where(norms > 0, norms, 1.0)[:, :, None]
        else:
            Gs = GD * self.row_scale[None, :, None]
        return d_, v_, Gs

    def fix_row_scale(self, q, t) -> None:
        """Freeze the constraint-row scaling at (q, t) (normally the start).

        Rows normalized afresh at every state would hide a singular configuration in which
        a constraint's gradient itself vanishes (the parallelogram four-bar at its flat
        position: one row of G goes to zero); with the scaling frozen it shows."""
        M = self.M(q, t)
        GD = self.G(q, t) / np.sqrt(np.maximum(np.abs(np.diag(M)), 1e-300))[None, :]
        norms = np.linalg.norm(GD, axis=1)
        self.row_scale = 1.0 / np.where(norms > 0, norms, 1.0)

    def scaled_G(self, q, t) -> np.ndarray:
        """S G D: coordinates scaled by the mass metric, constraint rows scaled by the frozen
        row scaling (or normalized at (q, t) if none was frozen)."""
        if self.row_scale is None:
            return scale_jacobian(self.G(q, t), self.M(q, t))
        M = self.M(q, t)
        GD = self.G(q, t) / np.sqrt(np.maximum(np.abs(np.diag(M)), 1e-300))[None, :]
        return GD * self.row_scale[:, None]

    def _jac(self):
        if self.fn["ode_jac"] is None:
            s = self.sym
            self.fn["ode_jac"] = _ode_jacobian(self.fn["accel"], self.route, s["q"], s["qd"], s["t"], s["p"])
        return self.fn["ode_jac"]

    def _jac_at(self, q, qd, t) -> np.ndarray | None:
        """The index-1 ODE's Jacobian at a state, None where it cannot be evaluated: its linear
        solve fails on a singular KKT matrix (andrews.mech with m3 = -1e12 raised CasADi's
        "Evaluation failed" from the method choice, exit 3), or it is not finite."""
        try:
            J = np.array(self._jac()(q, qd, t, self.p), float)
        except RuntimeError as e:
            if "KeyboardInterrupt" in str(e):       # CasADi took a Ctrl-C: give it back (stepper.call_integrator)
                raise KeyboardInterrupt from None
            return None
        return J if J.size and np.all(np.isfinite(J)) else None

    def eigenvalues(self, q, qd, t) -> np.ndarray:
        """Eigenvalues of the Jacobian (none where it cannot be evaluated: the callers' estimates
        then fall back to their defaults, and the run itself meets the problem and says so)."""
        J = self._jac_at(q, qd, t)
        return np.zeros(0) if J is None else np.linalg.eigvals(J)

    def spectral_radius(self, q, qd, t) -> float:
        """Largest |eigenvalue| of the unstabilized index-1 ODE's Jacobian (a rate, 1/s)."""
        J = self._jac_at(q, qd, t)
        return 0.0 if J is None else float(np.max(np.abs(np.linalg.eigvals(J))))


def _ode_jacobian(accel, route, q, qd, t, pp):
    """Function (q, qd, t, p) -> d(qd, qdd)/d(q, qd) of the unstabilized index-1 ODE."""
    ca = _sx()
    if route in ("sx", "schur"):
        Q, QD, T, P = q, qd, t, pp
    else:
        Q, QD, T, P = ca.MX.sym("q", q.numel()), ca.MX.sym("qd", qd.numel()), ca.MX.sym("t"), ca.MX.sym("p", pp.numel())
    a, _ = accel(Q, QD, T, P, 0, 0)
    return ca.Function("ode_jac", [Q, QD, T, P], [ca.jacobian(ca.vertcat(QD, a), ca.vertcat(Q, QD))])


def scale_jacobian(G: np.ndarray, M: np.ndarray | None) -> np.ndarray:
    """Row-normalized G D with D = diag(M)^(-1/2): unit-independent for rank decisions."""
    G = np.asarray(G, float)
    if M is not None:
        d = 1.0 / np.sqrt(np.maximum(np.abs(np.diag(M)), 1e-300))
        G = G * d[None, :]
    norms = np.linalg.norm(G, axis=1)
    norms[norms == 0] = 1.0
    return G / norms[:, None]


def kkt_solve(M: np.ndarray, G: np.ndarray, r1: np.ndarray, r2: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Numeric solve of [[M, G^T], [G, 0]] [x; y] = [r1; r2], equilibrated as the symbolic one.

    Falls back to least squares (minimum norm) when the matrix is singular (redundant or
    singular constraints)."""
    n, m = M.shape[0], G.shape[0]
    d = 1.0 / np.sqrt(np.maximum(np.abs(np.diag(M)), 1e-300))
    GD = G * d[None, :]
    s = 1.0 / np.sqrt(np.sum(GD * GD, axis=1) + 1e-300)
    K = np.zeros((n + m, n + m))
    K[:n, :n] = M * d[:, None] * d[None, :]
    K[:n, n:] = (GD * s[:, None]).T
    K[n:, :n] = GD * s[:, None]
    b = np.concatenate([d * r1, s * r2])
    try:
        x = np.linalg.solve(K, b)
        if not np.all(np.isfinite(x)):
            raise np.linalg.LinAlgError
    except np.linalg.LinAlgError:
        x = np.linalg.lstsq(K, b, rcond=1e-13)[0]
    return d * x[:n], s * x[n:]
