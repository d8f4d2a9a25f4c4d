"""Bad input to simulations with contacts: diagnostics and usage errors, never tracebacks;
a run that stops early keeps its results and says when and why."""
import dataclasses

import numpy as np
import pytest

from imp_models import ball
from mechdsl import ir
from mechdsl.diagnostics import MechError, UsageError
from mechdsl.impacts import events_table, print_events, simulate_with_contacts


def test_start_state_penetrating_a_contact():
    eom, floor = ball(h0=-0.01)
    with pytest.raises(MechError) as ex:
        simulate_with_contacts(eom, [floor], 1.0)
    assert ex.value.first.code == "E701" and "penetrates contact 'floor'" in ex.value.first.message


@pytest.mark.parametrize("method, text", [("nonsense", "unknown method"), ("stormer-verlet", "symplectic")])
def test_bad_method(method, text):
    eom, floor = ball()
    with pytest.raises(UsageError, match=text):
        simulate_with_contacts(eom, [floor], 1.0, method=method)


def test_bad_options():
    eom, floor = ball()
    with pytest.raises(UsageError, match="not an output"):
        simulate_with_contacts(eom, [floor], 1.0, outputs=["nope"])
    with pytest.raises(UsageError, match="unknown option"):
        simulate_with_contacts(eom, [floor], 1.0, tolerance=3)
    with pytest.raises(UsageError, match="impact order"):
        simulate_with_contacts(eom, [floor], 1.0, impact_order="random")
    with pytest.raises(UsageError, match="after the start"):
        simulate_with_contacts(eom, [floor], -1.0)


def test_restitution_out_of_range():
    eom, floor = ball()
    bad = dataclasses.replace(floor, fields=tuple((k, ir.Const(1.5) if k == "e" else v) for k, v in floor.fields))
    with pytest.raises(MechError, match="restitution"):
        simulate_with_contacts(eom, [bad], 1.0)


def test_point_contact_without_point_kinematics():
    eom, floor = ball()
    eom = dataclasses.replace(eom, point_position=None)
    with pytest.raises(MechError) as ex:
        simulate_with_contacts(eom, [floor], 1.0)
    assert ex.value.first.code == "E702"


def test_too_many_events_keeps_results():
    eom, floor = ball(e=0.9)
    r = simulate_with_contacts(eom, [floor], 5.0, points=51, max_events=5)
    assert not r.success
    assert "more than 5 events" in r.message
    assert len(r.events) == 6
    t_fail = r.failure.time
    assert t_fail == pytest.approx(r.events[-1]["time"])
    # every output point before the failure is there, none after
    assert r.t[-1] <= t_fail < r.t[-1] + 0.1 + 1e-12
    assert np.all(np.isfinite(r.q))


def test_events_table():
    eom, floor = ball()
    r = simulate_with_contacts(eom, [floor], 5.0, points=3)
    text = events_table(r.events, max_rows=6)
    lines = text.splitlines()
    assert lines[0].startswith(f"events: {len(r.events)} (") and "impact floor" in lines[0]
    assert len(lines) == 2 + 7 and "more)" in text
    assert events_table([]) == "events: none\n"
    import io

    buf = io.StringIO()
    print_events(r, file=buf)
    assert buf.getvalue() == events_table(r.events)
