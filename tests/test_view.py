"""Drawing that stands up and the interactive 3-D view (docs/animate.md): the up direction from
gravity, the equivalent ellipsoid of an inertia tensor, the hoop of the bead, quaternions, the
page's data, `mech view` and its bad input.  The page in a real browser: test_view_browser.py."""
from __future__ import annotations

import base64
import hashlib
import math
import re
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

import mechdsl
from mechdsl.animate import animate
from mechdsl.animate.camera import gravity_up, parse_up, screen_axes
from mechdsl.animate.geometry import build
from mechdsl.animate.shapes import circle_through, equivalent_ellipsoid
from mechdsl.cli import main
from mechdsl.diagnostics import UsageError
from mechdsl.view import View, still, view
from mechdsl.view.scene import continuous, quaternions

from conftest import MODELS as MODEL_DIR

MODELS = sorted(MODEL_DIR.glob("*.mech"))


def _load(name, **kw):
    return mechdsl.load(MODEL_DIR / f"{name}.mech", **kw)


def _rotation(rng) -> np.ndarray:
    q, r = np.linalg.qr(rng.normal(size=(3, 3)))
    q = q * np.sign(np.diag(r))
    return q if np.linalg.det(q) > 0 else -q


# ----------------------------------------------------------------------------- up and views


def test_up_is_against_gravity_and_y_without_it():
    assert gravity_up([[0, 0, -9.81]]) == pytest.approx([0, 0, 1])
    assert gravity_up([[0, -9.81, 0]]) == pytest.approx([0, 1, 0])
    assert gravity_up([[3.0, 0, -4.0]]) == pytest.approx([-0.6, 0, 0.8])
    assert gravity_up([]) == pytest.approx([0, 1, 0])
    assert build(_load("heavy_top").eom).up == pytest.approx([0, 0, 1])
    assert build(_load("double_pendulum").eom).up == pytest.approx([0, 1, 0])


@pytest.mark.parametrize("seed", range(6))
def test_the_3d_view_keeps_up_vertical_on_the_screen(seed):
    up = np.random.default_rng(seed).normal(size=3)
    up /= np.linalg.norm(up)
    right, sup, toward = screen_axes("3d", up)
    A = np.array([right, sup, toward])
    assert A @ A.T == pytest.approx(np.eye(3), abs=1e-12)            # orthonormal
    assert np.linalg.det(A) == pytest.approx(1.0)                    # right-handed: no mirror image
    assert right @ up == pytest.approx(0.0, abs=1e-12)               # up has no sideways part
    assert sup @ up == pytest.approx(math.cos(math.radians(20)))      # seen from 20 deg above
    assert toward @ up == pytest.approx(math.sin(math.radians(20)))


def test_the_y_up_3d_view_is_the_one_drawn_before():
    az, el = math.radians(35), math.radians(20)
    d = np.array([math.sin(az) * math.cos(el), math.sin(el), math.cos(az) * math.cos(el)])
    right = np.cross([0, 1, 0], d)
    right /= np.linalg.norm(right)
    assert screen_axes("3d", [0, 1, 0]) == pytest.approx(np.array([right, np.cross(d, right), d]), abs=1e-12)


def test_plane_views_turn_up_to_the_screens_vertical():
    assert screen_axes("xz", [0, 0, 1])[:2] == pytest.approx(np.array([[1, 0, 0], [0, 0, 1]]))
    assert screen_axes("xy", [0, 1, 0])[:2] == pytest.approx(np.array([[1, 0, 0], [0, 1, 0]]))
    assert screen_axes("xy", [0, -1, 0])[:2] == pytest.approx(np.array([[-1, 0, 0], [0, -1, 0]]))
    assert screen_axes("xy", [1, 0, 0])[:2] == pytest.approx(np.array([[0, -1, 0], [1, 0, 0]]))
    assert screen_axes("xy", [0, 0, 1])[:2] == pytest.approx(np.array([[1, 0, 0], [0, 1, 0]]))   # seen from above


def test_parse_up():
    assert parse_up("z") == pytest.approx([0, 0, 1])
    assert parse_up("-x") == pytest.approx([-1, 0, 0])
    assert parse_up("+y") == pytest.approx([0, 1, 0])
    for bad in ("w", "--z", "xy", ""):
        with pytest.raises(UsageError, match="choices: x, y, z, -x, -y, -z"):
            parse_up(bad)


