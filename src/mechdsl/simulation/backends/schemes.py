"""The step functions of the fixed-step back end (fixed_step.py), as CasADi Functions
(state, h, p) -> (next state, residual): Stormer-Verlet (explicit or generalized),
implicit midpoint, 2-stage Gauss-Legendre and rk4 in canonical variables (``step_function``),
and RATTLE for constrained models (``rattle_step``).

RATTLE: the Stormer-Verlet method for constrained Hamiltonian systems.

    q' = H_p(q, p, t),   p' = -H_q(q, p, t) + Q_nc - G(q, t)^T lambda,   g(q, t) = 0

(H from mechdsl.analysis.hamilton: the Hamiltonian of the unconstrained Lagrangian; the
multipliers lambda are those of the DAE, M q'' = bias - G^T lambda).  One step (Hairer,
Lubich, Wanner, GNI, VII.1.4, the form for general H), with F = -H_q + Q_nc and v = H_p:

    p_1/2 = p_n + h/2 (F(q_n, p_1/2, t_n) - G(q_n)^T lambda)
    q_n+1 = q_n + h/2 (v(q_n, p_1/2, t_n) + v(q_n+1, p_1/2, t_n+1))
    0     = g(q_n+1, t_n+1)                                      (position projection)
    p_n+1 = p_1/2 + h/2 (F(q_n+1, p_1/2, t_n+1) - G(q_n+1)^T mu)
    0     = G(q_n+1) v(q_n+1, p_n+1, t_n+1) + g_t(q_n+1, t_n+1)  (velocity projection)

Symplectic on the constraint manifold and of order 2 for conservative autonomous systems;
for separable H (constant M) it is the classical explicit-looking RATTLE, whose only
nonlinear equations are the m position constraints.  Both stages are solved by CasADi's
Newton rootfinder on SX residuals (Jacobians by AD); the state carries the last lambda as
the predictor of the next.  Only the independent (active) constraints enter, chosen at the
consistent start by ``mechdsl.dae.dof_report`` (redundant rows dropped).
"""
from __future__ import annotations

import math
import types

import numpy as np


def rattle_step(ham, eom, active, tol: float, max_newton: int):
    """(Function (X, h, p) -> (X_next, residual)) with X = (q, p, t, lambda_active)."""
    import casadi as ca

    n = eom.n
    m = len(active)
    q, pm, t, p = ham.q, ham.pm, ham.t, ham.p
    g = ca.SX(eom.g)[list(active)]
    G = ca.jacobian(g, eom.q)
    gt = ca.jacobian(g, eom.t)
    rhs = ca.Function("f", [q, pm, t, p], [ham.qd_of_p, ham.pdot])
    con = ca.Function("con", [eom.q, eom.t, eom.p], [g, G, gt])

    Sq, Sp, St, Sh = ca.SX.sym("Sq", n), ca.SX.sym("Sp", n), ca.SX.sym("St"), ca.SX.sym("Sh")
    Sps = ca.SX.sym("Sps", p.numel())
    Y1 = ca.SX.sym("Y1", 2 * n + m)                        # (p_half, q1, lambda)
    ph, q1, lam = Y1[:n], Y1[n:2 * n], Y1[2 * n:]
    v0, F0 = rhs(Sq, ph, St, Sps)
    v1, _ = rhs(q1, ph, St + Sh, Sps)
    _, G0, _ = con(Sq, St, Sps)
    g1, _, _ = con(q1, St + Sh, Sps)
    R1 = ca.vertcat(ph - Sp - 0.5 * Sh * (F0 - ca.mtimes(G0.T, lam)),
                    q1 - Sq - 0.5 * Sh * (v0 + v1),
                    g1)
    Y2 = ca.SX.sym("Y2", n + m)                            # (p1, mu)
    p1, mu = Y2[:n], Y2[n:]
    _, Fh = rhs(Sq, Sp, St + Sh, Sps)                      # here Sq = q1, Sp = p_half
    _, G1, gt1 = con(Sq, St + Sh, Sps)
    v11, _ = rhs(Sq, p1, St + Sh, Sps)
    R2 = ca.vertcat(p1 - Sp - 0.5 * Sh * (Fh - ca.mtimes(G1.T, mu)),
                    ca.mtimes(G1, v11) + gt1)
    E1 = ca.Function("E1", [Y1, Sq, Sp, St, Sh, Sps], [R1])
    E2 = ca.Function("E2", [Y2, Sq, Sp, St, Sh, Sps], [R2])
    opts = {"abstol": tol, "abstolStep": tol, "max_iter": max_newton, "error_on_fail": False}
    rf1 = ca.rootfinder("rattle_pos", "newton", E1, opts)
    rf2 = ca.rootfinder("rattle_vel", "newton", E2, opts)

    X = ca.MX.sym("X", 2 * n + 1 + m)
    h = ca.MX.sym("h")
    ps = ca.MX.sym("p", p.numel())
    qn, pn, tn, ln = X[:n], X[n:2 * n], X[2 * n], X[2 * n + 1:]
    _, Gn, _ = con(qn, tn, ps)
    vn, Fn = rhs(qn, pn, tn, ps)
    ph0 = pn + 0.5 * h * (Fn - ca.mtimes(Gn.T, ln))
    q10 = qn + h * rhs(qn, ph0, tn, ps)[0]
    y1 = rf1(ca.vertcat(ph0, q10, ln), qn, pn, tn, h, ps)
    phs, q1s, lams = y1[:n], y1[n:2 * n], y1[2 * n:]
    _, Fh0 = rhs(q1s, phs, tn + h, ps)
    y2 = rf2(ca.vertcat(phs + 0.5 * h * Fh0, lams), q1s, phs, tn, h, ps)
    r = ca.vertcat(E1(y1, qn, pn, tn, h, ps), E2(y2, q1s, phs, tn, h, ps))
    step = ca.Function("rattle", [X, h, ps], [ca.vertcat(q1s, y2[:n], tn + h, lams), ca.norm_inf(r)])
    return step


