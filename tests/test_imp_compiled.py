"""Contact stepping in the compiled loop (impacts/compiled.py, crk.c's gap events) against the
Python contact stepper (compiled=False) and against closed forms."""
import numpy as np
import pytest

import mechdsl
from conftest import needs_cc, MODELS
from imp_models import ball, ball_closed_form, pendulum, pendulum_wall_impacts, wall
from mechdsl.impacts import simulate_with_contacts

G = 9.81


def impacts(r):
    return [e for e in r.events if e["kind"] == "impact"]


def both(eom, contacts, t_end, **kw):
    c = simulate_with_contacts(eom, contacts, t_end, **kw)
    p = simulate_with_contacts(eom, contacts, t_end, compiled=False, **kw)
    return c, p


def agree(c, p, t_tol, x_tol):
    assert c.success and p.success, (c.message, p.message)
    assert [(e["kind"], e["contact"]) for e in c.events] == [(e["kind"], e["contact"]) for e in p.events]
    tc, tp = np.array([e["time"] for e in c.events]), np.array([e["time"] for e in p.events])
    assert tc == pytest.approx(tp, abs=t_tol)
    assert c.t == pytest.approx(p.t, abs=0)
    assert np.hstack([c.q, c.qd]) == pytest.approx(np.hstack([p.q, p.qd]), abs=x_tol)


@needs_cc
@pytest.mark.parametrize("method", ["dop853", "rk45"])
def test_ball_compiled_matches_closed_form_and_python(method):
    """The free flights run in C (every segment but the last, resting one); impact times and
    speeds against the closed form, everything against the Python stepper."""
    eom, floor = ball(1.0, 0.8, G)
    c, p = both(eom, [floor], 4.05, points=9, rtol=1e-10, atol=1e-12, method=method)
    assert c.stats["compiled_segments"] >= 20 and "compiled loop" in c.metadata["compiled"]
    assert "compiled_segments" not in p.stats and p.metadata["compiled"] == "off (requested)"
    times, speeds = ball_closed_form(1.0, 0.8, G, 21)
    imp = impacts(c)
    assert np.array([e["time"] for e in imp[:20]]) == pytest.approx(times[:20], abs=1e-9)
    assert -np.array([e["speed_before"] for e in imp[:20]]) == pytest.approx(speeds[:20], abs=1e-9)
    apex = np.array([e["speed_after"] ** 2 / (2 * G) for e in imp[:20]])
    assert apex == pytest.approx(0.8 ** (2 * np.arange(1, 21)), abs=1e-9)
    agree(c, p, 1e-12, 1e-10)


@needs_cc
def test_output_points_between_and_at_events():
    """Many output points, some exactly at impact-free times and one at the end: the rows written
    by C (interpolant) equal the closed-form height; the number of points does not change the
    events (steps never stop at output times)."""
    from imp_models import ball_height

    eom, floor = ball(1.0, 0.8, G)
    r = simulate_with_contacts(eom, [floor], 2.0, points=401, rtol=1e-10, atol=1e-12)
    coarse = simulate_with_contacts(eom, [floor], 2.0, points=2, rtol=1e-10, atol=1e-12)
    assert r.q[:, 0] == pytest.approx(ball_height(r.t, 1.0, 0.8, G), abs=1e-9)
    assert [e["time"] for e in r.events] == pytest.approx([e["time"] for e in coarse.events], abs=1e-13)


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
@needs_cc
def test_pendulum_wall_compiled_against_elliptic_closed_form():
    th0, thw, e = -1.0, 0.3, 0.9
    eom = pendulum(1.0, G, 1.0, th0)
    c, p = both(eom, [wall(np.sin(thw), e)], 6.0, points=3, rtol=1e-11, atol=1e-13)
    exact, _ = pendulum_wall_impacts(5, 1.0, G, th0, thw, e)
    got = np.array([ev["time"] for ev in impacts(c)[:5]])
    assert got == pytest.approx(np.asarray(exact), abs=1e-8)
    agree(c, p, 1e-10, 1e-8)


SCENES = [("bouncing_ball.mech", "Bounce"), ("bouncing_ball.mech", "BounceElastic"),
          ("pendulum_wall.mech", "Knock"), ("newtons_cradle.mech", "Cradle3"), ("newtons_cradle.mech", "Cradle5"),
          ("newtons_cradle.mech", "Cradle5Simultaneous"), ("falling_rod.mech", "Drop"),
          ("falling_rod.mech", "Catch"), ("particle_on_sphere.mech", "SlideOff")]


@needs_cc
@pytest.mark.slow
@pytest.mark.parametrize("file,scene", SCENES)
def test_every_shipped_contact_scene_compiled_equals_python(file, scene):
    m = mechdsl.load(MODELS / file, scene=scene)
    s = m.scene_settings
    opts = {k: s[k] for k in ("rest_speed", "impact_order", "points", "rtol", "atol", "method") if k in s}
    c, p = both(m.eom, None, s["stop_time"], **opts)
    # chaotic scenes (the rod, the cradle's trains) amplify round-off: tolerance scaled by rtol
    tol = 1e3 * opts.get("rtol", 1e-8)
    agree(c, p, tol, tol)