def test_the_heavy_top_stands_above_its_tip():
    """Gravity along -z: the top's centre is drawn above its tip in every frame (with y up, as
    before issue 26, it hung below it)."""
    m = _load("heavy_top")
    r = m.simulate(1.0, points=11)
    anim = animate(r, m, fps=10, speed=1.0)
    assert anim.view == "3d" and anim.stage.up == pytest.approx([0, 0, 1])
    geo = anim.stage.geometry
    centre = next(it for it in geo.items if it.kind == "ellipsoid").cols.start
    tip = next(it for it in geo.items if it.kind == "pin").cols.start
    S = anim.stage.S
    phi, theta = r.q[:, 0], r.q[:, 1]                                 # z-x-z: the axis is Rz(phi) Rx(theta) e_z
    com = m.parameters["l"] * np.stack([np.sin(phi) * np.sin(theta), -np.cos(phi) * np.sin(theta), np.cos(theta)])
    height = screen_axes("3d", [0, 0, 1])[1] @ com
    assert S[:, 1, centre] - S[:, 1, tip] == pytest.approx(height, abs=1e-9)
    assert (height > 0.25).all()
    hung = animate(r, m, fps=10, speed=1.0, up="y").stage.S
    assert hung[0, 1, centre] < hung[0, 1, tip]                       # --up y: the old, hanging picture


# ----------------------------------------------------------------------------- shapes


@pytest.mark.parametrize("seed", range(4))
def test_equivalent_ellipsoid_of_a_uniform_ellipsoid_is_itself(seed):
    rng = np.random.default_rng(seed)
    m = rng.uniform(0.5, 5)
    a, b, c = rng.uniform(0.1, 1.0, 3)
    R = _rotation(rng)
    I = R @ np.diag([m * (b * b + c * c) / 5, m * (a * a + c * c) / 5, m * (a * a + b * b) / 5]) @ R.T
    semi, axes = equivalent_ellipsoid(m, I)
    for s, v in zip(semi, axes.T):
        k = int(np.argmax(np.abs(R.T @ v)))                           # the matching principal axis
        assert abs(R[:, k] @ v) == pytest.approx(1.0, abs=1e-9)
        assert s == pytest.approx([a, b, c][k], rel=1e-9)
    assert np.linalg.det(axes) == pytest.approx(1.0)


def test_a_flat_or_empty_tensor():
    semi, _ = equivalent_ellipsoid(2.0, np.diag([0.0, 0.0, 0.2]))     # a planar body: I3 = I1 + I2
    assert semi.max() == pytest.approx(math.sqrt(5 * 0.2 / 4))
    assert semi.min() == pytest.approx(0.05 * semi.max())             # drawn thin, not absent
    assert equivalent_ellipsoid(1.0, np.zeros((3, 3))) is None
    assert equivalent_ellipsoid(0.0, np.eye(3)) is None


BODY = """model Plate
  parameter Real m = 2;
  Gravity gravity(g = {0, 0, -9.81});
  Body plate(m = m, r_cm = {0.3, 0, 0}, I_11 = 0.0125, I_22 = 0.0325, I_33 = 0.0425);
  Revolute hinge(parent = world, child = plate, axis = {0, 1, 0}, phi(start = 0.2, speed = 0));
end Plate;
"""


def test_a_general_body_is_drawn_as_its_inertia_ellipsoid(tmp_path):
    """The semi-axes drawn (measured in the world, at another angle than the start) are
    a^2 = 5 (I2 + I3 - I1) / (2 m) and cyclically; the ellipsoid sits on the centre of mass."""
    src = tmp_path / "plate.mech"
    src.write_text(BODY)
    m = mechdsl.load(src)
    geo = build(m.eom)
    e = next(it for it in geo.items if it.kind == "ellipsoid")
    X = geo.positions([0.0], [[0.7]])[0][:, e.cols]
    lengths = sorted(np.linalg.norm(X[:, 1:] - X[:, :1], axis=0))
    a2 = 5 / (2 * 2) * (0.0325 + 0.0425 - 0.0125)
    b2 = 5 / (2 * 2) * (0.0125 + 0.0425 - 0.0325)
    c2 = 5 / (2 * 2) * (0.0125 + 0.0325 - 0.0425)
    assert lengths == pytest.approx(sorted(np.sqrt([a2, b2, c2])), rel=1e-9)
    hinge = np.zeros(3)
    assert np.linalg.norm(X[:, 0] - hinge) == pytest.approx(0.3)       # centred on the centre of mass
    kinds = [it.kind for it in geo.items]
    assert "link" in kinds                                           # its frame joined to its centre