def step_function(ham, method, explicit_sv, n, tol, max_newton, q0, pm0, t0, pv, hold=False):
    """(Function (state, h, p) -> (state_next, residual), initial state, evals a step, initial evals).

    hold: the last parameter is the zero-order holds' time, set to the step's midpoint t_n + h/2
    for every stage of the step (the value passed in is ignored)."""
    sc = _Scheme(ham, n, hold, method in ("rk4",) or explicit_sv)
    if explicit_sv:
        return sc.explicit_sv(q0, pm0, t0, pv)
    if method == "rk4":
        return sc.rk4(q0, pm0, t0)
    c = sc.implicit(tol, max_newton)
    build = {"stormer-verlet": _stormer_verlet, "implicit-midpoint": _implicit_midpoint}.get(method, _gauss_legendre)
    return build(sc, c), np.concatenate([q0, pm0, [t0]]), None, 0


class _Scheme:
    """The canonical right-hand side of ``ham`` as the step functions call it: ``rhs(q, p, t,
    params)`` -> (q', p'), where with ``hold`` the parameters' last entry (the zero-order holds'
    time) is the step's midpoint (``holding``)."""

    def __init__(self, ham, n, hold, explicit):
        import casadi as ca

        self.ham, self.n, self.hold = ham, n, hold
        self.rhs0 = ca.Function("f", [ham.q, ham.pm, ham.t, ham.p], [ham.qd_of_p, ham.pdot])
        self.held = {}                      # id(parameter symbol) -> its value in the step
        self.h = ca.SX.sym("h") if explicit else ca.MX.sym("h")

    def rhs(self, qq, pp, tt, pps):
        return self.rhs0(qq, pp, tt, self.held.get(id(pps), pps))

    def holding(self, pps, tt, hh):
        """The parameters of a step from tt of size hh: the hold time at its midpoint."""
        import casadi as ca

        if self.hold:
            self.held[id(pps)] = ca.vertcat(pps[:-1], tt + 0.5 * hh)
        return pps

    def explicit_sv(self, q0, pm0, t0, pv):
        """Stormer-Verlet for a separable H: the force at the step's end carried to the next step."""
        import casadi as ca

        ham, n, h = self.ham, self.n, self.h
        q, pm, t, p = ham.q, ham.pm, ham.t, ham.p
        force0 = ca.Function("force", [q, t, p], [ca.substitute(ham.pdot, pm, ca.SX.zeros(n))])
        vel = ca.Function("vel", [pm, p], [ca.substitute(ham.qd_of_p, q, ca.SX.zeros(n))])

        def force(qq, tt, pps):
            return force0(qq, tt, self.held.get(id(pps), pps))
        X = ca.SX.sym("X", 2 * n + 1 + n)
        qn, pn, tn, Fn = X[:n], X[n:2 * n], X[2 * n], X[2 * n + 1:]
        ps = self.holding(ca.SX.sym("p", p.numel()), tn, h)
        if self.hold:                   # the force carried from the last step read the last step's hold
            Fn = force(qn, tn, ps)
        ph = pn + 0.5 * h * Fn
        q1 = qn + h * vel(ph, ps)
        F1 = force(q1, tn + h, ps)
        p1 = ph + 0.5 * h * F1
        step = ca.Function("sv", [X, h, ps], [ca.vertcat(q1, p1, tn + h, F1), ca.SX(0)])
        F0 = np.array(force0(q0, t0, pv), float).ravel()
        return step, np.concatenate([q0, pm0, [t0], F0]), 2 if self.hold else 1, 1

    def rk4(self, q0, pm0, t0):
        import casadi as ca

        n, h = self.n, self.h
        X = ca.SX.sym("X", 2 * n + 1)
        qn, pn, tn = X[:n], X[n:2 * n], X[2 * n]
        ps = self.holding(ca.SX.sym("p", self.ham.p.numel()), tn, h)

        def f(qq, pp, tt):
            a, b = self.rhs(qq, pp, tt, ps)
            return a, b

        k1 = f(qn, pn, tn)
        k2 = f(qn + 0.5 * h * k1[0], pn + 0.5 * h * k1[1], tn + 0.5 * h)
        k3 = f(qn + 0.5 * h * k2[0], pn + 0.5 * h * k2[1], tn + 0.5 * h)
        k4 = f(qn + h * k3[0], pn + h * k3[1], tn + h)
        q1 = qn + h / 6 * (k1[0] + 2 * k2[0] + 2 * k3[0] + k4[0])
        p1 = pn + h / 6 * (k1[1] + 2 * k2[1] + 2 * k3[1] + k4[1])
        step = ca.Function("rk4", [X, h, ps], [ca.vertcat(q1, p1, tn + h), ca.SX(0)])
        return step, np.concatenate([q0, pm0, [t0]]), 4, 0

    def implicit(self, tol, max_newton):
        """The symbols of an implicit step: the MX step's state X = (q_n, p_n, t_n) and parameters
        ps, the SX residuals' arguments (Sq, Sp, St, Sh, Sps; unknowns zq, zp) with their
        right-hand side ``frhs``, and the Newton rootfinder's options."""
        import casadi as ca

        n = self.n
        c = types.SimpleNamespace(opts={"abstol": tol, "abstolStep": tol, "max_iter": max_newton,
                                        "error_on_fail": False})
        c.X = ca.MX.sym("X", 2 * n + 1)
        c.qn, c.pn, c.tn = c.X[:n], c.X[n:2 * n], c.X[2 * n]
        # residual functions in SX (Jacobians by AD), called from the MX step
        c.zq = ca.SX.sym("zq", n)
        c.zp = ca.SX.sym("zp", n)
        c.Sq, c.Sp, c.St, c.Sh = ca.SX.sym("Sq", n), ca.SX.sym("Sp", n), ca.SX.sym("St"), ca.SX.sym("Sh")
        c.ps = self.holding(ca.MX.sym("p", self.ham.p.numel()), c.tn, self.h)
        c.Sps = self.holding(ca.SX.sym("Sps", self.ham.p.numel()), c.St, c.Sh)
        c.frhs = lambda qq, pp, tt: self.rhs(qq, pp, tt, c.Sps)
        return c


