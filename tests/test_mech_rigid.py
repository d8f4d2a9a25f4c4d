"""Torque-free asymmetric rigid body on a spherical joint at its centre of mass, in Euler
angles and in quaternions, against Euler's equations I w' + w x I w = 0."""
from __future__ import annotations

import casadi as ca
import numpy as np
import pytest
from scipy.integrate import solve_ivp

from mech_models import coord_var, mat, point, v3
from mechdsl.model import ir
from mechdsl.model.exprs import const
from mechdsl.mechanics import derive

I_BODY = np.array([[1.0, 0.1, -0.05], [0.1, 2.0, 0.2], [-0.05, 0.2, 3.0]])


def body_model(par="euler", seq="zyx", free=False):
    roles = ("q0", "q1", "q2", "q3") if par == "quaternion" else ("phi", "theta", "psi")
    if free:
        roles = ("x", "y", "z") + roles
    coords = tuple(ir.Coordinate(f"j.{r}", start=const(1.0 if r == "q0" else 0.0)) for r in roles)
    body = ir.Body("B", "rigid", mass=const(2.5), com=v3(0.1, 0.2, 0.3), inertia=mat(I_BODY.tolist()))
    return ir.Model(
        "TorqueFree", coordinates=coords, bodies=(body,),
        points=(point("world", "world"), point("B", "B"), point("B.c", "B", (0.1, 0.2, 0.3))),
        joints=(ir.Joint("j", "free" if free else "spherical", "world", "B.c", "world", "B",
                         variables=tuple(coord_var(r, f"j.{r}") for r in roles),
                         options=(("parametrization", par), ("sequence", seq))),),
        forces=(ir.Gravity("g", v3(0, -9.81, 0)),) if free else (),
        outputs=tuple(ir.Output(f"R{i}{j}", ir.BodyRot("B", i, j)) for i in range(3) for j in range(3)))


def omega_zyx(q, qd):
    phi, th, psi = q
    dphi, dth, dpsi = qd
    return np.array([dpsi - dphi * np.sin(th),
                     dth * np.cos(psi) + dphi * np.cos(th) * np.sin(psi),
                     -dth * np.sin(psi) + dphi * np.cos(th) * np.cos(psi)])


def qmul(a, b):
    a0, av, b0, bv = a[0], a[1:], b[0], b[1:]
    return np.concatenate([[a0 * b0 - av @ bv], a0 * bv + b0 * av + np.cross(av, bv)])


def conj(a):
    return np.concatenate([[a[0]], -a[1:]])


def euler_residual(w, wd):
    return I_BODY @ wd + np.cross(w, I_BODY @ w)


def test_euler_angles_satisfy_euler_equations():
    e = derive(body_model("euler"))
    f = ca.Function("f", [e.q, e.qd, e.p], [e.qdd])
    rng = np.random.default_rng(1)
    h = 1e-6
    for _ in range(5):
        q = rng.uniform(-1.2, 1.2, 3)
        qd = rng.uniform(-2, 2, 3)
        qdd = np.array(f(q, qd, e.param_values)).ravel()
        w = omega_zyx(q, qd)
        # w' by central differences along the trajectory direction (q', q'') of the hand formula
        wd = (omega_zyx(q + h * qd + 0.5 * h * h * qdd, qd + h * qdd)
              - omega_zyx(q - h * qd + 0.5 * h * h * qdd, qd - h * qdd)) / (2 * h)
        assert np.abs(euler_residual(w, wd)).max() < 1e-7


def test_quaternions_satisfy_euler_equations_and_keep_the_norm():
    e = derive(body_model("quaternion"))
    f = ca.Function("f", [e.q, e.qd, e.p], [e.qdd])
    rng = np.random.default_rng(2)
    for _ in range(5):
        q = rng.normal(size=4)
        q /= np.linalg.norm(q)
        w = rng.uniform(-2, 2, 3)
        qd = 0.5 * qmul(q, np.concatenate([[0.0], w]))
        qdd = np.array(f(q, qd, e.param_values)).ravel()
        wd = 2 * qmul(conj(q), qdd)[1:] + 2 * qmul(conj(qd), qd)[1:]
        assert np.abs(euler_residual(w, wd)).max() < 1e-12
        assert q @ qdd == pytest.approx(-(qd @ qd), abs=1e-12)      # d/dt (q . q') = 0


