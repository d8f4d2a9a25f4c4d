"""Bouncing ball against the closed form: impact times, apex heights (ratio e^2), many bounces
per output interval, coming to rest in finite time (no Zeno chatter)."""
import numpy as np
import pytest

from imp_models import ball, ball_closed_form, ball_height
from mechdsl.impacts import simulate_with_contacts

H0, E, G = 1.0, 0.8, 9.81


@pytest.fixture(scope="module")
def bounced():
    eom, floor = ball(H0, E, G)
    # 3 output points over 6 s: dozens of bounces per output interval
    return simulate_with_contacts(eom, [floor], 6.0, points=3, rtol=1e-10, atol=1e-12)


def impacts(r):
    return [e for e in r.events if e["kind"] == "impact"]


def test_impact_times_match_closed_form(bounced):
    imp = impacts(bounced)
    times, speeds = ball_closed_form(H0, E, G, 25)
    got = np.array([e["time"] for e in imp[:25]])
    assert len(imp) >= 25
    assert np.max(np.abs(got - times)) < 1e-8
    # impact speeds too (they come from integrating each flight)
    v = -np.array([e["speed_before"] for e in imp[:25]])
    assert np.max(np.abs(v - speeds)) < 1e-8


def test_apex_heights_shrink_by_e_squared(bounced):
    imp = impacts(bounced)[:20]
    apex = np.array([e["speed_after"] ** 2 / (2 * G) for e in imp])
    expected = H0 * E ** (2 * np.arange(1, 21))
    assert np.max(np.abs(apex - expected)) < 1e-9
    assert np.allclose(apex[1:] / apex[:-1], E ** 2, rtol=1e-6)


def test_energy_lost_per_impact_closed_form(bounced):
    # single contact: dT = -(1 - e^2)/2 (G q'-)^2 / (G M^-1 G^T), here G = 1, M = m = 1
    for ev in impacts(bounced)[:-1]:
        u = ev["speed_before"]
        assert ev["energy_change"] == pytest.approx(-(1 - E ** 2) / 2 * u ** 2, rel=1e-9, abs=1e-15)


def test_comes_to_rest_in_finite_time(bounced):
    """The infinite bounce sequence is cut off when the rebound speed drops below rest_speed
    (1e-3 m/s): one last plastic impact, then persistent contact holding the ball."""
    imp = impacts(bounced)
    times, speeds = ball_closed_form(H0, E, G, 200)
    n_bounce = int(np.sum(E * speeds >= 1e-3))     # impacts that rebound
    assert len(imp) == n_bounce + 1
    assert imp[-1]["time"] == pytest.approx(times[n_bounce], abs=1e-7)
    assert imp[-1]["speed_after"] == pytest.approx(0.0, abs=1e-12)
    t_zeno = np.sqrt(2 * H0 / G) * (1 + 2 * E / (1 - E))   # accumulation point of the impact times
    assert t_zeno - 1e-3 < imp[-1]["time"] < t_zeno
    closes = [e for e in bounced.events if e["kind"] == "close"]
    assert len(closes) == 1 and closes[0]["time"] == imp[-1]["time"]
    # at rest on the floor afterwards, the contact carrying the weight
    assert bounced.t[-1] == pytest.approx(6.0, rel=1e-14)
    assert abs(bounced.q[-1, 0]) < 1e-10 and abs(bounced.qd[-1, 0]) < 1e-10
    assert bounced["floor.force"][-1] == pytest.approx(G, rel=1e-9)
    assert bounced["energy"][-1] == pytest.approx(0.0, abs=1e-9)


def test_dense_grid_matches_closed_form_height():
    eom, floor = ball(H0, E, G)
    r = simulate_with_contacts(eom, [floor], 3.0, points=3001, rtol=1e-10, atol=1e-12)
    assert r.success
    exact = ball_height(r.t, H0, E, G)
    assert np.max(np.abs(r.q[:, 0] - exact)) < 1e-8
    assert np.all(r["floor.gap"] > -1e-11)


def test_many_events_in_one_output_interval_same_as_fine_grid():
    """Event location does not depend on the output grid (CasADi 3.8's cvodes events did:
    see benchmarks/impacts_casadi_events.py)."""
    eom, floor = ball(H0, E, G)
    coarse = simulate_with_contacts(eom, [floor], 4.0, points=2, rtol=1e-10, atol=1e-12)
    fine = simulate_with_contacts(eom, [floor], 4.0, points=401, rtol=1e-10, atol=1e-12)
    a = [e["time"] for e in coarse.events]
    b = [e["time"] for e in fine.events]
    assert len(a) == len(b) > 10
    assert np.max(np.abs(np.array(a) - b)) < 1e-9
    assert coarse.q[-1, 0] == pytest.approx(ball_height([4.0], H0, E, G)[0], abs=1e-8)


def test_elastic_ball_keeps_energy():
    eom, floor = ball(H0, 1.0, G)
    r = simulate_with_contacts(eom, [floor], 5.0, points=11, rtol=1e-10, atol=1e-12)
    T1 = np.sqrt(2 * H0 / G)
    imp = impacts(r)
    assert [e["time"] for e in imp] == pytest.approx([T1 * (2 * k + 1) for k in range(len(imp))], abs=1e-8)
    assert np.max(np.abs(r["energy"] - G * H0)) < 1e-8
    assert all(abs(e["energy_change"]) < 1e-12 for e in imp)


def test_rising_floor_rheonomic_gap():
    """A floor rising at constant speed w (gap = y - w t, an equation-layer gap in time):
    the impact law acts on the relative normal speed, v+ - w = -e (v- - w)."""
    from mechdsl.model import ir

    w = 0.5
    eom, _ = ball(H0, E, G)
    gap = ir.Op("sub", (ir.Coord("y"), ir.Op("mul", (ir.Const(w), ir.Time()))))
    floor = ir.Contact("floor", "gap", (("gap", gap), ("e", ir.Param("e"))))
    r = simulate_with_contacts(eom, [floor], 0.6, points=2, rtol=1e-10, atol=1e-12)
    ev = [e for e in r.events if e["kind"] == "impact"][0]
    t1 = (-w + np.sqrt(w * w + 2 * G * H0)) / G          # H0 - g t^2/2 = w t
    assert ev["time"] == pytest.approx(t1, abs=1e-9)
    v_minus = -G * t1
    assert ev["speed_before"] == pytest.approx(v_minus - w, rel=1e-9)
    v_plus = w - E * (v_minus - w)
    dt = 0.6 - t1
    assert r.q[-1, 0] == pytest.approx(H0 - G * t1 ** 2 / 2 + v_plus * dt - G * dt ** 2 / 2, abs=1e-9)