def test_bead_on_hoop_hoop_carries_the_bead():
    """The hoop (radius R about the hoop frame's origin, in the frame turning about y by omega t)
    holds the bead at every state, and turns with the frame."""
    m = _load("bead_on_hoop")
    geo = build(m.eom)
    hoop = next(it for it in geo.items if it.kind == "hoop")
    bead = next(it for it in geo.items if it.kind == "point" and it.body == "bead").cols.start
    assert not any(it.kind == "arm" for it in geo.items)
    R, omega = m.parameters["R"], m.parameters["omega"]
    rng = np.random.default_rng(4)
    t = rng.uniform(0, 3, 5)
    Q = rng.uniform(-np.pi, np.pi, (5, 1))
    X = geo.positions(t, Q)
    for k in range(5):
        ring = X[k][:, hoop.cols]
        normal = np.array([math.sin(omega * t[k]), 0.0, math.cos(omega * t[k])])     # R_y(omega t) z
        assert np.linalg.norm(ring, axis=0) == pytest.approx(R, rel=1e-12)
        assert np.abs(normal @ ring).max() < 1e-12
        assert np.linalg.norm(X[k][:, bead]) == pytest.approx(R, rel=1e-12)
        assert abs(normal @ X[k][:, bead]) < 1e-12


def test_circle_through_three_points():
    rng = np.random.default_rng(1)
    c, r, R = rng.normal(size=3), 0.7, _rotation(rng)
    pts = [c + r * R @ [math.cos(a), math.sin(a), 0] for a in (0.3, 1.9, 4.0)]
    centre, normal, radius = circle_through(*pts)
    assert centre == pytest.approx(c) and radius == pytest.approx(r) and abs(normal @ R[:, 2]) == pytest.approx(1)
    assert circle_through(np.zeros(3), np.ones(3), 2 * np.ones(3)) is None


# ----------------------------------------------------------------------------- the page's data


def test_quaternions_agree_with_scipy_including_half_turns():
    from scipy.spatial.transform import Rotation

    rng = np.random.default_rng(2)
    Rs = [_rotation(rng) for _ in range(50)]
    Rs += [Rotation.from_rotvec(np.pi * v / np.linalg.norm(v)).as_matrix() for v in rng.normal(size=(10, 3))]
    Rs += [np.eye(3), np.diag([1.0, -1.0, -1.0]), np.diag([-1.0, 1.0, -1.0]), np.diag([-1.0, -1.0, 1.0])]
    q = quaternions(np.array(Rs))
    ref = Rotation.from_matrix(np.array(Rs)).as_quat()                # x, y, z, w
    assert np.abs(np.einsum("ij,ij->i", q, ref)) == pytest.approx(np.ones(len(Rs)), abs=1e-12)


def test_continuous_quaternions_take_the_short_way():
    q = np.array([[[0, 0, 0, 1.0]], [[0, 0, 0, -1.0]], [[0, 0, 0.1, -0.995]]])
    c = continuous(q)
    assert c[1, 0] @ c[0, 0] > 0 and c[2, 0] @ c[1, 0] > 0
    assert np.abs(c) == pytest.approx(np.abs(q))


def _floats(text, dtype="<f4"):
    return np.frombuffer(base64.b64decode(text), dtype)


