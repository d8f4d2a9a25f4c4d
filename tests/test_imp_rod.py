"""A uniform rod falling onto a plane with one end, and a rod whose end is suddenly fixed.

Closed forms (rod of mass m, length L, I = m L^2 / 12, falling without spin at speed v,
inclined at th to the floor, hitting with its lower end):
    impulse      P  = (1 + e) m v / (1 + 3 cos^2 th)
    after        v' = -v + P/m (upwards),  w' = -6 (1 + e) v cos th / (L (1 + 3 cos^2 th))
    energy       dT = -(1 - e^2)/2 v^2 / (1/m + L^2 cos^2 th / (4 I))
Fixation of an end of a rod translating at v across its length (no gravity):
    angular momentum about the end is kept: w = 3 v / (2 L); 1/4 of the energy is lost.
"""
import numpy as np
import pytest

from imp_models import floor_at, planar_rod
from mechdsl.impacts import Fixation, simulate_with_contacts

L, M, G = 1.0, 2.0, 9.81


@pytest.mark.slow_cases('0.5-0.6', '1.2-1.0')  # CPU budget: the cheaper tests of this file stay in the default run
@pytest.mark.parametrize("th, e", [(0.5, 0.6), (1.2, 1.0), (0.2, 0.0)])
def test_rod_end_hits_floor(th, e):
    y0 = 1.0
    eom = planar_rod(L, M, G, phi0=th, y0=y0)
    h = y0 - L / 2 * np.sin(th)                     # height of end a
    t_hit = np.sqrt(2 * h / G)
    r = simulate_with_contacts(eom, [floor_at("a", e), floor_at("b", e)], t_hit + 1e-3, points=2,
                               rtol=1e-11, atol=1e-12)
    assert r.success, r.message
    imp = [ev for ev in r.events if ev["kind"] == "impact"]
    assert imp[0]["contact"] == "floor_a"
    assert imp[0]["time"] == pytest.approx(t_hit, abs=1e-9)
    v = G * t_hit
    c2 = np.cos(th) ** 2
    P = (1 + e) * M * v / (1 + 3 * c2)
    assert imp[0]["impulse"] == pytest.approx(P, rel=1e-8)
    I = M * L ** 2 / 12
    assert imp[0]["energy_change"] == pytest.approx(-(1 - e * e) / 2 * v * v / (1 / M + L * L * c2 / (4 * I)), rel=1e-8)
    if e == 0.0:
        # a plastic impact at a speed above rest_speed: the end stays on the floor only while pushed
        assert imp[0]["speed_after"] == pytest.approx(0.0, abs=1e-12)
    # spin and vertical speed right after: integrate back by the 1 ms of free flight / pivoting
    # is not closed-form, so check them at the impact with a run that ends just after it
    r2 = simulate_with_contacts(eom, [floor_at("a", e)], t_hit + 1e-9, points=2, rtol=1e-11, atol=1e-12)
    vy, w = r2.qd[-1, 1], r2.qd[-1, 2]
    assert w == pytest.approx(-6 * (1 + e) * v * np.cos(th) / (L * (1 + 3 * c2)), rel=1e-6)
    assert vy == pytest.approx(-v + P / M, abs=1e-6)


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
def test_fixation_of_rod_end():
    v = 2.0
    eom = planar_rod(L, M, 0.0, phi0=0.0, y0=0.0, vy0=v)
    t_fix = 0.25
    r = simulate_with_contacts(eom, [], 1.0, points=101, fixations=[Fixation(point="a", time=t_fix, name="catch")],
                               rtol=1e-10, atol=1e-12)
    assert r.success, r.message
    assert [e["kind"] for e in r.events] == ["fixation"]
    ev = r.events[0]
    assert ev["time"] == t_fix and ev["contact"] == "catch"
    T0 = 0.5 * M * v ** 2
    assert ev["energy_change"] == pytest.approx(-T0 / 4, rel=1e-10)
    # impulse on the end: -m v / 4 (it stops the end: m(v_cm' - v) = P with v_cm' = w L/2 = 3v/4)
    assert ev["impulse"][1] == pytest.approx(-M * v / 4, rel=1e-10)
    after = r.t > t_fix
    w = 3 * v / (2 * L)
    assert r.qd[after, 2] == pytest.approx(np.full(after.sum(), w), rel=1e-8)
    # the end stays where it was caught: (-L/2, v t_fix)
    ax = r.q[after, 0] - L / 2 * np.cos(r.q[after, 2])
    ay = r.q[after, 1] - L / 2 * np.sin(r.q[after, 2])
    assert np.max(np.abs(ax + L / 2)) < 1e-8 and np.max(np.abs(ay - v * t_fix)) < 1e-8
    assert np.max(np.abs(r["energy"][after] - 0.75 * T0)) < 1e-8
    # before the fixation: free translation
    before = r.t < t_fix
    assert r.q[before, 1] == pytest.approx(v * r.t[before], abs=1e-12)


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
def test_fixation_energy_is_kinetic_energy_of_lost_velocities():
    """Carnot: dT = -1/2 (q'+ - q'-)^T M (q'+ - q'-) for an impulsive constraint (e = 0)."""
    v = np.array([0.3, -1.1, 2.5])
    eom = planar_rod(L, M, G, phi0=0.4, y0=2.0, vx0=v[0], vy0=v[1], w0=v[2])
    r = simulate_with_contacts(eom, [], 0.2, points=2, fixations=[Fixation(point="b", time=0.0)],
                               rtol=1e-10, atol=1e-12)
    ev = r.events[0]
    rr = simulate_with_contacts(eom, [], 1e-12, points=2, fixations=[Fixation(point="b", time=0.0)])
    vp = rr.qd[0]
    Mm = np.diag([M, M, M * L ** 2 / 12])
    dv = vp - v
    assert ev["energy_change"] == pytest.approx(-0.5 * dv @ Mm @ dv, rel=1e-10)
    # point b is at rest right after
    ph = 0.4
    vb = vp[:2] + vp[2] * L / 2 * np.array([-np.sin(ph), np.cos(ph)])
    assert np.max(np.abs(vb)) < 1e-12
