"""First integrals: which are found, their closed forms, and their conservation along
trajectories computed independently (scipy DOP853 on Lagrange's equations)."""
import math

import casadi as ca
import numpy as np
import pytest

import ana_models as am
from mechdsl.analysis.integrals import first_integrals, integral_signals


def trajectory(eom, T, n=200):
    """(t, q, qd) from scipy's DOP853 on M qdd = bias (independent of mechdsl's integrators)."""
    from scipy.integrate import solve_ivp

    f = ca.Function("mb", [eom.q, eom.qd, eom.t, eom.p], [eom.M, eom.bias])
    pv = eom.param_values
    k = eom.n

    def rhs(t, x):
        M, b = f(x[:k], x[k:], t, pv)
        return np.concatenate([x[k:], np.linalg.solve(np.array(M), np.array(b).ravel())])

    q0, qd0 = eom.start()
    ts = np.linspace(0, T, n)
    sol = solve_ivp(rhs, (0, T), np.concatenate([q0, qd0]), method="DOP853", rtol=1e-12, atol=1e-12, t_eval=ts)
    assert sol.success
    return sol.t, sol.y[:k].T, sol.y[k:].T


def values(eom, sx, t, q, qd):
    f = ca.Function("v", [eom.q, eom.qd, eom.t, eom.p], [sx])
    return np.array([float(f(q[i], qd[i], t[i], eom.param_values)) for i in range(len(t))])


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
def test_heavy_top_cyclic_momenta():
    I1, I3 = 0.3, 0.2
    eom = am.heavy_top(I1=I1, I3=I3)
    fis = {fi.name: fi for fi in first_integrals(eom)}
    assert set(fis) == {"p_phi", "p_psi", "energy"}
    assert fis["p_phi"].kind == "momentum" and fis["p_phi"].coordinate == "phi"
    assert fis["energy"].kind == "energy"
    # closed forms: p_psi = I3 (psi' + phi' cos th), p_phi = I1 phi' sin^2 th + p_psi cos th
    rng = np.random.default_rng(1)
    f = ca.Function("p", [eom.q, eom.qd, eom.t, eom.p], [fis["p_phi"].sx, fis["p_psi"].sx])
    for _ in range(5):
        q, qd = rng.uniform(-2, 2, 3), rng.uniform(-3, 3, 3)
        a, b = (float(v) for v in f(q, qd, 0.0, eom.param_values))
        ppsi = I3 * (qd[2] + qd[0] * math.cos(q[1]))
        assert b == pytest.approx(ppsi, rel=1e-12, abs=1e-12)
        assert a == pytest.approx(I1 * qd[0] * math.sin(q[1]) ** 2 + ppsi * math.cos(q[1]), rel=1e-12, abs=1e-12)
    # conserved along an independently integrated motion (nutation visible in theta)
    t, q, qd = trajectory(eom, 2.0)
    assert np.ptp(q[:, 1]) > 0.01
    for name in ("p_phi", "p_psi", "energy"):
        v = values(eom, fis[name].sx, t, q, qd)
        assert np.ptp(v) < 1e-8 * max(1.0, np.max(np.abs(v))), name


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
def test_heavy_top_texts_are_readable():
    fis = {fi.name: fi for fi in first_integrals(am.heavy_top())}
    assert fis["p_psi"].expression == "I3*(der(psi) + der(phi)*cos(theta))"
    assert fis["p_psi"].verified == "symbolic"       # sympy reduces dL/dpsi to 0


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
def test_two_body_translation_momenta():
    eom = am.two_body()
    fis = {fi.name: fi for fi in first_integrals(eom)}
    # translations, and (issue 17) the rotation of both bodies about the origin: x p_y - y p_x summed
    assert set(fis) == {"p_(x1+x2)", "p_(y1+y2)", "L_(x1:y1+x2:y2)", "energy"}
    assert fis["p_(x1+x2)"].direction == pytest.approx({"x1": 1.0, "x2": 1.0}, abs=1e-12)
    t, q, qd = trajectory(eom, 3.0)
    for name in fis:
        v = values(eom, fis[name].sx, t, q, qd)
        assert np.ptp(v) < 1e-9 * max(1.0, np.max(np.abs(v))), name


def test_hoop_jacobi_integral_differs_from_energy():
    eom = am.hoop(w=5.0, q0=0.9)
    fis = first_integrals(eom)
    assert [fi.name for fi in fis] == ["jacobi"]
    j = fis[0]
    assert j.kind == "jacobi" and "differs from the energy" in j.note
    t, q, qd = trajectory(eom, 2.0)
    h = values(eom, j.sx, t, q, qd)
    E = values(eom, eom.T + eom.V, t, q, qd)
    assert np.ptp(h) < 1e-9 * np.max(np.abs(h))
    assert np.ptp(E) > 0.1                            # the motor does work: T + V is not conserved
    # h = T2 - T0 + V in closed form
    m, R, g, w = eom.param_values
    closed = 0.5 * m * R ** 2 * (qd[:, 0] ** 2 - w ** 2 * np.sin(q[:, 0]) ** 2) - m * g * R * np.cos(q[:, 0])
    assert h == pytest.approx(closed, rel=1e-12, abs=1e-12)


def test_cart_pole_cart_momentum():
    fis = {fi.name: fi for fi in first_integrals(am.cart_pole(uniform=True))}
    assert set(fis) == {"p_x", "energy"}          # F = 0: the cart coordinate is cyclic


def test_no_integral_with_damping_or_forcing():
    assert first_integrals(am.pendulum(c=0.2)) == []
    assert first_integrals(am.pendulum(A=0.3, w=1.0)) == []
    names = [fi.name for fi in first_integrals(am.pendulum())]
    assert names == ["energy"]
    # a force on x2 breaks the translation symmetry; the energy is not conserved either
    assert first_integrals(am.two_masses(F=3.0)) == []
    assert [fi.name for fi in first_integrals(am.two_masses(F=0.0))] == ["p_(x1+x2)", "energy"]


def test_integral_signals_are_sx():
    sig = integral_signals(am.heavy_top())
    assert list(sig) == ["p_phi", "p_psi", "energy"]
    assert all(isinstance(v, ca.SX) for v in sig.values())
