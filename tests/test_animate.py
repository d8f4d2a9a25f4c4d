"""mech animate and the drawing of mechanisms (mechdsl.animate): geometry against closed forms,
every shipped model animates, frames change, impacts flash, bad input is a usage error."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import mechdsl
from mechdsl.animate import animate, draw, frame_times
from mechdsl.animate.geometry import build
from mechdsl.animate.stage import FLASH, detect_view
from mechdsl.cli import main
from mechdsl.diagnostics import UsageError

from conftest import MODELS as MODEL_DIR

MODELS = sorted(MODEL_DIR.glob("*.mech"))


def _load(name, **kw):
    return mechdsl.load(MODEL_DIR / f"{name}.mech", **kw)


# ----------------------------------------------------------------------------- geometry


def test_double_pendulum_rod_ends_match_closed_form_at_random_states():
    m = _load("double_pendulum")
    geo = build(m.eom)
    rods = {it.name: it for it in geo.items if it.kind == "rod"}
    rng = np.random.default_rng(7)
    Q = rng.uniform(-np.pi, np.pi, size=(5, 2))
    X = geo.positions(np.zeros(5), Q)
    l = m.parameters["l"]
    for k, (a, b) in enumerate(Q):
        elbow = l * np.array([np.sin(a), -np.cos(a), 0.0])
        tip = elbow + l * np.array([np.sin(a + b), -np.cos(a + b), 0.0])
        assert X[k, :, rods["rod1"].cols] == pytest.approx(np.array([[0, 0, 0], elbow]).T, abs=1e-12)
        assert X[k, :, rods["rod2"].cols] == pytest.approx(np.array([elbow, tip]).T, abs=1e-12)


def test_mapped_evaluation_equals_one_call_per_sample():
    m = _load("slider_crank")
    geo = build(m.eom)
    rng = np.random.default_rng(3)
    t = rng.uniform(0, 1, 4)
    Q = np.tile(m.eom.start()[0], (4, 1)) + rng.normal(0, 0.1, (4, m.eom.n))
    X = geo.positions(t, Q)
    for k in range(4):
        one = np.array(geo.function(t[k], Q[k], geo.p)[0])
        assert X[k] == pytest.approx(one, abs=1e-14)


def test_box_outline_is_its_size_and_sphere_radius_is_its_parameter():
    cart = build(_load("cart_pole").eom)
    solid = next(it for it in cart.items if it.kind == "solid")
    X = cart.positions([0.0], [np.zeros(2)])[0][:, solid.cols]
    assert X.max(axis=1) - X.min(axis=1) == pytest.approx([0.4, 0.2, 0.2])
    ball = build(_load("bouncing_ball").eom)
    sphere = next(it for it in ball.items if it.kind == "sphere")
    assert sphere.radius == pytest.approx(0.1)


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
def test_plane_detection():
    assert detect_view(np.zeros((3, 3, 2)) + np.array([1.0, 2.0, 0.0])[None, :, None], [0, 1]) == "xy"
    X = np.random.default_rng(0).normal(size=(4, 3, 3))
    assert detect_view(X, [0, 1, 2]) == "3d"
    X[:, 1, :] = 0.5
    assert detect_view(X, [0, 1, 2]) == "xz"
    assert build(_load("double_pendulum").eom).anchors
    r = _load("heavy_top").simulate(0.3, points=4)
    assert animate(r, r.source_model, fps=10).view == "3d"


# ----------------------------------------------------------------------------- frames


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
def test_frames_change_over_time_and_the_clock_runs():
    m = _load("pendulum")
    r = m.simulate(1.0, points=11)
    anim = animate(r, m, fps=10)
    assert len(anim) == 11 and anim.view == "xy"
    a, b = np.array(anim.frame(0)), np.array(anim.frame(5))
    assert a.shape == b.shape and (a != b).any(axis=2).sum() > 200      # the bob moved
    assert anim.times == pytest.approx(np.linspace(0, 1, 11))


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
def test_impacts_flash_in_the_frames_right_after_them():
    m = _load("bouncing_ball")
    r = m.simulate(0.6, points=61)
    t_hit = np.sqrt(2 * 1.0 / 9.81)                 # drop height 1 m
    assert any(abs(e["time"] - t_hit) < 1e-6 for e in r.events if e["kind"] == "impact")
    anim = animate(r, m, fps=100)
    flash = np.round(255 * np.array([int(FLASH[i:i + 2], 16) / 255 for i in (1, 3, 5)]))

    def flashing(k):
        px = np.array(anim.frame(k))[:, :, :3].astype(int)
        return (np.abs(px - flash).sum(axis=2) < 10).sum()

    after = int(np.searchsorted(anim.times, t_hit))
    assert flashing(after) > 20
    assert flashing(after - 10) == 0 and flashing(0) == 0


def test_frame_times_and_speed():
    assert frame_times(0.0, 2.0, 30, 1.0)[-1] == pytest.approx(2.0)
    assert len(frame_times(0.0, 2.0, 30, 2.0)) == 31
    with pytest.raises(UsageError):
        frame_times(0.0, 1.0, 0.0, 1.0)
    with pytest.raises(UsageError, match="too many"):
        frame_times(0.0, 1e6, 30, 1.0)


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
def test_draw_returns_a_figure_at_the_start_and_at_a_time():
    from matplotlib.figure import Figure

    m = _load("double_pendulum")
    f0 = m.draw()
    f1 = m.draw(t=0.5)
    assert isinstance(f0, Figure) and isinstance(f1, Figure)
    with pytest.raises(UsageError, match="coordinates"):
        draw(m, q=[1.0, 2.0, 3.0])


def test_model_without_bodies_is_drawn_as_bars(tmp_path):
    m = _load("pendulum", model="PendulumLagrange")
    r = m.simulate(0.5, points=6)
    anim = animate(r, m, fps=10)
    assert anim.view == "bars"
    assert (np.array(anim.frame(0)) != np.array(anim.frame(5))).any()


# ----------------------------------------------------------------------------- every model, files


# the four most expensive to draw (0.3 .. 1.3 s each) run in the slow set; by default the others
# cover the same kinds (a constrained linkage: four_bar, slider_crank; a chain: double_pendulum;
# 3-D bodies: heavy_top; contacts: bouncing_ball, newtons_cradle), and the slow
# test_every_shipped_model_animates_from_the_command_line animates every model
_DRAWN_SLOWLY = {"nfourbar", "andrews", "nlink_pendulum", "arm7"}


@pytest.mark.slow_cases('falling_rod', 'pendulum_wall')  # CPU budget: the cheaper tests of this file stay in the default run
@pytest.mark.parametrize("path", [pytest.param(p, marks=pytest.mark.slow) if p.stem in _DRAWN_SLOWLY else p
                                  for p in MODELS], ids=[p.stem for p in MODELS])
def test_every_shipped_model_draws_moving_frames(path, tmp_path):
    """Three frames of each model from its start state nudged (no simulation: rendering only)."""
    from types import SimpleNamespace

    m = mechdsl.load(path)
    q0 = m.eom.start()[0]
    Q = q0 + np.outer([0.0, 0.05, 0.1], np.ones_like(q0))
    fake = SimpleNamespace(t=np.array([0.0, 0.05, 0.1]), q=Q, events=[], failure=None)
    anim = animate(fake, m, fps=20, speed=1.0, size=(160, 120))
    assert len(anim) == 3
    anim.save(tmp_path / "a.gif")
    assert (tmp_path / "a.gif").stat().st_size > 500
    assert (np.array(anim.frame(0)) != np.array(anim.frame(2))).any()


@pytest.mark.slow
@pytest.mark.parametrize("path", MODELS, ids=[p.stem for p in MODELS])
def test_every_shipped_model_animates_from_the_command_line(path, tmp_path, capsys):
    out = tmp_path / f"{path.stem}.gif"
    assert main(["animate", str(path), "-o", str(out), "--t-end", "0.1", "--fps", "20", "--speed", "1",
                 "--size", "160x120"]) == 0
    from PIL import Image

    with Image.open(out) as im:
        assert im.n_frames == 3 and im.size == (160, 120)
    assert "wrote" in capsys.readouterr().out


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
def test_html_page_is_self_contained_and_replaceable(tmp_path):
    out = tmp_path / "p.html"
    args = ["animate", str(MODEL_DIR / "pendulum.mech"), "-o", str(out), "--t-end", "0.2", "--fps", "10",
            "--speed", "1", "--trail", "bob"]
    assert main(args) == 0
    text = out.read_text()
    assert text.count("iVBOR") == 3                      # three PNG frames inline
    assert "http://" not in text and "https://" not in text and "<script src" not in text
    assert 'id="mechdsl-' in text and "play" in text and 'type="range"' in text
    assert main(args) == 0                               # our own file: replaced without --force


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
def test_the_same_animation_twice_is_byte_identical(tmp_path):
    a, b = tmp_path / "a.gif", tmp_path / "b.gif"
    for out in (a, b):
        assert main(["animate", str(MODEL_DIR / "double_pendulum.mech"), "-o", str(out), "--t-end", "0.2",
                     "--fps", "10", "--size", "120x100"]) == 0
    assert a.read_bytes() == b.read_bytes()


# ----------------------------------------------------------------------------- bad input


@pytest.mark.parametrize("extra, message", [
    (["--view", "top"], "unknown view 'top' (views: auto, xy, xz, yz, 3d)"),
    (["--trail", "rod2.c"], "no point named 'rod2.c'"),
    (["--fps", "0"], "--fps must be a positive number"),
    (["--speed", "-1"], "--speed must be a positive number"),
    (["--size", "big"], "--size expects WIDTHxHEIGHT"),
    (["--t-end", "-1"], "must be after the start time"),
])
def test_bad_options_are_usage_errors(extra, message, tmp_path, capsys):
    rc = main(["animate", str(MODEL_DIR / "double_pendulum.mech"), "-o", str(tmp_path / "x.gif")] + extra)
    err = capsys.readouterr().err
    assert rc == 2 and message in err and "Traceback" not in err


def test_unsupported_extension_names_the_supported_ones(tmp_path, capsys):
    rc = main(["animate", str(MODEL_DIR / "pendulum.mech"), "-o", str(tmp_path / "x.avi")])
    err = capsys.readouterr().err
    assert rc == 2 and "cannot write '.avi' animations; supported: .gif" in err and ".html" in err


def test_mp4_without_ffmpeg_says_so(tmp_path, capsys, monkeypatch):
    monkeypatch.setattr("shutil.which", lambda name: None)
    rc = main(["animate", str(MODEL_DIR / "pendulum.mech"), "-o", str(tmp_path / "x.mp4")])
    err = capsys.readouterr().err
    assert rc == 2 and "no 'ffmpeg'" in err and ".gif" in err


def test_missing_folder_and_foreign_file_are_refused_before_any_work(tmp_path, capsys):
    rc = main(["animate", str(MODEL_DIR / "pendulum.mech"), "-o", str(tmp_path / "nope" / "x.gif")])
    assert rc == 2 and "does not exist" in capsys.readouterr().err
    foreign = tmp_path / "mine.gif"
    foreign.write_bytes(b"GIF89a not ours")
    rc = main(["animate", str(MODEL_DIR / "pendulum.mech"), "-o", str(foreign)])
    assert rc == 2 and "--force" in capsys.readouterr().err
    assert foreign.read_bytes() == b"GIF89a not ours"


def test_mp4_frames_are_piped_to_ffmpeg(tmp_path, monkeypatch, capsys):
    """Our side of the ffmpeg pipe (the machine has no ffmpeg): a stand-in program records the
    arguments and the raw frames it receives."""
    import os
    import stat
    import sys

    fake = tmp_path / "bin" / "ffmpeg"
    fake.parent.mkdir()
    fake.write_text(f"#!{sys.executable}\n"
                    "import sys\n"
                    "data = sys.stdin.buffer.read()\n"
                    "args = sys.argv[1:]\n"
                    "open(args[-1], 'wb').write(' '.join(args[:-1]).encode() + b'\\n' + str(len(data)).encode())\n")
    fake.chmod(fake.stat().st_mode | stat.S_IXUSR)
    monkeypatch.setenv("PATH", f"{fake.parent}{os.pathsep}{os.environ['PATH']}")
    out = tmp_path / "p.mp4"
    assert main(["animate", str(MODEL_DIR / "pendulum.mech"), "-o", str(out), "--t-end", "0.2", "--fps", "10",
                 "--speed", "1", "--size", "100x80"]) == 0
    args, nbytes = out.read_text().split("\n")
    assert "-s 100x80" in args and "-r 10" in args and "-pix_fmt rgba" in args
    assert int(nbytes) == 3 * 100 * 80 * 4                       # three RGBA frames


BEAD = """model Bead "sin(s) = t: the mass matrix cos(s)^2 is singular at t = 1"
  parameter Real m = 1;
  coordinate Real s(start = 0, speed = 1);