def test_page_data_decodes_to_the_geometry():
    m = _load("double_pendulum")
    r = m.simulate(1.0, points=11)
    v = view(r, m, fps=10, speed=1.0, trails=["rod2.b"])
    d = v.data
    times = _floats(d["times"], "<f8")
    assert times == pytest.approx(np.linspace(0, 1, 11))
    geo = build(m.eom, traces=("rod2.b",))
    origins, rotations = geo.poses(times, r.q)
    poses = _floats(d["poses"]).reshape(11, len(d["bodies"]), 7)
    assert poses[:, :, :3] == pytest.approx(origins, abs=1e-6)
    from scipy.spatial.transform import Rotation

    back = Rotation.from_quat(poses[:, :, 3:].reshape(-1, 4).astype(float)).as_matrix().reshape(rotations.shape)
    assert back == pytest.approx(rotations, abs=1e-6)
    trace = next(it for it in d["items"] if it["kind"] == "trace")
    pts = _floats(d["points"]).reshape(11, d["n_points"], 3)
    l = m.parameters["l"]
    a, b = r.q[:, 0], r.q[:, 1]
    tip = np.stack([l * (np.sin(a) + np.sin(a + b)), -l * (np.cos(a) + np.cos(a + b)), 0 * a], axis=1)
    assert pts[:, trace["cols"][0]] == pytest.approx(tip, abs=1e-6)
    assert [s["kind"] for b in d["bodies"] for s in b["solids"]] == ["rod", "rod"]
    assert d["up_label"] == "y"


def test_page_is_one_file_with_three_js_and_no_network(tmp_path):
    m = _load("heavy_top")
    path = still(m).save(tmp_path / "top.html")
    text = path.read_text()
    assert "<script src" not in text and "<link" not in text and "import(\"http" not in text
    assert 'id="mv-three-core"' in text and 'id="mv-orbit"' in text and "mechdsl_view" in text
    assert '"generator": "mechdsl"' in text[:4000]                    # a rerun may replace it
    assert text.count("</script>") == 5


def test_the_same_view_twice_is_byte_identical(tmp_path):
    m = _load("heavy_top")
    r = m.simulate(0.5, points=6)
    a = view(r, m, fps=10, speed=1.0).save(tmp_path / "a.html")
    b = view(r, m, fps=10, speed=1.0).save(tmp_path / "b.html")
    assert a.read_bytes() == b.read_bytes()


def test_vendored_three_js_is_the_release_its_readme_names():
    folder = Path(mechdsl.view.__file__).parent / "vendor" / "three"
    table = (folder / "README.md").read_text()
    listed = dict(re.findall(r"\| `([\w.]+)` \| [^|]+ \| `([0-9a-f]{64})` \|", table))
    assert set(listed) == {"three.core.min.js", "three.module.min.js", "OrbitControls.js", "LICENSE"}
    for name, digest in listed.items():
        assert hashlib.sha256((folder / name).read_bytes()).hexdigest() == digest, name
    assert "MIT License" in (folder / "LICENSE").read_text()


def test_notebook_display_is_the_page_in_an_iframe():
    import html

    v = _load("pendulum").view()
    frame = v._repr_html_()
    assert frame.startswith("<iframe srcdoc=\"") and "mv-three-core" in html.unescape(frame)
    assert html.unescape(frame.split('srcdoc="', 1)[1].split('" style=', 1)[0]) == v.to_html()
    assert repr(v).startswith("<mechdsl View of Pendulum: 1 frames")


def test_model_and_result_views():
    m = _load("double_pendulum")
    assert len(m.view(t_end=0.5)) == 76                           # a half-second run plays at speed 0.2: 2.5 s at 30 fps
    assert len(m.view(q=[0.1, 0.2])) == 1
    r = m.simulate(1.0, points=11)
    assert isinstance(r.view(), View) and len(r.view(fps=10)) == 11
    with pytest.raises(UsageError, match="not both"):
        m.view(t_end=1.0, q=[0.0, 0.0])
    with pytest.raises(UsageError, match="no point named 'nope'"):
        r.view(trails=["nope"])


def test_a_model_without_bodies_is_viewed_as_bars():
    m = _load("andrews")
    v = still(m)
    assert v.mode == "bars" and v.data["names"] == list(m.eom.coords)


@pytest.mark.slow_cases('nfourbar')  # CPU budget: the cheaper tests of this file stay in the default run
@pytest.mark.parametrize("path", MODELS, ids=[p.stem for p in MODELS])
def test_every_shipped_model_views(path, tmp_path):
    """Three frames of each model from its start state nudged (no simulation)."""
    m = mechdsl.load(path)
    q0 = m.eom.start()[0]
    fake = SimpleNamespace(t=np.array([0.0, 0.05, 0.1]), q=q0 + np.outer([0.0, 0.05, 0.1], np.ones_like(q0)),
                           events=[], failure=None)
    v = view(fake, m, fps=20, speed=1.0)
    assert len(v) == 3
    out = v.save(tmp_path / f"{path.stem}.html")
    assert out.stat().st_size < 1_500_000
    if v.mode == "3d":
        poses = _floats(v.data["poses"])
        assert np.isfinite(poses).all() and np.isfinite(v.data["scale"]) and v.data["scale"] > 0


