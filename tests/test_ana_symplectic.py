"""Symplectic integration: bounded energy error over long runs (against an explicit
Runge-Kutta method of the same cost, which drifts), orders of convergence against an
independent reference (scipy DOP853 on Lagrange's equations), conserved momenta, failures."""
import math

import casadi as ca
import numpy as np
import pytest

import ana_models as am
from mechdsl.diagnostics import MechError, UsageError
from ana_models import simulate_symplectic

PERIOD = 2 * math.pi          # Kepler orbit with mu = 1, a = 1


def reference(eom, T, p=None):
    from scipy.integrate import solve_ivp

    f = ca.Function("mb", [eom.q, eom.qd, eom.t, eom.p], [eom.M, eom.bias])
    pv = eom.param_values if p is None else p
    k = eom.n

    def rhs(t, x):
        M, b = f(x[:k], x[k:], t, pv)
        return np.concatenate([x[k:], np.linalg.solve(np.array(M), np.array(b).ravel())])

    q0, qd0 = eom.start()
    sol = solve_ivp(rhs, (0, T), np.concatenate([q0, qd0]), method="DOP853", rtol=1e-13, atol=1e-13)
    return sol.y[:k, -1], sol.y[k:, -1]


def kepler_energy_errors(orbits, steps_per_orbit=400):
    eom = am.kepler(e=0.6)
    sv = simulate_symplectic(eom, orbits * PERIOD, method="stormer-verlet", dt=PERIOD / steps_per_orbit)
    rk = simulate_symplectic(eom, orbits * PERIOD, method="rk4", dt=4 * PERIOD / steps_per_orbit)
    assert sv.success and rk.success
    # the same cost: one force evaluation a Verlet step, four a Runge-Kutta step
    assert abs(sv.stats["rhs_evaluations"] - rk.stats["rhs_evaluations"]) <= 1
    E0 = -0.5                                             # -mu m / (2 a)
    assert sv["energy"][0] == pytest.approx(E0, rel=1e-14)
    out = {}
    for name, r in (("sv", sv), ("rk", rk)):
        err = np.abs(r["energy"] - E0)
        first = err[r.t <= orbits * PERIOD / 10 + 1e-9]
        out[name] = (first.max(), err.max(), err[-1])
    return out


def check_bounded_vs_drift(e):
    sv_first, sv_all, _ = e["sv"]
    rk_first, rk_all, rk_end = e["rk"]
    assert sv_all <= 1.05 * sv_first             # Verlet: the error over the whole run stays where it was
    assert rk_end >= 5 * rk_first                # RK4: grows (about linearly) with time
    assert rk_end >= 5 * sv_all                  # and ends far above Verlet's bounded error


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
def test_kepler_verlet_bounded_rk4_drifts_100_orbits():
    e = kepler_energy_errors(100)
    check_bounded_vs_drift(e)


@pytest.mark.slow
def test_kepler_verlet_bounded_rk4_drifts_1000_orbits():
    e = kepler_energy_errors(1000)
    check_bounded_vs_drift(e)
    assert e["rk"][2] >= 50 * e["sv"][1]          # 1000 orbits: RK4 ends two orders above Verlet


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
def test_free_two_body_momenta_and_energy():
    eom = am.two_body(e=0.6)
    P = 2 * math.pi / math.sqrt(1.5)          # a = 1, mu = G (m1 + m2) = 1.5
    r = simulate_symplectic(eom, 20 * P, method="stormer-verlet", dt=P / 400)
    assert r.success and r.metadata["why"].startswith("explicit")
    for name in ("p_(x1+x2)", "p_(y1+y2)"):
        assert np.ptp(r[name]) < 1e-12
    err = np.abs(r["energy"] - r["energy"][0])
    assert err.max() < 2e-3 and err.max() <= 1.05 * err[r.t <= 2 * P].max()


def order(eom, method, T, dts):
    qref, qdref = reference(eom, T)
    errs = []
    for dt in dts:
        r = simulate_symplectic(eom, T, method=method, dt=dt)
        errs.append(np.max(np.abs(np.concatenate([r.q[-1] - qref, r.qd[-1] - qdref]))))
    return [math.log2(errs[i] / errs[i + 1]) for i in range(len(errs) - 1)], errs


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
@pytest.mark.parametrize("method,expected", [("stormer-verlet", 2), ("implicit-midpoint", 2),
                                             ("gauss-legendre", 4), ("rk4", 4)])
def test_orders_on_nonseparable_double_pendulum(method, expected):
    eom = am.double_pendulum(q0=(0.8, -0.5), qd0=(0.0, 0.5))
    rates, errs = order(eom, method, 1.0, [0.01, 0.005])
    assert rates[0] == pytest.approx(expected, abs=0.25), errs


