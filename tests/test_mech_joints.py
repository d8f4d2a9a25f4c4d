"""Every joint kind: the recursive route (ABA; CRBA M and RNEA bias) equals the Lagrange
route (T from velocities by automatic differentiation of positions) at random states."""
from __future__ import annotations

import casadi as ca
import numpy as np
import pytest

from mech_models import joint_chain, rot_z_expr, t_expr, v3, fn
from mechdsl.model import ir
from mechdsl.model.exprs import const, mul
from mechdsl.mechanics import derive


def random_state(e, rng):
    n = e.n
    q, qd = rng.uniform(-1.2, 1.2, n), rng.uniform(-1.5, 1.5, n)
    for name, expr in e.invariants.items():        # quaternion blocks: unit q, qd tangent
        joint = name.split(".quaternion_norm")[0]
        idx = [e.coords.index(f"{joint}.q{i}") for i in range(4)]
        qb = q[idx] / np.linalg.norm(q[idx])
        qdb = qd[idx] - qb * (qb @ qd[idx])
        q[idx], qd[idx] = qb, qdb
    return q, qd


def accelerations(e, q, qd, t):
    f = ca.Function("mb", [e.q, e.qd, e.t, e.p], [e.M, e.bias])
    M, b = (np.array(x) for x in f(q, qd, t, e.param_values))
    assert np.allclose(M, M.T, rtol=0, atol=1e-13 * max(1, np.abs(M).max()))
    return np.linalg.solve(M, b.ravel()), M


def check_routes(model, seeds=4):
    e = derive(model)
    el = derive(model, route="lagrange")
    assert e.route == "aba", e.notes
    rhs = ca.Function("f", [e.q, e.qd, e.t, e.p], [e.qdd])
    rng = np.random.default_rng(len(model.name))
    for _ in range(seeds):
        q, qd = random_state(e, rng)
        t = rng.uniform(0, 2)
        a = np.array(rhs(q, qd, t, e.param_values)).ravel()
        a_crba, M1 = accelerations(e, q, qd, t)
        a_lag, M2 = accelerations(el, q, qd, t)
        scale = max(1.0, np.abs(a_lag).max())
        assert np.abs(a - a_lag).max() <= 1e-10 * scale, (a, a_lag)
        assert np.abs(a_crba - a_lag).max() <= 1e-10 * scale
        assert np.abs(M1 - M2).max() <= 1e-11 * max(1.0, np.abs(M2).max())
    return e


@pytest.mark.parametrize("kind", ["revolute", "prismatic", "cylindrical", "planar", "spherical", "free", "fixed"])
def test_joint_kind_aba_equals_lagrange(kind):
    check_routes(joint_chain(kind))


@pytest.mark.parametrize("seq", ["xyz", "zxz", "yzy"])
def test_euler_sequences(seq):
    e = check_routes(joint_chain("spherical", options=(("sequence", seq),)))
    assert "jA.gimbal" in e.singularity_monitors


@pytest.mark.parametrize("kind", ["spherical", "free"])
def test_quaternion_joints(kind):
    e = check_routes(joint_chain(kind, options=(("parametrization", "quaternion"),)))
    assert "jA.quaternion_norm" in e.invariants


@pytest.mark.parametrize("kind", ["free", "planar"])
def test_point_mass_child(kind):
    check_routes(joint_chain(kind, point_child=True))


def test_coordinate_axis_and_point_child_revolute():
    check_routes(joint_chain("revolute", axis=(0, 0, 1)))
    check_routes(joint_chain("prismatic", axis=(1, 0, 0), second=False))


def test_prescribed_joint_variables():
    # cylindrical with its angle prescribed, the slide free; a fully prescribed revolute
    check_routes(joint_chain("cylindrical", prescribed={"phi": t_expr(0.2, 0.5, 3.0, 0.4)}))
    check_routes(joint_chain("revolute", prescribed={"phi": t_expr(0.1, 1.5, 2.0, 0.3)}))
    check_routes(joint_chain("spherical", prescribed={"theta": t_expr(0.0, 0.7, 1.0, 0.2)}))


def test_moving_frame():
    ang = mul(const(1.7), ir.Time())
    frame = (rot_z_expr(ang), (fn("sin", ir.Time()), const(0.2), mul(const(0.3), mul(ir.Time(), ir.Time()))))
    check_routes(joint_chain("revolute", frame=frame))


def test_quaternion_prescribed_and_mixed():
    # a fully prescribed ball joint in quaternions (rotation about a fixed axis at rate 2)
    h = mul(const(1.0), ir.Time())
    pres = {"q0": fn("cos", h), "q1": mul(const(0.6), fn("sin", h)), "q2": mul(const(0.8), fn("sin", h)), "q3": const(0.0)}
    check_routes(joint_chain("spherical", options=(("parametrization", "quaternion"),), prescribed=pres))


def test_gimbal_monitor_vanishes_at_lock():
    e = derive(joint_chain("spherical", second=False))
    mon = ca.Function("m", [e.q], [e.singularity_monitors["jA.gimbal"]])
    i = e.coords.index("jA.theta")
    q = np.array([0.3, 0.2, -0.4])
    assert abs(float(mon(q))) == pytest.approx(np.cos(0.2))
    q[i] = np.pi / 2
    assert abs(float(mon(q))) < 1e-15