def _stormer_verlet(sc: _Scheme, c):
    """The generalized (implicit) Stormer-Verlet step."""
    import casadi as ca

    h, rhs = sc.h, sc.rhs
    X, qn, pn, tn, ps, Sq, Sp, St, Sh, Sps, zq, zp = c.X, c.qn, c.pn, c.tn, c.ps, c.Sq, c.Sp, c.St, c.Sh, c.Sps, c.zq, c.zp
    a = c.frhs(Sq, zp, St)                                    # at (q_n, p_half, t_n)
    G1 = ca.Function("G1", [zp, Sq, Sp, St, Sh, Sps], [zp - Sp - 0.5 * Sh * a[1]])
    G2 = ca.Function("G2", [zq, Sq, Sp, St, Sh, Sps],
                     [zq - Sq - 0.5 * Sh * (c.frhs(Sq, Sp, St)[0] + c.frhs(zq, Sp, St + Sh)[0])])
    rf1 = ca.rootfinder("rf1", "newton", G1, c.opts)
    rf2 = ca.rootfinder("rf2", "newton", G2, c.opts)
    f0 = rhs(qn, pn, tn, ps)
    ph = rf1(pn + 0.5 * h * f0[1], qn, pn, tn, h, ps)
    q1 = rf2(qn + h * rhs(qn, ph, tn, ps)[0], qn, ph, tn, h, ps)
    p1 = ph + 0.5 * h * rhs(q1, ph, tn + h, ps)[1]
    r = ca.vertcat(G1(ph, qn, pn, tn, h, ps), G2(q1, qn, ph, tn, h, ps))
    return ca.Function("gsv", [X, h, ps], [ca.vertcat(q1, p1, tn + h), ca.norm_inf(r)])


