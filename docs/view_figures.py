"""Screenshots of `mech view` for docs/animate.md (docs/figures/view_*.png) and docs/import.md
(docs/figures/import_ur5_view.png), made by the project: each page is written by mechdsl, opened
in headless Chromium (the system's, driven by Playwright, WebGL on SwiftShader), paused at a
chosen time and photographed.  Run from the repository root:

    python docs/view_figures.py               # writes the four figures
    python docs/view_figures.py import_ur5    # writes only those named

Needs Chromium (`apt-get install chromium`) and the test extra (Playwright).
"""
from __future__ import annotations

import io
import shutil
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "src"))

import mechdsl  # noqa: E402

# name -> (model file, seconds simulated, time shown [s], trails)
FIGURES = {
    "heavy_top": ("heavy_top.mech", 2.0, 0.5, ()),
    "four_bar": ("four_bar.mech", 3.0, 1.0, ("coupler.com",)),
    "arm7": ("arm7.mech", 1.0, 0.5, ("hand.com",)),
    # the UR5 of example-robot-data through `mech import`, still at the pose STILL gives (its links
    # drawn as the boxes of their meshes, placed by the URDF's visual origins)
    "import_ur5": ("urdf:ur_description/urdf/ur5_robot.urdf", 0.0, 0.0, ()),
}
TARGET = {"import_ur5": "import_ur5_view.png"}
# start values of the stills (mech view --still --set J.phi.start=...)
STILL = {"import_ur5": {"shoulder_pan_joint.phi": 0.3, "shoulder_lift_joint.phi": -1.2, "elbow_joint.phi": 1.5,
                        "wrist_1_joint.phi": -0.8, "wrist_2_joint.phi": 1.2}}
SIZE = (560, 400)
ARGS = ["--no-sandbox", "--disable-dev-shm-usage", "--use-angle=swiftshader", "--enable-unsafe-swiftshader"]


def page(name: str, folder: Path) -> tuple[Path, int]:
    file, t_end, shown, trails = FIGURES[name]
    if file.startswith("urdf:"):
        sys.path.insert(0, str(ROOT / "tests"))
        from urdf_util import robots_dir

        m = mechdsl.loads(mechdsl.import_urdf(robots_dir() / file[len("urdf:"):]))
    else:
        m = mechdsl.load(ROOT / "models" / file)
    if name in STILL:
        from mechdsl.view import still

        q = [STILL[name].get(c, 0.0) for c in m.eom.coords]
        return still(m, q).save(folder / f"{name}.html"), 0
    r = m.simulate(t_end, points=int(round(30 * t_end)) + 1)
    path = r.view(fps=30, speed=1.0, trails=list(trails)).save(folder / f"{name}.html")
    return path, int(round(30 * shown))


def main(names: list[str]) -> None:
    from PIL import Image
    from playwright.sync_api import sync_playwright

    chromium = shutil.which("chromium") or shutil.which("chromium-browser")
    if chromium is None:
        sys.exit("no Chromium on the PATH (apt-get install chromium)")
    out = ROOT / "docs" / "figures"
    with tempfile.TemporaryDirectory() as tmp, sync_playwright() as p:
        browser = p.chromium.launch(executable_path=chromium, headless=True, args=ARGS)
        try:
            for name in names or FIGURES:
                path, frame = page(name, Path(tmp))
                pg = browser.new_page(viewport={"width": SIZE[0], "height": SIZE[1]})
                pg.goto(path.as_uri())
                pg.wait_for_selector("body[data-ready='1']", timeout=30000)
                pg.click("#mv-play")                                       # pause, then show the frame
                pg.evaluate("""(k) => { const r = document.getElementById('mv-range');
                                        r.value = k; r.dispatchEvent(new Event('input')); }""", frame)
                pg.wait_for_function("() => !window.mechdsl_view.state.dirty")
                shot = Image.open(io.BytesIO(pg.screenshot())).convert("RGB")
                target = out / TARGET.get(name, f"view_{name}.png")
                shot.quantize(colors=96, method=Image.Quantize.MEDIANCUT).save(target, optimize=True)
                print(f"wrote {target.relative_to(ROOT)} ({target.stat().st_size // 1024} kB)")
                pg.close()
        finally:
            browser.close()


if __name__ == "__main__":
    unknown = [n for n in sys.argv[1:] if n not in FIGURES]
    if unknown:
        sys.exit(f"unknown figure {unknown[0]!r} (figures: {', '.join(FIGURES)})")
    main(sys.argv[1:])
