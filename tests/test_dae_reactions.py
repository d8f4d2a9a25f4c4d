"""Reaction forces of cut joints from the multipliers, checked against Newton-Euler by hand.

At recorded states the accelerations and the multipliers are put into the Newton-Euler
equations of every body (written out here, independently of Lagrange's equations): the
unknown joint forces are solved by least squares from all body equations; the system is
overdetermined by one, so a small residual checks the accelerations, and the force of the
cut joint must equal the multipliers (force on the child, in the child's joint frame)."""
import numpy as np
import pytest

from dae_models import crank_rocker_eom, slider_crank_eom
from mechdsl.dae import simulate_dae
from mechdsl.dae.constrained_system import ConstrainedSystem
from mechdsl.diagnostics import UsageError

G = 9.81


def e2(a):
    return np.array([np.cos(a), np.sin(a)])


def perp(a):
    return np.array([-np.sin(a), np.cos(a)])


def cross(r):
    """Row of the planar moment r x F as a linear map of F = (Fx, Fy)."""
    return np.array([-r[1], r[0]])


def rod_acc(base_acc, L, th, w, al):
    """Acceleration of the point at distance L along a rod at angle th from a point with base_acc."""
    return base_acc + L * (al * perp(th) - w * w * e2(th))


def _accel(e, r, i):
    s = ConstrainedSystem.build(e)
    qdd, _ = s.accel(r.q[i], r.qd[i], r.t[i])
    return qdd


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
def test_crank_rocker_reactions_match_newton_euler():
    e = crank_rocker_eom()
    a, b, c, d = 0.4, 1.0, 0.8, 1.0
    m1, m2, m3 = 0.5, 1.0, 0.8
    r = simulate_dae(e, 1.0, rtol=1e-11, atol=1e-11, points=6, reactions=True)
    assert r.success
    assert "jC.force[0]" in r and "lambda[jC.force[0]]" in r
    for i in range(len(r.t)):
        (t1, t2, t3), (w1, w2, w3) = r.q[i], r.qd[i]
        al1, al2, al3 = _accel(crank_rocker_eom(), r, i)
        A, D = np.zeros(2), np.array([d, 0.0])
        B = a * e2(t1)
        C = D + c * e2(t3)
        c1, c2, c3 = 0.5 * B, B + 0.5 * b * e2(t2), D + 0.5 * c * e2(t3)
        aB = rod_acc(np.zeros(2), a, t1, w1, al1)
        ac1 = rod_acc(np.zeros(2), a / 2, t1, w1, al1)
        ac2 = rod_acc(aB, b / 2, t2, w2, al2)
        ac3 = rod_acc(np.zeros(2), c / 2, t3, w3, al3)
        I1, I2, I3 = m1 * a * a / 12, m2 * b * b / 12, m3 * c * c / 12
        g = np.array([0.0, -G])
        # unknowns F_A, F_B, F_C, F_D (each 2): force of the parent on the child at the joint
        Aeq = np.zeros((9, 8))
        rhs = np.zeros(9)
        Aeq[0:2, 0:2] = np.eye(2); Aeq[0:2, 2:4] = -np.eye(2); rhs[0:2] = m1 * ac1 - m1 * g   # noqa: E702
        Aeq[2, 0:2] = cross(A - c1); Aeq[2, 2:4] = -cross(B - c1); rhs[2] = I1 * al1         # noqa: E702
        Aeq[3:5, 2:4] = np.eye(2); Aeq[3:5, 4:6] = -np.eye(2); rhs[3:5] = m2 * ac2 - m2 * g   # noqa: E702
        Aeq[5, 2:4] = cross(B - c2); Aeq[5, 4:6] = -cross(C - c2); rhs[5] = I2 * al2         # noqa: E702
        Aeq[6:8, 4:6] = np.eye(2); Aeq[6:8, 6:8] = np.eye(2); rhs[6:8] = m3 * ac3 - m3 * g    # noqa: E702
        Aeq[8, 4:6] = cross(C - c3); Aeq[8, 6:8] = cross(D - c3); rhs[8] = I3 * al3          # noqa: E702
        F, *_ = np.linalg.lstsq(Aeq, rhs, rcond=None)
        scale = np.max(np.abs(rhs)) + np.max(np.abs(F))
        assert np.max(np.abs(Aeq @ F - rhs)) < 1e-9 * scale
        R3 = np.array([[np.cos(t3), -np.sin(t3)], [np.sin(t3), np.cos(t3)]])
        FC_local = R3.T @ F[4:6]
        lam = np.array([r["jC.force[0]"][i], r["jC.force[1]"][i]])
        assert np.max(np.abs(lam - FC_local)) < 1e-8 * scale


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
def test_slider_crank_reactions_match_newton_euler():
    e = slider_crank_eom()
    rr, l, (m1, m2, m3), tau = 0.3, 1.0, (1.0, 2.0, 0.5), 5.0
    out = simulate_dae(e, 1.5, rtol=1e-11, atol=1e-11, points=7, outputs=["jB.force[0]", "jB.force[1]"])
    assert out.success
    always = {"constraint_drift", "velocity_drift", "kinetic_energy", "potential_energy", "energy",
              "residual(jB.force[0])", "residual(jB.force[1])"}
    assert set(out.signals) == always | {"jB.force[0]", "jB.force[1]"}
    for i in range(len(out.t)):
        (t1, t2, s), (w1, w2, v) = out.q[i], out.qd[i]
        al1, al2, sdd = _accel(slider_crank_eom(), out, i)
        A = rr * e2(t1)
        B = A + l * e2(t2)
        c1, c2 = 0.5 * A, A + 0.5 * l * e2(t2)
        aA = rod_acc(np.zeros(2), rr, t1, w1, al1)
        ac1 = rod_acc(np.zeros(2), rr / 2, t1, w1, al1)
        ac2 = rod_acc(aA, l / 2, t2, w2, al2)
        I1, I2 = m1 * rr * rr / 12, m2 * l * l / 12
        g = np.array([0.0, -G])
        # unknowns F_O (2), F_A (2), F_B (2), N (1)
        Aeq = np.zeros((8, 7))
        rhs = np.zeros(8)
        Aeq[0:2, 0:2] = np.eye(2); Aeq[0:2, 2:4] = -np.eye(2); rhs[0:2] = m1 * ac1 - m1 * g    # noqa: E702
        Aeq[2, 0:2] = cross(-c1); Aeq[2, 2:4] = -cross(A - c1); rhs[2] = I1 * al1 - tau        # noqa: E702
        Aeq[3:5, 2:4] = np.eye(2); Aeq[3:5, 4:6] = -np.eye(2); rhs[3:5] = m2 * ac2 - m2 * g    # noqa: E702
        Aeq[5, 2:4] = cross(A - c2); Aeq[5, 4:6] = -cross(B - c2); rhs[5] = I2 * al2          # noqa: E702
        Aeq[6, 4] = 1.0; rhs[6] = m3 * sdd                                                      # noqa: E702
        Aeq[7, 5] = 1.0; Aeq[7, 6] = 1.0; rhs[7] = m3 * G                                       # noqa: E702
        F, *_ = np.linalg.lstsq(Aeq, rhs, rcond=None)
        scale = np.max(np.abs(rhs)) + np.max(np.abs(F))
        assert np.max(np.abs(Aeq @ F - rhs)) < 1e-9 * scale
        lam = np.array([out["jB.force[0]"][i], out["jB.force[1]"][i]])
        assert np.max(np.abs(lam - F[4:6])) < 1e-8 * scale


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
def test_multipliers_only_when_asked():
    r = simulate_dae(slider_crank_eom(), 0.2, points=3)
    assert not any(k.startswith("lambda[") or k.startswith("jB.") for k in r.signals)
    assert {"xA", "yA", "constraint_drift", "velocity_drift"} <= set(r.signals)
    r = simulate_dae(slider_crank_eom(), 0.2, points=3, outputs=["lambda[jB.force[1]]"])
    assert {k for k in r.signals if "force" in k and not k.startswith("residual")} == {"lambda[jB.force[1]]"}


def test_reaction_outputs_from_eom_reactions_and_lam_outputs():
    e = slider_crank_eom()
    lam = e.lam if e.lam is not None else None
    import casadi as ca

    sym = ca.SX.sym("lam", 2)
    e = e.replace(lam=sym, reactions={"pin.normal": -sym[1]},
                  outputs={**e.outputs, "pin_force_norm": ca.norm_2(sym)})
    r = simulate_dae(e, 0.2, points=3, reactions=True)
    assert lam is None
    assert np.allclose(r["pin.normal"], -r["jB.force[1]"])
    assert np.allclose(r["pin_force_norm"], np.hypot(r["jB.force[0]"], r["jB.force[1]"]))


def test_unknown_output_is_a_usage_error():
    with pytest.raises(UsageError, match="did you mean"):
        simulate_dae(slider_crank_eom(), 0.2, points=3, outputs=["jB.forse[0]"])