def _implicit_midpoint(sc: _Scheme, c):
    import casadi as ca

    h, n = sc.h, sc.n
    X, qn, pn, tn, ps, Sq, Sp, St, Sh, Sps = c.X, c.qn, c.pn, c.tn, c.ps, c.Sq, c.Sp, c.St, c.Sh, c.Sps
    Y = ca.SX.sym("Y", 2 * n)
    fm = c.frhs(Y[:n], Y[n:], St + 0.5 * Sh)
    G = ca.Function("G", [Y, Sq, Sp, St, Sh, Sps],
                    [Y - ca.vertcat(Sq, Sp) - 0.5 * Sh * ca.vertcat(fm[0], fm[1])])
    rf = ca.rootfinder("rf", "newton", G, c.opts)
    f0 = sc.rhs(qn, pn, tn, ps)
    y0 = ca.vertcat(qn, pn)
    Ym = rf(y0 + 0.5 * h * ca.vertcat(f0[0], f0[1]), qn, pn, tn, h, ps)
    y1 = 2 * Ym - y0
    return ca.Function("imr", [X, h, ps], [ca.vertcat(y1, tn + h), ca.norm_inf(G(Ym, qn, pn, tn, h, ps))])


def _gauss_legendre(sc: _Scheme, c):
    """The 2-stage Gauss-Legendre step (order 4)."""
    import casadi as ca

    h, n = sc.h, sc.n
    X, qn, pn, tn, ps, Sq, Sp, St, Sh, Sps = c.X, c.qn, c.pn, c.tn, c.ps, c.Sq, c.Sp, c.St, c.Sh, c.Sps
    s3 = math.sqrt(3.0)
    A = [[0.25, 0.25 - s3 / 6], [0.25 + s3 / 6, 0.25]]
    cs = [0.5 - s3 / 6, 0.5 + s3 / 6]
    d = [-s3, s3]                        # b' A^-1: y1 = y0 + d1 Z1 + d2 Z2
    m2 = 2 * n
    Z = ca.SX.sym("Z", 2 * m2)
    y0s = ca.vertcat(Sq, Sp)
    fs = []
    for j in range(2):
        Yj = y0s + Z[j * m2:(j + 1) * m2]
        fj = c.frhs(Yj[:n], Yj[n:], St + cs[j] * Sh)
        fs.append(ca.vertcat(fj[0], fj[1]))
    res = ca.vertcat(*[Z[i * m2:(i + 1) * m2] - Sh * (A[i][0] * fs[0] + A[i][1] * fs[1]) for i in range(2)])
    G = ca.Function("G", [Z, Sq, Sp, St, Sh, Sps], [res])
    rf = ca.rootfinder("rf", "newton", G, c.opts)
    f0 = sc.rhs(qn, pn, tn, ps)
    f0v = ca.vertcat(f0[0], f0[1])
    Zs = rf(ca.vertcat(cs[0] * h * f0v, cs[1] * h * f0v), qn, pn, tn, h, ps)
    y1 = ca.vertcat(qn, pn) + d[0] * Zs[:m2] + d[1] * Zs[m2:]
    return ca.Function("gl2", [X, h, ps], [ca.vertcat(y1, tn + h), ca.norm_inf(G(Zs, qn, pn, tn, h, ps))])
