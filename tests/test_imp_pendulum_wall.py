"""A pendulum hitting a wall: angular velocity reversed times e at the wall angle, impact times
from the elliptic-integral closed form; the same in Cartesian coordinates with a constraint (DAE)."""
import numpy as np
import pytest
from imp_models import cartesian_pendulum, pendulum, pendulum_wall_impacts, wall
from mechdsl.impacts import simulate_with_contacts

L, G, TH0, THW, E = 1.0, 9.81, -1.0, 0.3, 0.7
XW = L * np.sin(THW)


def closed_form_impacts(n):
    """Impact times and angular speeds just before each impact (elliptic integrals)."""
    return pendulum_wall_impacts(n, L, G, TH0, THW, E)


def check(r, omega_index=0, scale=1.0):
    imp = [e for e in r.events if e["kind"] == "impact"]
    times, omegas = closed_form_impacts(4)
    assert len(imp) >= 4
    assert np.array([e["time"] for e in imp[:4]]) == pytest.approx(times, abs=1e-8)
    # normal speed of the bob into the wall = L cos(thw) * omega
    vn = L * np.cos(THW) * omegas
    assert np.array([-e["speed_before"] for e in imp[:4]]) == pytest.approx(vn, rel=1e-7)
    assert np.array([e["speed_after"] for e in imp[:4]]) == pytest.approx(E * vn, rel=1e-7)
    # energy lost: (1 - e^2)/2 * m L^2 omega^2  (single contact closed form)
    assert np.array([e["energy_change"] for e in imp[:4]]) == pytest.approx(-(1 - E ** 2) / 2 * L ** 2 * omegas ** 2,
                                                                            rel=1e-7)
    return imp, times, omegas


def test_pendulum_wall_minimal_coordinates():
    eom = pendulum(L, G, 1.0, TH0)
    r = simulate_with_contacts(eom, [wall(XW, E)], 5.0, points=501, rtol=1e-10, atol=1e-12)
    assert r.success
    imp, times, omegas = check(r)
    # angular velocity just after the first impact: -e * omega, at the wall angle
    k = np.searchsorted(r.t, times[0])
    assert np.all(r.q[:, 0] <= THW + 1e-10)
    # between the first two impacts the motion is a free pendulum of the new amplitude
    amp = np.arccos(np.cos(THW) - L * (E * omegas[0]) ** 2 / (2 * G))
    assert np.min(r.q[k:np.searchsorted(r.t, times[1]), 0]) == pytest.approx(-amp, abs=2e-4)  # grid-limited


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
def test_pendulum_wall_constrained_model():
    """x^2 + y^2 = L^2 as a bilateral constraint: the impact equations include its row (e = 0)."""
    eom = cartesian_pendulum(L, G, 1.0, TH0)
    r = simulate_with_contacts(eom, [wall(XW, E)], 5.0, points=51, rtol=1e-10, atol=1e-12)
    assert r.success, r.message
    check(r)
    # the constraint holds throughout (projection after events and when drift exceeds 100 atol)
    assert np.max(np.abs(r.q[:, 0] ** 2 + r.q[:, 1] ** 2 - L ** 2)) < 1e-8


def test_pendulum_comes_to_rest_leaning_on_wall():
    """Wall at theta_w = -0.2 (left of the bottom): gravity presses the bob against it.  The
    impacts accumulate (Zeno); below rest_speed the contact becomes persistent, and the bob
    rests on the wall with normal force m g tan(theta_w)."""
    thw = -0.2
    eom = pendulum(L, G, 1.0, -1.0, omega0=3.0)
    r = simulate_with_contacts(eom, [wall(L * np.sin(thw), 0.5)], 8.0, points=5, rtol=1e-10, atol=1e-12)
    assert r.success, r.message
    kinds = [e["kind"] for e in r.events]
    assert kinds[-1] == "close" and kinds.count("close") == 1 and "release" not in kinds
    assert r.q[-1, 0] == pytest.approx(thw, abs=1e-10)
    assert r.qd[-1, 0] == pytest.approx(0.0, abs=1e-10)
    assert r["wall.force"][-1] == pytest.approx(G * np.tan(-thw), rel=1e-8)
