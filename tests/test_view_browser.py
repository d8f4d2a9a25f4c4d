"""The interactive 3-D view (`mech view`) in a real browser: headless Chromium (the system's,
driven by Playwright; nothing downloaded) loads the page from a file:// URL with no console
error and no network request, draws the mechanism with WebGL (SwiftShader, the software
renderer), the canvas changes while playing, the scrubber moves the mechanism, dragging turns
the view, and the page works inside an iframe's srcdoc as notebooks show it.

Slow (a browser start): run with -m slow; .ci/run installs Chromium and runs it by name.
Without Chromium the tests are skipped with that reason (CI installs it, so there they run).
"""
from __future__ import annotations

import io
from contextlib import contextmanager
from pathlib import Path

import numpy as np
import pytest
from conftest import MODELS, chromium_path

# WebGL without a GPU: ANGLE on SwiftShader (Chromium asks for the flag since it is software)
ARGS = ["--no-sandbox", "--disable-dev-shm-usage", "--use-angle=swiftshader", "--enable-unsafe-swiftshader"]


@pytest.fixture(scope="module")
def pages(tmp_path_factory):
    import mechdsl

    folder = tmp_path_factory.mktemp("view")
    m = mechdsl.load(MODELS / "double_pendulum.mech")
    r = m.simulate(2.0, points=61)
    out = {"pendulum": r.view(fps=30, speed=1.0).save(folder / "dp.html"),
           "trail": r.view(fps=30, speed=1.0, trails=["rod2.b"]).save(folder / "dp_trail.html")}
    andrews = mechdsl.load(MODELS / "andrews.mech")
    out["bars"] = andrews.view(t_end=0.03).save(folder / "andrews.html")
    notebook = folder / "notebook.html"
    notebook.write_text("<!DOCTYPE html><html><body><p>a notebook cell</p>\n"
                        + mechdsl.load(MODELS / "heavy_top.mech").view(t_end=0.5)._repr_html_()
                        + "\n</body></html>")
    out["notebook"] = notebook
    from mechdsl.view import still
    from urdf_util import robots_dir

    panda = mechdsl.loads(mechdsl.import_urdf(robots_dir() / "panda_description/urdf/panda.urdf"))
    out["panda_view"] = still(panda, [0.3, -0.8, 0.4, -2.0, 0.5, 1.6, 0.7, 0.03])   # an imported arm, its
    out["panda"] = out["panda_view"].save(folder / "panda.html")                   # visuals placed and turned
    return out


@pytest.fixture(scope="module")
def browser():
    path = chromium_path()
    if path is None:
        pytest.skip("no Chromium on the PATH (apt-get install chromium)")
    from playwright import sync_api

    with sync_api.sync_playwright() as p:
        b = p.chromium.launch(executable_path=path, headless=True, args=ARGS)
        try:
            yield b
        finally:
            b.close()


class Page:
    """A page that records console errors, page errors and every request that is not local."""

    def __init__(self, browser, url):
        self.problems: list[str] = []
        self.page = page = browser.new_page(viewport={"width": 480, "height": 360})
        page.on("console", lambda msg: self.problems.append(f"console {msg.type}: {msg.text}")
                if msg.type in ("error", "warning") else None)
        page.on("pageerror", lambda exc: self.problems.append(f"page error: {exc}"))
        page.on("requestfailed", lambda req: self.problems.append(f"request failed: {req.url}"))
        page.on("request", lambda req: None if req.url.split(":", 1)[0] in ("file", "blob", "data", "about")
                else self.problems.append(f"network request: {req.url}"))
        page.goto(url)

    def ready(self, frame=None):
        (frame or self.page).wait_for_selector("body[data-ready='1']", timeout=30000)

    def canvas(self, frame=None) -> np.ndarray:
        from PIL import Image

        shot = (frame or self.page).locator("#mv-canvas").screenshot()
        return np.asarray(Image.open(io.BytesIO(shot)).convert("RGB")).astype(int)

    def scrub(self, k: int) -> None:
        self.page.evaluate("""(k) => { const r = document.getElementById('mv-range');
                                       r.value = k; r.dispatchEvent(new Event('input')); }""", k)
        self.page.wait_for_function("() => !window.mechdsl_view.state.dirty", timeout=10000)



@contextmanager
def opened(browser, path: Path, wait: bool = True):
    """The page at ``path``, ready; closed after, and then it must have had no problem."""
    p = Page(browser, path.as_uri())
    try:
        if wait:
            p.ready()
        yield p
    finally:
        p.page.close()
    assert p.problems == []


def _changed(a, b) -> int:
    return int((np.abs(a - b).sum(axis=2) > 30).sum())


