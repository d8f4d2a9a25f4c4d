"""Imported URDF robots against Pinocchio (an independent C++ implementation of the same rigid-body
algorithms, reading the same URDF itself): mass matrix, bias and forward dynamics at random states
of six arms of example-robot-data (UR5, Franka Panda with its mimic finger, xArm7, TALOS's left arm,
Kinova, Unitree Z1), a floating base, and 5 s under gravity against scipy + pin.aba."""
from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

import mechdsl
from mechdsl.urdf import convert

from urdf_util import Pair, rel, robots_dir

ARMS = {
    "ur5": "ur_description/urdf/ur5_robot.urdf",
    "panda": "panda_description/urdf/panda.urdf",            # its second finger mimics the first
    "xarm7": "xarm_description/urdf/xarm7.urdf",
    "talos_left_arm": "talos_data/robots/talos_left_arm.urdf",
    "kinova": "kinova_description/robots/kinova.urdf",
    "z1": "z1_description/urdf/z1.urdf",
}
TOL = 1e-10


@pytest.fixture(scope="module", params=sorted(ARMS))
def pair(request):
    return Pair(ARMS[request.param])


@pytest.mark.slow_cases('kinova', 'panda', 'z1')  # CPU budget: the cheaper tests of this file stay in the default run
def test_joint_order_and_names_match_pinocchio(pair):
    """The coordinate of URDF joint J is J.phi (revolute, continuous) or J.s (prismatic)."""
    names = [pair.pin.names[j] for j in range(1, pair.pin.njoints) if pair.pin.joints[j].nv]
    movable = [n for n in names if n not in pair.imp.mimics]
    kinds = {j.get("name"): j.get("type") for j in _joints(pair.path)}
    for n in movable:
        role = "s" if kinds[n] == "prismatic" else "phi"
        assert pair.imp.coordinates[n] == (f"{pair.imp.joints[n]}.{role}",)
    order = [pair.imp.coordinates[n][0] for n in movable]
    assert list(pair.eom.coords) == order          # the same order as Pinocchio's joints
    assert pair.imp.mimics == ({"panda_finger_joint2": ("panda_finger_joint1", 1.0, 0.0)} if "panda" in str(pair.path)
                               else {})


def _joints(path):
    import xml.etree.ElementTree as ET

    return ET.parse(path).getroot().iter("joint")


@pytest.mark.slow_cases('panda-0', 'z1-0')  # CPU budget: the cheaper tests of this file stay in the default run
@pytest.mark.parametrize("seed", range(4))
def test_mass_matrix_bias_and_accelerations_agree(pair, seed):
    rng = np.random.default_rng(seed)
    q, v, (qp, vp) = pair.state(rng)
    M, b, a = pair.mechdsl(q, v)
    Mp, bp, ap = pair.pinocchio(qp, vp)
    assert rel(M, Mp) < TOL and rel(b, bp) < TOL and rel(a, ap) < TOL, (rel(M, Mp), rel(b, bp), rel(a, ap))


def test_six_arms_at_least():
    assert len(ARMS) >= 4 and len(set(ARMS.values())) == len(ARMS)


def _quat_rates(quat_wxyz, w_body):
    """der(q) of the unit quaternion (scalar first) for the body angular velocity w_body."""
    q0, q1, q2, q3 = quat_wxyz
    G = np.array([[-q1, q0, q3, -q2], [-q2, -q3, q0, q1], [-q3, q2, -q1, q0]])
    return 0.5 * G.T @ w_body, G


