"""Screenshots of `mech view` for docs/animate.md (docs/figures/view_*.png), made by the project:
each page is written by mechdsl, opened in headless Chromium (the system's, driven by
Playwright, WebGL on SwiftShader), paused at a chosen time and photographed.  Run from the
repository root:

    python docs/view_figures.py        # writes docs/figures/view_heavy_top.png, view_four_bar.png, view_arm7.png

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
}
SIZE = (560, 400)
ARGS = ["--no-sandbox", "--disable-dev-shm-usage", "--use-angle=swiftshader", "--enable-unsafe-swiftshader"]


def page(name: str, folder: Path) -> tuple[Path, int]:
    file, t_end, shown, trails = FIGURES[name]
    m = mechdsl.load(ROOT / "models" / file)
    r = m.simulate(t_end, points=int(round(30 * t_end)) + 1)
    path = r.view(fps=30, speed=1.0, trails=list(trails)).save(folder / f"{name}.html")
    return path, int(round(30 * shown))


def main() -> None:
    from PIL import Image
    from playwright.sync_api import sync_playwright

    chromium = shutil.which("chromium") or shutil.which("chromium-browser")
    if chromium is None:
        sys.exit("no Chromium on the PATH (apt-get install chromium)")
    out = ROOT / "docs" / "figures"
    with tempfile.TemporaryDirectory() as tmp, sync_playwright() as p:
        browser = p.chromium.launch(executable_path=chromium, headless=True, args=ARGS)
        try:
            for name in FIGURES:
                path, frame = page(name, Path(tmp))
                pg = browser.new_page(viewport={"width": SIZE[0], "height": SIZE[1]})
                pg.goto(path.as_uri())
                pg.wait_for_selector("body[data-ready='1']", timeout=30000)
                pg.click("#mv-play")                                       # pause, then show the frame
                pg.evaluate("""(k) => { const r = document.getElementById('mv-range');
                                        r.value = k; r.dispatchEvent(new Event('input')); }""", frame)
                pg.wait_for_function("() => !window.mechdsl_view.state.dirty")
                shot = Image.open(io.BytesIO(pg.screenshot())).convert("RGB")
                target = out / f"view_{name}.png"
                shot.quantize(colors=96, method=Image.Quantize.MEDIANCUT).save(target, optimize=True)
                print(f"wrote {target.relative_to(ROOT)} ({target.stat().st_size // 1024} kB)")
                pg.close()
        finally:
            browser.close()


if __name__ == "__main__":
    main()