equation
  kinetic = 1/2*m*cos(s)^2*der(s)^2;
end Bead;
"""


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
def test_a_failed_run_is_animated_up_to_the_failure_and_says_so(tmp_path, capsys):
    src = tmp_path / "bead.mech"
    src.write_text(BEAD)
    out = tmp_path / "bead.gif"
    assert main(["animate", str(src), "-o", str(out), "--t-end", "3", "--fps", "10"]) == 1
    cap = capsys.readouterr()
    assert "simulation failed at t = 1" in cap.err and "animated up to t = 1" in cap.err
    assert "11 frames at 10 fps, 1 s of model time" in cap.out
    from PIL import Image

    with Image.open(out) as im:
        assert im.n_frames == 11


# ----------------------------------------------------------------------------- frame timing (issue 27)


@pytest.mark.parametrize("fps", [30, 24, 25, 50, 12.5, 7])
def test_gif_frame_delays_add_up_to_the_frame_rate(fps):
    from mechdsl.animate.writer import gif_durations

    n = 97
    d = np.array(gif_durations(n, fps))
    assert (d % 10 == 0).all() and d.min() >= 20                      # whole centiseconds, none a browser stretches
    starts = np.concatenate([[0], np.cumsum(d)])
    assert np.abs(starts - 1000 * np.arange(n + 1) / fps).max() <= 5.0   # every frame starts within half a centisecond


def test_a_30_fps_gif_plays_at_30_fps(tmp_path):
    from PIL import Image

    m = _load("pendulum")
    r = m.simulate(1.0, points=31)
    out = animate(r, m, fps=30, speed=1.0, size=(100, 80)).save(tmp_path / "p.gif")
    total = 0
    with Image.open(out) as im:
        for k in range(im.n_frames):
            im.seek(k)
            total += im.info["duration"]
        n = im.n_frames
    assert n == 31 and total == pytest.approx(1000 * 31 / 30, abs=5)   # before: 31 x 30 ms, 11% fast


def test_a_gif_faster_than_50_fps_is_refused_before_any_work(tmp_path, capsys):
    rc = main(["animate", str(MODEL_DIR / "pendulum.mech"), "-o", str(tmp_path / "x.gif"), "--fps", "60"])
    err = capsys.readouterr().err
    assert rc == 2 and "a GIF cannot play 60 frames per second" in err and "--fps 50" in err
    assert not (tmp_path / "x.gif").exists()


def test_pick_speed_slows_short_runs_to_nice_numbers():
    from mechdsl.animate import pick_speed

    assert pick_speed(10.0) == 1.0 and pick_speed(1.0) == 1.0
    assert pick_speed(0.03) == pytest.approx(0.01)
    assert pick_speed(0.5) == pytest.approx(0.2)
    assert pick_speed(0.1) == pytest.approx(0.05)
    for d in np.geomspace(1e-6, 0.999, 40):
        s = pick_speed(d)
        assert 2.0 <= d / s <= 10.0 + 1e-9                            # plays 2 to 10 s
    with pytest.raises(UsageError, match="use --speed 0.9 or less"):
        frame_times(0.0, 0.03, 30, 1.0)


def test_pick_speed_speeds_long_runs_up_to_play_at_most_a_minute():
    """A hundred Kepler orbits (628 s) would be 18850 GIF frames in real time (minutes and GBs to
    write); without --speed a run longer than a minute plays for 24 to 60 s."""
    from mechdsl.animate import pick_speed

    assert pick_speed(60.0) == 1.0 and pick_speed(628.3) == pytest.approx(20.0)
    for d in np.geomspace(60.001, 1e7, 40):
        s = pick_speed(d)
        assert 24.0 - 1e-9 <= d / s <= 60.0 + 1e-9                           # (5 / 2 apart)
        mantissa = s / 10.0 ** np.floor(np.log10(s) + 1e-12)
        assert min(abs(mantissa - m) for m in (1, 2, 5)) < 1e-9                 # a nice number
    assert len(frame_times(0.0, 628.3, 30)) == 943


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
def test_a_long_run_animates_in_fast_motion(tmp_path, capsys):
    out = tmp_path / "p.html"
    assert main(["animate", str(MODEL_DIR / "pendulum.mech"), "--model", "Pendulum", "--t-end", "120", "--fps", "2",
                 "--size", "80x60", "-o", str(out)]) == 0
    cap = capsys.readouterr()
    assert "the run lasts 120 s: animating it at --speed 2 (fast motion, 60 s of playback" in cap.err
    assert "121 frames at 2 fps at speed 2, 120 s of model time" in cap.out


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
def test_andrews_short_scene_animates_in_slow_motion(tmp_path, capsys):
    """`mech animate models/andrews.mech -o a.gif` (0.03 s; before: "end time 0.0 .. 0.0")."""
    from PIL import Image

    out = tmp_path / "a.gif"
    assert main(["animate", str(MODEL_DIR / "andrews.mech"), "-o", str(out), "--size", "160x120"]) == 0
    cap = capsys.readouterr()
    assert "--speed 0.01 (slow motion, 3 s of playback; --speed sets another)" in cap.err
    assert "91 frames at 30 fps at speed 0.01, 0.03 s of model time" in cap.out
    total = 0
    with Image.open(out) as im:                  # (Pillow merges repeated frames, adding their delays)
        for k in range(im.n_frames):
            im.seek(k)
            total += im.info["duration"]
    assert total == pytest.approx(1000 * 91 / 30, abs=5)