def test_floating_base_against_a_free_flyer():
    """`--floating` gives the root a Free joint (quaternion): at random states its kinetic and
    potential energies and accelerations equal Pinocchio's with a JointModelFreeFlyer root (whose
    velocity is the root's spatial velocity in its own axes)."""
    path = robots_dir() / ARMS["ur5"]
    imp = convert(path, floating=True)
    m = mechdsl.loads(imp.text)
    e = m.eom
    pm = pin.buildModelFromUrdf(str(path), pin.JointModelFreeFlyer())
    pd = pm.createData()
    import casadi as ca

    f = ca.Function("f", [e.q, e.qd, e.t, e.p], [e.T, e.V, e.M, e.bias])
    coords = list(e.coords)
    root = imp.coordinates[""]
    rng = np.random.default_rng(3)
    for _ in range(3):
        quat = rng.normal(size=4)
        quat /= np.linalg.norm(quat)                       # (w, x, y, z)
        pos, v_loc, w_loc = rng.normal(size=3), rng.normal(size=3), rng.normal(size=3)
        qj, vj = rng.uniform(-2, 2, pm.nq - 7), rng.uniform(-2, 2, pm.nv - 6)
        qp = np.concatenate([pos, quat[1:], quat[:1], qj])
        vp = np.concatenate([v_loc, w_loc, vj])
        R = pin.Quaternion(quat[0], *quat[1:]).toRotationMatrix()
        qdot, G = _quat_rates(quat, w_loc)
        q, qd = np.zeros(len(coords)), np.zeros(len(coords))
        for k, (name, val, rate) in enumerate(zip(root, [*pos, *quat], [*(R @ v_loc), *qdot])):
            q[coords.index(name)], qd[coords.index(name)] = val, rate
        for jid in range(2, pm.njoints):
            c = coords.index(imp.coordinates[pm.names[jid]][0])
            q[c], qd[c] = qj[pm.joints[jid].idx_q - 7], vj[pm.joints[jid].idx_v - 6]
        T, V, M, b = (np.array(x) for x in f(q, qd, 0.0, e.param_values))
        Mp = pin.crba(pm, pd, qp)
        Mp = np.triu(Mp) + np.triu(Mp, 1).T
        assert T.item() == pytest.approx(0.5 * vp @ Mp @ vp, rel=1e-12)
        assert V.item() == pytest.approx(pin.computePotentialEnergy(pm, pd, qp), rel=1e-12, abs=1e-10)
        ap = pin.aba(pm, pd, qp, vp, np.zeros(pm.nv))
        qdd = np.linalg.solve(M, b).ravel()
        xdd = qdd[[coords.index(n) for n in root[:3]]]
        quat_dd = qdd[[coords.index(n) for n in root[3:]]]
        assert rel(R.T @ xdd - np.cross(w_loc, v_loc), ap[:3]) < TOL        # classical -> spatial
        assert rel(2 * G @ quat_dd, ap[3:6]) < TOL
        joints = [qdd[coords.index(imp.coordinates[pm.names[j]][0])] for j in range(2, pm.njoints)]
        assert rel(joints, ap[6:]) < TOL


@pytest.mark.slow
def test_five_seconds_under_gravity_agree_with_scipy_and_pin_aba():
    """The UR5 falls for 5 s from a random state: mechdsl (DOP853, tolerances 1e-12) against
    scipy's DOP853 with Pinocchio's ABA as the right-hand side, at the same tolerances."""
    from scipy.integrate import solve_ivp

    pair = Pair(ARMS["ur5"])
    rng = np.random.default_rng(11)
    q0, v0, _ = pair.state(rng)
    n = len(q0)
    starts = {}
    for k, c in enumerate(pair.eom.coords):
        starts[f"{c}.start"], starts[f"{c}.speed"] = float(q0[k]), float(v0[k])
    m = pair.model.with_params(**starts)
    times = np.linspace(0.0, 5.0, 11)
    r = m.simulate(5.0, rtol=1e-12, atol=1e-12, method="dop853", points=len(times))

    def rhs(t, y):
        qp, vp = pair.to_pin(y[:n], y[n:])
        a = pair.P @ pin.aba(pair.pin, pair.data, qp, vp, np.zeros(pair.pin.nv))
        return np.concatenate([y[n:], a])

    ref = solve_ivp(rhs, (0.0, 5.0), np.concatenate([q0, v0]), method="DOP853", rtol=1e-12, atol=1e-12,
                    t_eval=times)
    assert ref.success
    ours = np.hstack([r.q, r.qd])
    assert np.allclose(r.t, times)
    err = np.max(np.abs(ours - ref.y.T))
    assert err < 1e-8, err
