"""Equilibria and linearization on Spherical joints (issue 11), against closed forms.

Spherical pendulum (point mass m on a massless rod of length L): hanging is stable with the
small-oscillation frequency sqrt(g/L), twice; inverted is unstable with the rate sqrt(g/L).
Heavy top (mass m, centre of mass l from the tip, transverse moment I1 about the centre of
mass): hanging stable with w^2 = m g l / (I1 + m l^2) twice, upright unstable with that rate;
the Hessian of V in rotation vectors is +-m g l.  Euler angles (any sequence, at gimbal lock or
not) and quaternions must agree; the quaternion norm is a constraint, q and -q one rotation.
"""
from __future__ import annotations

import math
import os

import numpy as np
import pytest

from mechdsl.analysis.equilibrium import equilibria
from mechdsl.analysis.linearize import linearize
from mechdsl.api import loads
from mechdsl.cli import main
import mechdsl.examples

MODELS = str(mechdsl.examples.folder())
G, L = 9.81, 0.8
m_top, l_top, I1, I2, I3 = 1.0, 0.5, 0.12, 0.15, 0.2

PENDULUM = """
model SphericalPendulum
  parameter Real m(unit = "kg") = 1;
  parameter Real L(unit = "m") = 0.8;
  parameter Real g(unit = "m/s2") = 9.81;
  Gravity gravity(g = {0, 0, -g});
  PointMass bob(m = m);
  Point top(body = bob, r = {0, 0, L});
  Spherical j(parent = world, child = top, JOINT);
end SphericalPendulum;
"""

TOP = """
model Top
  parameter Real m(unit = "kg") = 1;
  parameter Real l(unit = "m") = 0.5;
  Gravity gravity(g = {0, 0, -9.81});
  Body top(m = m, r_cm = {0, 0, l}, I_11 = 0.12, I_22 = 0.15, I_33 = 0.2);
  Spherical tip(parent = world, child = top, JOINT);
end Top;
"""

EULER_ZYX = 'sequence = "zyx", psi(start = 0.3), theta(start = 0.2)'
EULER_XYX = 'sequence = "xyx", theta(start = 0.3)'
QUAT = 'parametrization = "quaternion", q0(start = 0.9), q1(start = 0.3), q2(start = 0.1)'


def axis_quaternion(k, a):
    q = np.zeros(4)
    q[0], q[1 + k] = math.cos(a / 2), math.sin(a / 2)
    return q


def hamilton(p, q):
    p0, pv, q0, qv = p[0], p[1:], q[0], q[1:]
    return np.concatenate([[p0 * q0 - pv @ qv], p0 * qv + q0 * pv + np.cross(pv, qv)])


def pendulum(joint):
    return loads(PENDULUM.replace("JOINT", joint)).eom


def top(joint):
    return loads(TOP.replace("JOINT", joint)).eom


def hanging_and_inverted(eqs, height):
    """(stable, unstable) equilibria told apart by the height of the bob / centre of mass."""
    down = [e for e in eqs if height(e) < 0]
    up = [e for e in eqs if height(e) > 0]
    return down, up


def quat_height(e, idx, arm):
    """z of the point arm*e_z of the child for the quaternion block at idx (z of R e3)."""
    q0, q1, q2, q3 = (e.q[i] for i in idx)
    return arm * (q0 * q0 - q1 * q1 - q2 * q2 + q3 * q3)


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
def test_quaternion_pendulum_equilibria_are_unit_and_distinct():
    e = pendulum(QUAT)
    eqs = equilibria(e)
    assert len(eqs) == 2                     # before: hundreds of non-unit "equilibria"
    for x in eqs:
        assert np.linalg.norm(x.q) == pytest.approx(1.0, abs=1e-12)
    # the bob hangs at -L R e3 (the rod's top is L above it)
    down, up = hanging_and_inverted(eqs, lambda x: quat_height(x, range(4), -L))
    assert len(down) == 1 and len(up) == 1
    assert down[0].stability == "stable"     # before: "undetermined"
    assert up[0].stability == "unstable"
    assert down[0].hessian_eigenvalues == pytest.approx([G * L, G * L], rel=1e-9)   # m g L, m = 1


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
@pytest.mark.parametrize("joint", [QUAT, EULER_ZYX, EULER_XYX], ids=["quaternion", "zyx", "xyx-gimbal-lock"])
def test_pendulum_modes_are_sqrt_g_over_L_twice(joint):
    e = pendulum(joint)
    eqs = equilibria(e)
    assert len(eqs) == 2                     # one hanging, one inverted: every chart, q ~ -q, twins
    stable = [x for x in eqs if x.stable]
    unstable = [x for x in eqs if x.stable is False]
    assert stable and unstable
    assert all(x.stable is not None for x in eqs)
    w = math.sqrt(G / L)
    lin = linearize(e, at=stable[0])
    md = lin.modes()
    assert len(md) == 2                      # the rod's spin carries nothing: left out, no fake mode
    assert list(md.kinds) == ["oscillatory", "oscillatory"]
    assert md.frequencies == pytest.approx([w, w], rel=1e-9)
    up = linearize(e, at=unstable[0])
    assert sorted(ev.real for ev in up.eigenvalues)[-1] == pytest.approx(w, rel=1e-9)


