"""The shipped contact models (models/*.mech), from .mech text through mechdsl.load to events,
each against its closed form."""
import re

import numpy as np
import pytest
from scipy.special import ellipk

import mechdsl
from conftest import MODELS
from imp_models import ball_closed_form
from mechdsl.cli import main as mech
from mechdsl.impacts import simulate_with_contacts

G = 9.81


def run(file, scene, **kw):
    m = mechdsl.load(MODELS / file, scene=scene)
    s = m.scene_settings
    t_end = kw.pop("t_end", s["stop_time"])
    opts = {k: s[k] for k in ("rest_speed", "impact_order", "points", "rtol", "atol", "method") if k in s}
    opts.update(kw)
    r = simulate_with_contacts(m.eom, None, t_end, **opts)
    assert r.success, r.message
    return m, r


def test_bouncing_ball_components():
    m, r = run("bouncing_ball.mech", "Bounce", atol=1e-12)
    imp = [e for e in r.events if e["kind"] == "impact"]
    times, speeds = ball_closed_form(1.0, 0.8, G, 30)
    assert np.array([e["time"] for e in imp[:30]]) == pytest.approx(times, abs=1e-8)
    apex = np.array([e["speed_after"] ** 2 / (2 * G) for e in imp[:20]])
    assert apex == pytest.approx(0.8 ** (2 * np.arange(1, 21)), abs=1e-9)
    assert r["height"][-1] == pytest.approx(0.0, abs=1e-9)      # at rest at t = 5
    assert r["floor.force"][-1] == pytest.approx(G, rel=1e-8)


def test_bouncing_ball_default_scene_shows_the_bounces(tmp_path):
    """The default scene's output shows what the model is about: the sampled height falls back
    to the floor again and again (at least 15 visible rebounds), and the first rebound's apex
    is e^2 h (closed form; sampling at 5 ms misses the apex by at most g dt^2 / 8 = 3e-5 m)."""
    import csv

    out = tmp_path / "b.csv"
    assert mech(["simulate", str(MODELS / "bouncing_ball.mech"), "-o", str(out), "--no-progress"]) == 0
    rows = list(csv.DictReader(out.open()))
    h = np.array([float(r["height"]) for r in rows])
    v = np.diff(h)
    rebounds = int(np.sum((v[:-1] < 0) & (v[1:] > 0)))
    assert rebounds >= 15 and len(rows) >= 501
    first, second = 0.4515, 1.1740          # the first two impact times (closed form, as above)
    t = np.array([float(r["time"]) for r in rows])
    apex = h[(t > first) & (t < second)].max()
    assert apex == pytest.approx(0.8 ** 2 * 1.0, abs=1e-4)


def test_bouncing_ball_equation_layer_same_events():
    _, a = run("bouncing_ball.mech", "BounceElastic")
    T1 = np.sqrt(2 / G)
    imp = [e for e in a.events if e["kind"] == "impact"]
    assert [e["time"] for e in imp] == pytest.approx([T1 * (2 * k + 1) for k in range(len(imp))], abs=1e-8)
    assert np.max(np.abs(a["energy"] - G)) < 1e-7


def test_pendulum_wall_reverses_omega_times_e():
    m, r = run("pendulum_wall.mech", "Knock", t_end=2.0)
    ev = [e for e in r.events if e["kind"] == "impact"][0]
    thw, e = 0.3, 0.7
    w = np.sqrt(2 * G * (np.cos(thw) - np.cos(1.0)))
    assert ev["speed_before"] == pytest.approx(-np.cos(thw) * w, rel=1e-8)
    assert ev["speed_after"] == pytest.approx(e * np.cos(thw) * w, rel=1e-8)
    assert ev["energy_change"] == pytest.approx(-(1 - e * e) / 2 * w * w, rel=1e-8)


@pytest.mark.parametrize("scene, N", [("Cradle3", 3), ("Cradle5", 5)])
def test_cradle_sequential(scene, N):
    m, r = run("newtons_cradle.mech", scene, t_end=0.6)
    L, th0 = 0.3, 0.4
    t_hit = np.sqrt(L / G) * ellipk(np.sin(th0 / 2) ** 2)
    imp = [e for e in r.events if e["kind"] == "impact"]
    assert len(imp) == N - 1 and all(e["time"] == pytest.approx(t_hit, abs=1e-8) for e in imp)
    v = L * np.sqrt(2 * G / L * (1 - np.cos(th0)))
    assert [e["speed_after"] for e in imp] == pytest.approx([v] * (N - 1), rel=1e-8)
    # half a period of the last ball later it comes back: ball N reached theta0 on the other side
    assert np.max(r.q[:, N - 1]) == pytest.approx(th0, abs=1e-4)      # grid-limited maximum
    assert np.max(np.abs(r["energy"] - r["energy"][0])) < 1e-8


