"""Issue 17: each event records the state before and after it, and `output_events` adds result rows
just before and after every event, so the velocity after an impact is read off directly."""
import math
from pathlib import Path

import numpy as np
import pytest

import mechdsl
import mechdsl.examples

MODELS = mechdsl.examples.folder()
BALL = MODELS / "bouncing_ball.mech"


def _ball(e=0.7):
    return mechdsl.load(BALL, model="BouncingBall").with_params(e=e, h=1.0, r=0.1)


def test_event_states_before_and_after_closed_form():
    """First impact after a drop from h: v- = -sqrt(2 g h), v+ = -e v- (Newton's law)."""
    e, g, h = 0.7, 9.81, 1.0
    r = _ball(e).simulate(1.2, points=7)
    first = r.events[0]
    assert first["kind"] == "impact"
    v_minus = -math.sqrt(2 * g * h)
    assert first["time"] == pytest.approx(math.sqrt(2 * h / g), rel=1e-9)
    assert first["state_before"]["der(drop.s)"] == pytest.approx(v_minus, rel=1e-8)
    assert first["state_after"]["der(drop.s)"] == pytest.approx(-e * v_minus, rel=1e-8)
    assert first["state_before"]["drop.s"] == pytest.approx(first["state_after"]["drop.s"], abs=1e-12)
    assert first["state_before"]["drop.s"] == pytest.approx(0.1, abs=1e-8)        # centre at one radius


def test_output_events_rows_pre_and_post():
    e, g, h = 0.7, 9.81, 1.0
    plain = _ball(e).simulate(2.0, points=11)
    r = _ball(e).simulate(2.0, points=11, output_events=True)
    impacts = [ev for ev in r.events if ev["kind"] == "impact"]
    t1 = math.sqrt(2 * h / g)                                 # t_k = t1 (1 + 2 e + ... + 2 e^(k-1))
    times = [t1 * (1 + 2 * sum(e**j for j in range(1, k))) for k in range(1, 5)]
    assert [ev["time"] for ev in impacts] == pytest.approx(times, rel=1e-9)     # 0.45, 1.08, 1.53, 1.84
    side = r["event"]
    assert len(r.t) == 11 + 2 * len(impacts)
    assert np.all(np.diff(r.t) >= 0)
    before, after = np.flatnonzero(side == -1), np.flatnonzero(side == 1)
    assert list(after) == [i + 1 for i in before]
    v_minus = -math.sqrt(2 * g * h)
    for k, (i, j) in enumerate(zip(before, after)):
        assert r.t[i] == r.t[j] == pytest.approx(impacts[k]["time"], rel=1e-12)
        vb, va = r["der(drop.s)"][i], r["der(drop.s)"][j]
        assert va == pytest.approx(-e * vb, rel=1e-8)                  # v+ = -e v-
        assert vb == pytest.approx(v_minus * e**k, rel=1e-7)
    grid = side == 0
    assert np.allclose(r.t[grid], plain.t, rtol=0, atol=1e-12)
    assert np.allclose(r["drop.s"][grid], plain["drop.s"], rtol=1e-9, atol=1e-12)
    assert r.metadata["options"]["output_events"] is True
    assert r.stats["energy_drift_relative"] < 1e-8          # the rows before an impact are not counted as drift
    assert "event" not in plain.signals


def test_output_events_cli_flag(tmp_path, capsys):
    from mechdsl.cli import main

    out = tmp_path / "ball.csv"
    rc = main(["simulate", str(BALL), "--model", "BouncingBall", "--t-end", "1", "--points", "3",
               "--output-events", "--no-progress", "-o", str(out)])    # in this process: the subject is the flag
    assert rc == 0, capsys.readouterr().err
    lines = out.read_text().splitlines()
    header = lines[0].split(",")
    col = header.index("event")
    sides = [float(line.split(",")[col]) for line in lines[1:]]
    assert sides == [0, -1, 1, 0, 0]                 # t = 0, the impact (before, after), t = 0.5, 1


def test_output_events_scene_setting_and_other_problems():
    src = BALL.read_text() + """
scene Events "rows at every event"
  model BouncingBall(e = 0.5);
  stop_time = 1;
  points = 3;
  output_events = true;
end Events;
"""
    r = mechdsl.loads(src, scene="Events").simulate()
    t1 = math.sqrt(2 * 1.0 / 9.81)                      # impacts at t1 and t1 (1 + 2 e) = 2 t1
    assert list(r["event"]) == [0, -1, 1, 0, -1, 1, 0]
    assert r.t[[1, 2, 4, 5]] == pytest.approx([t1, t1, 2 * t1, 2 * t1], rel=1e-9)
    # an ODE problem has no events: the setting is reported as without effect, not silently dropped
    plain = mechdsl.load(MODELS / "pendulum.mech").simulate(1, points=3, output_events=True)
    assert "settings without effect on an ODE problem: output_events = True" in plain.metadata["notes"]
