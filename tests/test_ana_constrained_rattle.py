"""RATTLE (constrained Stormer-Verlet, mechdsl.rattle) on the Cartesian pendulum (separable H,
against the exact elliptic-function solution) and on the four-bar linkage (non-separable:
M depends on the joint angles; against the adaptive DAE simulator at tight tolerance)."""
import math

import numpy as np
import pytest
from scipy.special import ellipj, ellipk

import mechdsl
from conftest import MODELS
from mechdsl.diagnostics import UsageError

G_, L_ = 9.81, 1.0


@pytest.fixture(scope="module")
def pend():
    return mechdsl.load(MODELS / "pendulum_cartesian.mech", model="PendulumCartesian")


@pytest.fixture(scope="module")
def four_bar():
    return mechdsl.load(MODELS / "four_bar.mech", model="FourBar")


def exact(t, th0=math.pi / 2):
    """Released at rest at th0 from the bottom: th = 2 asin(k sn(K - w t, k)), k = sin(th0/2)."""
    k = math.sin(th0 / 2)
    w = math.sqrt(G_ / L_)
    sn, *_ = ellipj(ellipk(k * k) - w * np.asarray(t), k * k)
    th = 2 * np.arcsin(k * sn)
    return np.stack([L_ * np.sin(th), -L_ * np.cos(th)], axis=-1)


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
def test_pendulum_second_order_against_exact(pend):
    errs = []
    for dt in (0.01, 0.005):
        r = pend.simulate(5.0, method="rattle", dt=dt, points=11, error_estimate="off")
        assert r.failure is None and r.metadata["method"] == "rattle"
        errs.append(float(np.max(np.abs(r.q - exact(r.t)))))
        assert r.stats["max_constraint_drift"] < 1e-10 and r.stats["max_velocity_drift"] < 1e-10
    assert errs[0] < 2e-2
    assert 3.5 < errs[0] / errs[1] < 4.5            # order 2


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
def test_pendulum_energy_error_bounded(pend):
    """400 s (170 periods) with a step of 0.02: the energy error oscillates, O(h^2), without drift."""
    res = {}
    for dt in (0.02, 0.01):
        r = pend.simulate(400.0, method="stormer-verlet", dt=dt,     # RATTLE for a constrained model
                          error_estimate="off")            # the test's subject is the energy, not the estimate
        assert r.metadata["method"] == "rattle"
        dE = np.abs(r.signals["energy"] - r.signals["energy"][0])
        first, last = dE[r.t <= 100].max(), dE[r.t >= 300].max()
        assert last < 1.1 * first and first < 1.1 * last
        res[dt] = dE.max()
        assert r.stats["energy_drift"] == pytest.approx(res[dt])
    assert 3.5 < res[0.02] / res[0.01] < 4.5
    assert res[0.02] < 0.02 * G_ * L_


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
def test_four_bar_non_separable(four_bar):
    """M(q) in joint angles, five loop equations of which three are redundant (dropped)."""
    ref = four_bar.simulate(2.0, rtol=1e-11, atol=1e-11, points=3, error_estimate="off")
    errs, dEs = [], []
    for dt in (0.004, 0.002):
        r = four_bar.simulate(2.0, method="rattle", dt=dt, points=3, error_estimate="off")
        assert r.failure is None
        assert r.metadata["active_constraints"] == ["close.fx", "close.fy"]
        assert any(c["name"] == "elbow.phi" for c in r.metadata["initialization"]["changes"])
        errs.append(float(np.max(np.abs(r.q[-1] - ref.q[-1]))))
        assert r.stats["max_constraint_drift"] < 1e-10
        assert np.all(np.isfinite(r.signals["F_close[1]"]))           # reaction outputs from the multipliers
    assert 3.5 < errs[0] / errs[1] < 4.5
    r = four_bar.simulate(40.0, method="rattle", dt=0.004, error_estimate="off")
    dE = np.abs(r.signals["energy"] - r.signals["energy"][0])
    assert dE[r.t >= 20].max() < 1.5 * dE[r.t <= 20].max()
    assert dE.max() < 1e-3 * abs(r.signals["kinetic_energy"]).max()


def test_other_methods_refuse_constraints(pend):
    for method in ("implicit-midpoint", "gauss-legendre"):
        with pytest.raises(UsageError, match="rattle"):
            pend.simulate(1.0, method=method, dt=0.01)


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
def test_rattle_without_constraints_is_stormer_verlet():
    import ana_models as am
    from ana_models import simulate_symplectic

    eom = am.kepler()
    a = simulate_symplectic(eom, 1.0, method="rattle", dt=0.01)
    b = simulate_symplectic(eom, 1.0, method="stormer-verlet", dt=0.01)
    assert a.metadata["method"] == "stormer-verlet"
    assert np.array_equal(a.q, b.q)
