"""RATTLE: the Stormer-Verlet method for constrained Hamiltonian systems.

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


def consistent_start(eom, x0, q0, qd0, t0, pv):
    """(q, qd, InitReport, active constraint indices, DofReport) at the start: the DAE's
    consistent initialization (overridden values count as fixed) and its choice of
    independent constraints."""
    from .dae import dof_report, initialize
    from .simulation.inputs import fixed_start

    if q0 is not None or qd0 is not None:
        a, b = eom.start(pv)
        a = a if q0 is None else np.asarray(q0, float).ravel()
        b = b if qd0 is None else np.asarray(qd0, float).ravel()
        x0 = np.concatenate([a, b])
    qs, qds, fq, fqd = fixed_start(eom, x0, pv)
    init = initialize(eom, qs, qds, t0, pv, fixed_q=fq, fixed_qd=fqd)
    dof = dof_report(eom, init.q, t0, pv)
    return init.q, init.qd, init, tuple(dof.independent), dof


def constrained_signals(eom, active, t, q, qd, pv, outputs) -> tuple[dict, dict]:
    """Signals of a constrained run as the DAE simulator records them (outputs, energies,
    residuals, drift, multipliers from the consistent state when an output needs them);
    returns (signals, drift statistics)."""
    from .dae.record import constrained_signals as record_signals, multipliers, select_signals
    from .dae.system import ConstrainedSystem

    chosen, need_lam = select_signals(eom, outputs, False)
    LAM = multipliers(ConstrainedSystem.build(eom, pv, active), t, q, qd) if need_lam else None
    sig = record_signals(eom, chosen, t, q, qd, LAM, pv)
    stats = {"max_constraint_drift": float(np.max(sig.get("constraint_drift", [0.0]), initial=0.0)),
             "max_velocity_drift": float(np.max(sig.get("velocity_drift", [0.0]), initial=0.0))}
    return sig, stats