@pytest.mark.slow
def test_view_loads_plays_scrubs_and_turns(browser, pages):
    with opened(browser, pages["pendulum"]) as p:
        webgl = p.page.evaluate("() => !!window.mechdsl_view.camera")
        assert webgl, p.page.inner_text("#mv-status")
        a = p.canvas()
        assert (a.sum(axis=2) < 600).sum() > 200                          # something is drawn on the white
        p.page.wait_for_timeout(400)
        assert _changed(a, p.canvas()) > 100                              # playing: the canvas changes
        p.page.click("#mv-play")                                          # pause
        assert p.page.inner_text("#mv-play") == "play"
        held = p.page.inner_text("#mv-clock")
        p.page.wait_for_timeout(300)
        assert p.page.inner_text("#mv-clock") == held
        p.scrub(0)
        assert p.page.inner_text("#mv-clock") == "t = 0.000 s"
        start = p.canvas()
        p.scrub(45)
        assert p.page.inner_text("#mv-clock") == "t = 1.500 s"
        later = p.canvas()
        assert _changed(start, later) > 300                               # the scrubber moves the mechanism
        p.scrub(0)
        assert _changed(start, p.canvas()) < 20                           # and back: the same picture
        before = p.page.evaluate("() => window.mechdsl_view.camera.position.toArray()")
        box = p.page.locator("#mv-canvas").bounding_box()
        x, y = box["x"] + box["width"] / 2, box["y"] + box["height"] / 2
        p.page.mouse.move(x, y)
        p.page.mouse.down()
        p.page.mouse.move(x + 120, y + 30, steps=8)                       # orbit drag
        p.page.mouse.up()
        p.page.wait_for_function("() => !window.mechdsl_view.state.dirty", timeout=10000)
        after = p.page.evaluate("() => window.mechdsl_view.camera.position.toArray()")
        assert np.linalg.norm(np.subtract(after, before)) > 0.1
        turned = p.canvas()
        assert _changed(start, turned) > 300                              # the view turned
        p.page.click("#mv-reset")
        p.page.wait_for_function("() => !window.mechdsl_view.state.dirty", timeout=10000)
        assert _changed(start, p.canvas()) < 20


@pytest.mark.slow
def test_view_trail_grows(browser, pages):
    with opened(browser, pages["trail"]) as p:
        p.page.click("#mv-play")

        def red(a):                                                       # the trace's colour, #d62728
            return int((np.abs(a - [214, 39, 40]).sum(axis=2) < 60).sum())
        p.scrub(1)
        short = red(p.canvas())
        p.scrub(45)
        assert red(p.canvas()) > short + 50


@pytest.mark.slow
def test_view_speed_menu_changes_the_pace(browser, pages):
    with opened(browser, pages["pendulum"]) as p:
        p.page.click("#mv-play")
        p.scrub(0)
        p.page.select_option("#mv-speed", "0.1")
        p.page.click("#mv-play")
        p.page.wait_for_timeout(1000)
        slow = p.page.evaluate("() => window.mechdsl_view.state.t")
        assert 0.02 < slow < 0.2                                          # 1 s of playback at 0.1x


@pytest.mark.slow
def test_bars_view_of_a_model_without_bodies(browser, pages):
    with opened(browser, pages["bars"]) as p:
        p.page.click("#mv-play")
        p.scrub(0)
        a = p.canvas()
        p.scrub(90)
        assert p.page.inner_text("#mv-clock") == "t = 0.0300 s"
        assert _changed(a, p.canvas()) > 100


@pytest.mark.slow
def test_view_inside_a_notebooks_iframe(browser, pages):
    with opened(browser, pages["notebook"], wait=False) as p:
        frame = p.page.wait_for_selector("iframe").content_frame()
        p.ready(frame)
        a = p.canvas(frame)
        assert (a.sum(axis=2) < 600).sum() > 200
        p.page.wait_for_timeout(400)
        assert _changed(a, p.canvas(frame)) > 50                          # it plays in the iframe


@pytest.mark.slow
def test_imported_arm_boxes_are_drawn_where_the_page_data_puts_them(browser, pages):
    """What three.js draws: the world corners of every box mesh in the scene (its BoxGeometry and
    matrixWorld after the render) are the corners the page's data gives each Shape of the
    imported Franka Panda (body pose times the solid's centre, quaternion and size; that data is
    checked against Pinocchio's visual placements in tests/test_urdf_visuals.py); some of its
    visuals are turned in their links (the hand, the right finger)."""
    from draw_util import SIGNS, page_solids, quat_matrix

    with opened(browser, pages["panda"]) as p:
        drawn = p.page.evaluate("""() => {
            const out = [];
            window.mechdsl_view.scene.traverse((o) => {
              if (o.isMesh && o.geometry.type === 'BoxGeometry') {
                const g = o.geometry.parameters;
                out.push({size: [g.width, g.height, g.depth], m: o.matrixWorld.elements.slice()});
              }
            });
            return out; }""")
    got = []
    for d in drawn:
        M = np.array(d["m"]).reshape(4, 4).T                            # three.js stores by columns
        got.append(np.array([M[:3, :3] @ (np.array(d["size"]) / 2 * s) + M[:3, 3] for s in SIGNS]))
    expected = []
    for _, o, R, s in page_solids(pages["panda_view"].data):
        if s["kind"] == "box":
            S, c = quat_matrix(*s["quat"]), np.array(s["center"])
            expected.append(np.array([o + R @ (c + S @ (np.array(s["size"]) / 2 * sg)) for sg in SIGNS]))
    assert len(expected) == 11 and len(got) == len(expected)
    for e in expected:
        assert min(np.abs(g - e).max() for g in got) < 1e-5