@needs_cc
def test_no_compile_reaches_the_contact_stepper(tmp_path):
    """`compiled = false` (scene, CLI --no-compile, Model.simulate) steps the contact run in Python;
    the default compiles its free flights."""
    m = mechdsl.load(MODELS / "bouncing_ball.mech", scene="BounceElastic")
    off = m.simulate(t_end=1.0, compiled=False)
    on = m.simulate(t_end=1.0)
    assert off.metadata["compiled"] == "off (requested)" and "compiled_segments" not in off.stats
    assert on.stats["compiled_segments"] >= 1
    assert [e["time"] for e in on.events] == pytest.approx([e["time"] for e in off.events], abs=1e-12)


@needs_cc
def test_progress_is_reported_from_the_compiled_segments():
    """With a progress callback each compiled call (free flights and the impacts applied in C)
    runs in a worker thread and reports the time it reached: non-decreasing, ending at t_end;
    the numbers equal a run without one."""
    eom, floor = ball(1.0, 0.8, G)
    seen = []
    r = simulate_with_contacts(eom, [floor], 3.0, points=5, progress=lambda t, t_end: seen.append((t, t_end)))
    quiet = simulate_with_contacts(eom, [floor], 3.0, points=5)
    assert r.stats["compiled_segments"] >= 5 and len(seen) >= r.stats["compiled_calls"] >= 1
    times = [t for t, _ in seen]
    assert all(b >= a for a, b in zip(times, times[1:]))
    assert times[-1] == pytest.approx(3.0, abs=1e-12) and {te for _, te in seen} == {3.0}
    assert r.q == pytest.approx(quiet.q, abs=1e-14)
    assert [e["time"] for e in r.events] == pytest.approx([e["time"] for e in quiet.events], abs=1e-14)


@needs_cc
def test_nan_gap_hands_the_segment_to_python():
    """A gap that becomes NaN (sqrt of a negative number once the ball is below 0.5 m, so it never
    reaches zero): the compiled loop stops with an error and the segment is stepped in Python,
    which behaves as it always did (no event; the ball falls on).  It used to restart the C loop
    at the last good sample again and again."""
    import casadi as ca

    from mechdsl.impacts.gaps import ContactGap

    from mechdsl.simulation.backends.events import contact_run
    from mechdsl.simulation.settings import from_kwargs

    eom, _ = ball(1.0, 0.8, G)
    gap = ContactGap(name="floor", gap=ca.sqrt(eom.q[0] - 0.5), e=0.8)
    # through the one layer the NaN recorded gap fails the run there, as for Model.simulate
    r = simulate_with_contacts(eom, [gap], 0.6, points=4, rtol=1e-10, atol=1e-12)
    assert not r.success and r.failure.cause == "non-finite output" and "floor.gap" in r.failure.detail
    # the contact back end itself (before the layer's non-finite check): Python takes the segment over
    s = from_kwargs(0.6, points=4, rtol=1e-10, atol=1e-12, contacts=(gap,))
    c, p = contact_run(eom, s), contact_run(eom, s.replace(compiled=False))
    assert c.stats["python_segments"] >= 1 and c.stats["compiled_segments"] <= 2
    assert c.events == [] and p.events == []
    assert c.q[:, 0] == pytest.approx(1.0 - 0.5 * G * c.t ** 2, abs=1e-9)
    agree(c, p, 0, 1e-12)


@needs_cc
def test_run_record_names_the_compiled_loop_when_it_ran():
    """metadata.run names what ran: crk for free flight in the compiled loop, scipy for
    segments stepped in Python, both when a run used both; run.compiled says whether any
    compiled code ran (it read False for compiled contact runs)."""
    m = mechdsl.load(MODELS / "bouncing_ball.mech")
    on, off = m.simulate(3.0), m.simulate(3.0, compiled=False)
    assert on.stats["compiled_segments"] > 0 and on.stats["python_segments"] == 0
    assert on.metadata["run"]["integrator"] == "crk:dop853" and on.metadata["run"]["compiled"] is True
    assert off.stats.get("compiled_segments", 0) == 0
    assert off.metadata["run"]["integrator"] == "scipy:DOP853" and off.metadata["run"]["compiled"] is False


def test_a_repeated_contact_run_reuses_the_contact_functions(monkeypatch):
    """The contact system's CasADi Functions are derived once per model and set of contacts
    (kept in the EOM's workspace): a second run builds none and gives the same numbers."""
    import mechdsl.simulation.backends.events as S    # the contact back end builds them

    calls = []
    real = S.contact_functions
    monkeypatch.setattr(S, "contact_functions", lambda *a: calls.append(1) or real(*a))
    eom, floor = ball(1.0, 0.8, G)
    first = simulate_with_contacts(eom, [floor], 1.0, points=5)
    again = simulate_with_contacts(eom, [floor], 1.0, points=5)
    other, floor2 = ball(1.0, 0.5, G)
    simulate_with_contacts(other, [floor2], 1.0, points=5)            # another model builds its own
    assert len(calls) == 2
    np.testing.assert_allclose(again.q, first.q, rtol=0, atol=1e-14)