# ----------------------------------------------------------------------------- mech view


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
def test_mech_view_writes_the_page_and_replaces_its_own(tmp_path, capsys):
    out = tmp_path / "arm.html"
    args = ["view", str(MODEL_DIR / "arm7.mech"), "-o", str(out), "--t-end", "0.5", "--fps", "20", "--speed", "1"]
    assert main(args) == 0
    said = capsys.readouterr().out
    assert "wrote" in said and "11 frames" in said and "z up" in said
    v = out.read_text()
    assert len(re.findall(r'"kind":"cylinder"', v)) == 7 and len(re.findall(r'"kind":"box"', v)) == 2
    assert main(args) == 0


def test_mech_view_picks_the_speed_of_a_short_run_and_says_so(tmp_path, capsys):
    assert main(["view", str(MODEL_DIR / "andrews.mech"), "-o", str(tmp_path / "a.html")]) == 0
    cap = capsys.readouterr()
    assert "--speed 0.01 (slow motion, 3 s of playback; --speed sets another)" in cap.err
    assert "91 frames" in cap.out and "bars of the coordinates" in cap.out


def test_mech_view_still(tmp_path, capsys):
    assert main(["view", str(MODEL_DIR / "heavy_top.mech"), "-o", str(tmp_path / "t.html"), "--still"]) == 0
    assert "at its start values, z up" in capsys.readouterr().out


@pytest.mark.parametrize("extra, out, message", [
    ([], "x.gif", "the output must end in .html"),
    (["--up", "north"], "x.html", "--up: unknown direction 'north'"),
    (["--trail", "rod2.c"], "x.html", "no point named 'rod2.c'"),
    (["--speed", "0"], "x.html", "--speed must be a positive number"),
    (["--t-end", "1", "--speed", "100"], "x.html", "use --speed 30 or less"),
    (["--scene", "Nope"], "x.html", "Nope"),
])
def test_mech_view_bad_input_is_a_usage_error(extra, out, message, tmp_path, capsys):
    rc = main(["view", str(MODEL_DIR / "double_pendulum.mech"), "-o", str(tmp_path / out)] + extra)
    err = capsys.readouterr().err
    assert rc == 2 and message in err and "Traceback" not in err


def test_mech_view_refuses_a_foreign_file_and_a_missing_folder(tmp_path, capsys):
    foreign = tmp_path / "mine.html"
    foreign.write_text("<html>mine</html>")
    assert main(["view", str(MODEL_DIR / "pendulum.mech"), "-o", str(foreign)]) == 2
    assert "--force" in capsys.readouterr().err and foreign.read_text() == "<html>mine</html>"
    assert main(["view", str(MODEL_DIR / "pendulum.mech"), "-o", str(tmp_path / "no" / "x.html")]) == 2
    assert "does not exist" in capsys.readouterr().err


@pytest.mark.slow
@pytest.mark.parametrize("path", MODELS, ids=[p.stem for p in MODELS])
def test_every_shipped_model_views_from_the_command_line(path, tmp_path, capsys):
    out = tmp_path / f"{path.stem}.html"
    assert main(["view", str(path), "-o", str(out), "--t-end", "0.2", "--fps", "10", "--speed", "1"]) == 0
    assert "wrote" in capsys.readouterr().out and out.stat().st_size > 700_000


def test_a_failed_run_is_viewed_up_to_the_failure_and_says_so(tmp_path, capsys):
    from test_animate import BEAD                 # the bead whose mass matrix turns singular at t = 1

    src = tmp_path / "bead.mech"
    src.write_text(BEAD)
    out = tmp_path / "bead.html"
    assert main(["view", str(src), "-o", str(out), "--t-end", "3", "--fps", "10"]) == 1
    cap = capsys.readouterr()
    assert "simulation failed at t = 1" in cap.err and "viewed up to t = 1" in cap.err
    assert "11 frames for 10 fps, 1 s of model time" in cap.out
    assert "stopped at t = 1" in out.read_text()
