"""A ball dropped onto a ball resting on the floor: a persistent contact takes part in an impact.

The resting ball's floor contact is closed (it carries the weight).  With e = 1 the upper
ball bounces back with its impact speed and the lower ball stays, whichever way the touching
pair is resolved: sequentially (upper-lower, then lower-floor, then upper-lower again) or
simultaneously (the lower ball and the floor act as one immovable body)."""
import numpy as np
import pytest

from imp_models import stack
from mechdsl.impacts import simulate_with_contacts

R, H, G = 0.1, 1.0, 9.81


@pytest.mark.parametrize("order, n_impacts", [("sequential", 3), ("simultaneous", 1)])
def test_drop_on_resting_ball(order, n_impacts):
    eom, contacts = stack(R, H, G)
    t_hit = np.sqrt(2 * H / G)
    r = simulate_with_contacts(eom, contacts, t_hit + 0.05, points=3, rtol=1e-10, atol=1e-12, impact_order=order)
    assert r.success, r.message
    assert (r.events[0]["kind"], r.events[0]["contact"], r.events[0]["time"]) == ("close", "floor", 0.0)
    imp = [e for e in r.events if e["kind"] == "impact"]
    assert len(imp) == n_impacts
    assert all(e["time"] == pytest.approx(t_hit, abs=1e-9) for e in imp)
    v = G * t_hit
    # 0.05 s later: the upper ball flies up (leaving with v), the lower one rests on the floor
    assert r.qd[-1, 1] == pytest.approx(v - G * 0.05, rel=1e-8)
    assert r.qd[-1, 0] == pytest.approx(0.0, abs=1e-9) and r.q[-1, 0] == pytest.approx(R, abs=1e-10)
    assert r["floor.force"][-1] == pytest.approx(G, rel=1e-8)
    assert np.max(np.abs(r["energy"] - r["energy"][0])) < 1e-8
