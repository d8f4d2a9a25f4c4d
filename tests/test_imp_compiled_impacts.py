"""Impacts applied inside the compiled loop (crk.c impact_in_c, impacts/compiled.py
impact_function): the simple case (one touching contact, restitution, no other rows) never
leaves C between bounces; the records and states equal the Python stepper's, and the closed
forms of the bouncing ball hold."""
import numpy as np
import pytest

from imp_models import ball, ball_closed_form, pendulum, wall
from mechdsl.impacts import simulate_with_contacts
from conftest import needs_cc

G = 9.81


def both(eom, contacts, t_end, **kw):
    return (simulate_with_contacts(eom, contacts, t_end, **kw),
            simulate_with_contacts(eom, contacts, t_end, compiled=False, **kw))


def records_agree(c, p, t_tol, x_tol):
    assert c.success and p.success, (c.message, p.message)
    assert [(e["kind"], e["contact"]) for e in c.events] == [(e["kind"], e["contact"]) for e in p.events]
    for ec, ep in zip(c.events, p.events):
        assert ec["time"] == pytest.approx(ep["time"], abs=t_tol)
        for key in ("impulse", "energy_change", "speed_before", "speed_after"):
            assert ec[key] == pytest.approx(ep[key], abs=x_tol), key
        for side in ("state_before", "state_after"):
            assert ec[side].keys() == ep[side].keys()
            assert list(ec[side].values()) == pytest.approx(list(ep[side].values()), abs=x_tol), side
    assert c.t == pytest.approx(p.t, abs=0)
    assert np.hstack([c.q, c.qd]) == pytest.approx(np.hstack([p.q, p.qd]), abs=x_tol)


@needs_cc
@pytest.mark.parametrize("method", ["dop853", "rk45"])
def test_twenty_bounces_in_one_compiled_call(method):
    """Halfway between the 20th and 21st impact: one C call, 20 impacts applied in C; the
    impact times and the apex heights e^(2k) h0 of the closed form; equal to the Python
    stepper (event times 1e-12, states 1e-11)."""
    h0, e = 1.0, 0.8
    times, speeds = ball_closed_form(h0, e, G, 21)
    t_end = 0.5 * (times[19] + times[20])
    eom, floor = ball(h0, e, G)
    c, p = both(eom, [floor], t_end, points=7, rtol=1e-10, atol=1e-12, method=method)
    assert c.stats["compiled_calls"] == 1 and c.stats["compiled_impacts"] == 20
    imp = [ev for ev in c.events if ev["kind"] == "impact"]
    assert np.array([ev["time"] for ev in imp]) == pytest.approx(times[:20], abs=1e-9)
    apex = np.array([ev["speed_after"] ** 2 / (2 * G) for ev in imp])
    assert apex == pytest.approx(h0 * e ** (2 * np.arange(1, 21)), abs=1e-9)
    records_agree(c, p, 1e-12, 1e-11)


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
@needs_cc
def test_pendulum_wall_impacts_in_c_equal_python():
    """A nonlinear gap (the bob's x against a wall): the projection after each impact is a
    Newton step on the gap; the whole run in C equals the Python stepper."""
    eom = pendulum(1.0, G, 1.0, -1.0)
    c, p = both(eom, [wall(np.sin(0.3), 0.9)], 6.0, points=5, rtol=1e-11, atol=1e-13)
    assert c.stats["compiled_impacts"] >= 5 and c.stats["compiled_calls"] == 1
    records_agree(c, p, 1e-12, 1e-11)


@needs_cc
def test_coming_to_rest_returns_to_python():
    """A rebound slower than rest_speed closes the contact: that impact, and the resting
    contact after it, are Python's (the records agree, the ball ends resting on the floor)."""
    eom, floor = ball(1.0, 0.5, G)
    c, p = both(eom, [floor], 3.0, points=3, rtol=1e-10, atol=1e-12, rest_speed=0.05)
    assert c.stats["compiled_impacts"] >= 3 and c.stats["python_segments"] >= 1
    assert "close" in [ev["kind"] for ev in c.events]
    records_agree(c, p, 1e-12, 1e-11)
    assert c.q[-1, 0] == pytest.approx(0.0, abs=1e-9)


@needs_cc
def test_max_events_still_fails_at_the_event_over_the_limit():
    eom, floor = ball(1.0, 0.8, G)
    c, p = both(eom, [floor], 3.0, points=3, rtol=1e-10, atol=1e-12, max_events=5)
    assert not c.success and not p.success
    assert c.message == p.message
    assert len(c.events) == len(p.events) == 6