def test_cradle_simultaneous_block():
    m, r = run("newtons_cradle.mech", "Cradle5Simultaneous", t_end=0.3)
    ev = [e for e in r.events if e["kind"] == "impact"][0]
    L, th0, N = 0.3, 0.4, 5
    v = L * np.sqrt(2 * G / L * (1 - np.cos(th0)))
    assert ev["impulse"] == pytest.approx([0.1 * (N - k) * 2 * v / N for k in range(1, N)], rel=1e-8)


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
def test_particle_on_sphere_leaves_at_two_thirds():
    m, r = run("particle_on_sphere.mech", "SlideOff")
    rel = [e for e in r.events if e["kind"] == "release"]
    assert len(rel) == 1
    r2 = simulate_with_contacts(m.eom, None, rel[0]["time"], points=2, rtol=1e-10, atol=1e-12)
    assert r2["cos_th"][-1] == pytest.approx(2 / 3 * np.cos(0.05), abs=1e-7)


def test_falling_rod_first_impact():
    m, r = run("falling_rod.mech", "Drop", t_end=0.4, atol=1e-12)
    ev = r.events[0]
    th, e, L, mass = 0.5, 0.5, 1.0, 1.0
    h = 1 - L / 2 * np.sin(th)
    v = np.sqrt(2 * G * h)
    assert ev["contact"] == "end_a" and ev["time"] == pytest.approx(np.sqrt(2 * h / G), abs=1e-9)
    assert ev["impulse"] == pytest.approx((1 + e) * mass * v / (1 + 3 * np.cos(th) ** 2), rel=1e-8)


def test_falling_rod_comes_to_rest_flat():
    m, r = run("falling_rod.mech", "Drop")
    closes = {e["contact"] for e in r.events if e["kind"] == "close"}
    assert closes == {"end_a", "end_b"}
    assert r["ya"][-1] == pytest.approx(0.0, abs=1e-9) and r["yb"][-1] == pytest.approx(0.0, abs=1e-9)
    assert r["end_a.force"][-1] + r["end_b.force"][-1] == pytest.approx(G, rel=1e-8)


def test_caught_rod_loses_a_quarter():
    m, r = run("falling_rod.mech", "Catch")
    ev = r.events[0]
    assert ev["kind"] == "fixation" and ev["time"] == pytest.approx(0.25, abs=1e-12)
    T0 = 0.5 * 2 * 2 ** 2
    assert ev["energy_change"] == pytest.approx(-T0 / 4, rel=1e-10)
    assert r["der(fly.phi)"][-1] == pytest.approx(3 * 2 / 2, rel=1e-8)


def test_model_simulate_dispatches_to_contacts():
    """Model.simulate (and mechdsl.simulate.simulate) route models with contacts here, with the
    scene's contact settings."""
    m = mechdsl.load(MODELS / "newtons_cradle.mech", scene="Cradle3")
    r = m.simulate(0.5)
    assert r.metadata["simulator"] == "mechdsl.impacts"
    assert r.metadata["options"]["impact_order"] == "sequential"
    assert [e["contact"] for e in r.events if e["kind"] == "impact"] == ["touch[1]", "touch[2]"]
    r = m.simulate(0.5, impact_order="simultaneous")
    assert [e["contact"] for e in r.events if e["kind"] == "impact"] == ["touch[1], touch[2]"]


def test_cli_prints_events(capsys, tmp_path):
    out = tmp_path / "ball.csv"
    rc = mech(["simulate", str(MODELS / "bouncing_ball.mech"), "--t-end", "2", "-o", str(out)])
    text = capsys.readouterr().out
    assert rc == 0
    assert "events: 3 (3 impact floor); total energy change" in text
    # every number says its unit: the total in J, the columns in s, N.s, J and m/s
    assert re.search(r"total energy change -?[0-9.e+-]+ J\n", text)
    assert re.search(r"time \[s\] +event +contact +impulse \[N\.s\] +energy change \[J\] +normal speed -/\+ \[m/s\]", text)
    assert "0.451523641  impact  floor" in text
    import json

    side = json.loads((tmp_path / "ball.json").read_text())
    assert [e["kind"] for e in side["events"]] == ["impact"] * 3
    header = out.read_text().splitlines()[0].split(",")
    assert header[:3] == ["time", "drop.s", "der(drop.s)"] and "floor.force" in header