def test_order_explicit_verlet_on_pendulum():
    rates, errs = order(am.pendulum(q0=1.5), "stormer-verlet", 2.0, [0.02, 0.01, 0.005])
    assert all(abs(r - 2) < 0.1 for r in rates), errs


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
def test_nonseparable_energy_bounded():
    eom = am.double_pendulum(q0=(0.6, 0.3))
    T = 60.0
    errs = {}
    for method, dt in (("stormer-verlet", 0.02), ("implicit-midpoint", 0.02), ("gauss-legendre", 0.04),
                       ("rk4", 0.08)):
        r = simulate_symplectic(eom, T, method=method, dt=dt, error_estimate="off")    # the energy, not the estimate
        assert r.success, r.message
        e = np.abs(r["energy"] - r["energy"][0])
        errs[method] = (e[r.t <= T / 10].max(), e.max(), e[-1])
    for m in ("stormer-verlet", "implicit-midpoint", "gauss-legendre"):
        assert errs[m][1] <= 1.5 * errs[m][0], (m, errs[m])
    assert errs["rk4"][2] >= 3 * errs["rk4"][0]


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
def test_top_momenta_conserved_and_matches_reference():
    eom = am.heavy_top()
    T = 1.0
    r = simulate_symplectic(eom, T, method="gauss-legendre", dt=0.002)
    assert r.success
    for name in ("p_phi", "p_psi"):
        assert np.ptp(r[name]) < 1e-10 * max(1, np.max(np.abs(r[name])))
    assert np.ptp(r["energy"]) < 1e-6 * np.max(np.abs(r["energy"]))
    qref, qdref = reference(eom, T)
    assert r.q[-1] == pytest.approx(qref, abs=1e-6)
    assert r.qd[-1] == pytest.approx(qdref, abs=1e-5)


def test_rheonomic_hoop_conserves_jacobi_not_energy():
    eom = am.hoop(w=5.0, q0=1.0)
    r = simulate_symplectic(eom, 10.0, method="implicit-midpoint", dt=0.005)
    assert r.success and "jacobi" in r.signals
    assert np.ptp(r["jacobi"]) < 1e-4 * np.max(np.abs(r["jacobi"]))
    assert np.ptp(r["energy"]) > 1.0
    assert np.allclose(r["H"], r["jacobi"], rtol=1e-12, atol=1e-12)


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
def test_forced_damped_pendulum_against_reference():
    eom = am.pendulum(c=0.3, A=0.8, w=2.5, q0=0.4)
    qref, qdref = reference(eom, 3.0)
    for method in ("stormer-verlet", "gauss-legendre"):
        r = simulate_symplectic(eom, 3.0, method=method, dt=0.001, error_estimate="off")   # against the reference
        assert r.q[-1] == pytest.approx(qref, abs=1e-5)
        assert not r.metadata["separable"]


def test_result_layout_and_determinism():
    eom = am.kepler()
    a = simulate_symplectic(eom, 3.0, method="stormer-verlet", dt=0.01, points=31)
    b = simulate_symplectic(eom, 3.0, method="stormer-verlet", dt=0.01, points=31)
    assert len(a.t) == 31 and a.t[0] == 0 and a.t[-1] == pytest.approx(3.0, rel=1e-14)
    assert np.array_equal(a.q, b.q) and np.array_equal(a["H"], b["H"])
    for name in ("energy", "H", "p_x", "p_y", "der(x)"):
        assert name in a
    assert a["p_x"] == pytest.approx(a.qd[:, 0])        # m = 1
    assert a.metadata["method"] == "stormer-verlet" and a.metadata["symplectic"]
    assert a.stats["steps"] == 300
    r = simulate_symplectic(eom, 1.0, method="rk4", dt=0.3)     # steps shortened to fit: 4 x 0.25
    assert r.stats["dt"] == pytest.approx(0.25, rel=1e-14) and r.t[-1] == pytest.approx(1.0, rel=1e-14)


def test_newton_failure_keeps_results():
    eom = am.pendulum(q0=2.5, qd0=3.0)
    r = simulate_symplectic(eom, 50.0, method="implicit-midpoint", dt=2.0, max_newton=3)
    assert not r.success
    assert r.failure.time > 0 and "Newton" in r.failure.cause
    assert len(r.t) >= 1 and r.t[-1] < r.failure.time


def test_bad_requests():
    eom = am.kepler()
    with pytest.raises(UsageError):
        simulate_symplectic(eom, 1.0, method="leapfrog-ish", dt=0.1)
    with pytest.raises(UsageError):
        simulate_symplectic(eom, 1.0, dt=-0.1)
    with pytest.raises(UsageError):
        simulate_symplectic(eom, 1.0, dt=0.1, colour="red")
    r = simulate_symplectic(eom, 1.0, dt=0.1, rtol=1e-6)          # adaptive options are noted, not used
    assert any("rtol" in n for n in r.metadata["notes"])


def test_constrained_model_needs_rattle():
    """Methods that ignore constraints refuse constrained models (RATTLE: test_ana_constrained_rattle.py)."""
    from mechdsl import eom as E

    q, qd, t, p = ca.SX.sym("q", 2), ca.SX.sym("qd", 2), ca.SX.sym("t"), ca.SX.sym("p", 0)
    eom = E.from_lagrangian("Pend2", ["x", "y"], [], [], q, qd, t, p, 0.5 * ca.dot(qd, qd), 9.81 * q[1],
                            g=ca.dot(q, q) - 1, q0=[1, 0])
    for method in ("implicit-midpoint", "gauss-legendre", "rk4"):
        with pytest.raises(UsageError, match="rattle"):
            simulate_symplectic(eom, 1.0, dt=0.01, method=method)