def _simulate(e, x0, t_end, t_eval):
    f = ca.Function("f", [e.q, e.qd, e.p], [e.qdd])
    n = e.n

    def rhs(t, x):
        return np.concatenate([x[n:], np.array(f(x[:n], x[n:], e.param_values)).ravel()])

    return solve_ivp(rhs, (0, t_end), x0, t_eval=t_eval, rtol=1e-11, atol=1e-12, method="DOP853")


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
def test_three_integrations_agree():
    """R(t) of Euler's equations + R' = R [w] (reference), of the Euler-angle EOM and of the
    quaternion EOM agree; the quaternion norm drift stays tiny; energy is conserved."""
    w0 = np.array([0.3, 1.1, -0.4])
    t_eval = np.linspace(0, 3, 7)

    def ref_rhs(t, x):
        w, R = x[:3], x[3:].reshape(3, 3)
        wd = np.linalg.solve(I_BODY, -np.cross(w, I_BODY @ w))
        S = np.array([[0, -w[2], w[1]], [w[2], 0, -w[0]], [-w[1], w[0], 0]])
        return np.concatenate([wd, (R @ S).ravel()])

    ref = solve_ivp(ref_rhs, (0, 3), np.concatenate([w0, np.eye(3).ravel()]), t_eval=t_eval,
                    rtol=1e-11, atol=1e-12, method="DOP853")
    # Euler angles zyx start at 0 (far from gimbal lock): qd0 from w0 (S = I at 0 for zyx: w = (psi', theta', phi'))
    ee = derive(body_model("euler"))
    se = _simulate(ee, np.concatenate([[0, 0, 0], [w0[2], w0[1], w0[0]]]), 3, t_eval)
    eq = derive(body_model("quaternion"))
    sq = _simulate(eq, np.concatenate([[1, 0, 0, 0], 0.5 * np.concatenate([[0], w0])]), 3, t_eval)
    rot_e = ca.Function("R", [ee.q], [_rot(ee)])
    rot_q = ca.Function("R", [eq.q], [_rot(eq)])
    norm_q = ca.Function("n", [eq.q], [eq.invariants["j.quaternion_norm"]])
    E = ca.Function("E", [eq.q, eq.qd, eq.p], [eq.T + eq.V])
    E0 = float(E(sq.y[:4, 0], sq.y[4:, 0], eq.param_values))
    for k in range(len(t_eval)):
        Rref = ref.y[3:, k].reshape(3, 3)
        R1 = np.array(rot_e(se.y[:3, k])).reshape(3, 3)
        R2 = np.array(rot_q(sq.y[:4, k])).reshape(3, 3)
        assert np.abs(R1 - Rref).max() < 1e-8
        assert np.abs(R2 - Rref).max() < 1e-8
        assert abs(float(norm_q(sq.y[:4, k]))) < 1e-9
        assert float(E(sq.y[:4, k], sq.y[4:, k], eq.param_values)) == pytest.approx(E0, rel=1e-9)


def _rot(e):
    """The body rotation from the BodyRot outputs, row-major (9,)."""
    return ca.vertcat(*[e.outputs[f"R{i}{j}"] for i in range(3) for j in range(3)])


def test_free_body_falls_with_gravity():
    for par in ("euler", "quaternion"):
        e = derive(body_model(par, free=True))
        f = ca.Function("f", [e.q, e.qd, e.p], [e.qdd])
        rng = np.random.default_rng(3)
        q = rng.uniform(-1, 1, e.n)
        qd = rng.uniform(-1, 1, e.n)
        if par == "quaternion":
            q[3:] /= np.linalg.norm(q[3:])
            qd[3:] -= q[3:] * (q[3:] @ qd[3:])
        a = np.array(f(q, qd, e.param_values)).ravel()
        # the child point is the centre of mass and x, y, z are its position: it falls freely
        assert np.allclose(a[:3], [0, -9.81, 0], atol=1e-12)