def test_heavy_top_model_equilibria_at_gimbal_lock():
    """models/heavy_top.mech (z-x-z): both equilibria are at theta = 0, pi (gimbal lock)."""
    from mechdsl.api import load

    e = load(os.path.join(MODELS, "heavy_top.mech")).eom
    eqs = equilibria(e)                      # before: LinAlgError (singular M at gimbal lock)
    assert len(eqs) == 2
    th = {round(abs(x["tip.theta"]), 6): x for x in eqs}
    A = 0.12 + 1.0 * 0.5 ** 2
    mgl = 1.0 * 9.81 * 0.5
    assert th[round(math.pi, 6)].stability == "stable"
    assert th[round(math.pi, 6)].hessian_eigenvalues == pytest.approx([mgl, mgl], rel=1e-9)
    up = th[0.0]
    assert up.stability == "unstable"
    assert up.hessian_eigenvalues == pytest.approx([-mgl, -mgl], rel=1e-9)
    assert max(ev.real for ev in up.linear_eigenvalues) == pytest.approx(math.sqrt(mgl / A), rel=1e-9)
    lin = linearize(e, at=th[round(math.pi, 6)])
    md = lin.modes()
    osc = sorted(f for f, k in zip(md.frequencies, md.kinds) if k == "oscillatory")
    assert osc == pytest.approx([math.sqrt(mgl / A)] * 2, rel=1e-9)
    assert list(md.kinds).count("rigid") == 1          # rotation about the vertical


@pytest.mark.parametrize("cmd", ["equilibrium", "linearize"])
def test_cli_heavy_top_exits_0(cmd, capsys):
    assert main([cmd, os.path.join(MODELS, "heavy_top.mech")]) == 0      # before: exit 3
    out = capsys.readouterr().out
    assert "gimbal lock" in out


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
@pytest.mark.parametrize("joint", [EULER_ZYX, QUAT], ids=["zyx", "quaternion"])
def test_asymmetric_top_hanging_modes(joint):
    """Hanging asymmetric top: w_x^2 = m g l/(I1 + m l^2), w_y^2 = m g l/(I2 + m l^2) and a rigid
    spin about the vertical (a family of equilibria: neutral, the point counts as stable)."""
    e = top(joint)
    eqs = equilibria(e)
    mgl = m_top * 9.81 * l_top
    hang = [x for x in eqs if x.stable]
    assert len(eqs) == 2 and len(hang) == 1
    assert hang[0].hessian_eigenvalues == pytest.approx([mgl, mgl], rel=1e-9)
    assert all(x.stable is False for x in eqs if x is not hang[0])
    md = linearize(e, at=hang[0]).modes()
    osc = sorted(f for f, k in zip(md.frequencies, md.kinds) if k == "oscillatory")
    want = sorted([math.sqrt(mgl / (I1 + m_top * l_top ** 2)), math.sqrt(mgl / (I2 + m_top * l_top ** 2))])
    assert osc == pytest.approx(want, rel=1e-9)
    assert list(md.kinds).count("rigid") == 1


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
def test_quaternion_and_euler_agree_at_a_regular_state():
    """Tilted top at rest (not an equilibrium), linearized in both parametrizations about the
    same rotation with the same frozen state: the accelerations agree, and at the equilibrium
    (regular for z-y-x) both give the same eigenvalues."""
    eu = top(EULER_ZYX)
    qu = top(QUAT)
    ang = {"tip.phi": 0.4, "tip.theta": 0.3, "tip.psi": 2.5}
    quat = hamilton(hamilton(axis_quaternion(2, ang["tip.phi"]), axis_quaternion(1, ang["tip.theta"])),
                    axis_quaternion(0, ang["tip.psi"]))          # Rz(phi) Ry(theta) Rx(psi)
    le = linearize(eu, at=ang)
    lq = linearize(qu, at={f"tip.q{k}": float(quat[k]) for k in range(4)})
    assert le.kind == lq.kind == "state"
    # the potential energy at the two states is the same (same rotation)
    import casadi as ca

    fe = ca.Function("V", [eu.q, eu.p], [eu.V])
    fq = ca.Function("V", [qu.q, qu.p], [qu.V])
    assert float(fe(le.q, eu.param_values)) == pytest.approx(float(fq(lq.q, qu.param_values)), rel=1e-12)
    eqe = [x for x in equilibria(eu) if x.stable]
    eqq = [x for x in equilibria(qu) if x.stable]
    a = np.sort_complex(linearize(eu, at=eqe[0]).eigenvalues)
    b = np.sort_complex(linearize(qu, at=eqq[0]).eigenvalues)
    assert len(a) == len(b) == 6
    assert np.allclose(a, b, atol=1e-7)
