"""The HTML animation page in a real browser: headless Chromium (the system's, driven by
Playwright; nothing is downloaded) loads it with no console error, plays it (the shown frame
changes over time), pauses, and the scrubber shows the frame asked for.

Needs Chromium at the system path (``apt-get install chromium``).  Slow (a browser start):
run with -m slow; .ci/run installs Chromium and runs it.  Without Chromium the test is skipped
with that reason (pytest reports the skip; CI installs it, so there it runs).
"""
from __future__ import annotations

from pathlib import Path

import pytest
from conftest import chromium_path as _chromium

from conftest import CHECKOUT, MODELS, TESTS  # noqa: E402


@pytest.fixture(scope="module")
def page_file(tmp_path_factory):
    import mechdsl

    m = mechdsl.load(MODELS / "pendulum.mech")
    r = m.simulate(1.0, points=11)
    out = tmp_path_factory.mktemp("browser") / "pendulum.html"
    r.animate(fps=10, size=(200, 160)).save(out)
    return out


@pytest.mark.slow
def test_html_animation_plays_in_headless_chromium(page_file):
    browser_path = _chromium()
    if browser_path is None:
        pytest.skip("no Chromium on the PATH (apt-get install chromium)")
    from playwright import sync_api as sync_api
    problems: list[str] = []
    with sync_api.sync_playwright() as p:
        browser = p.chromium.launch(executable_path=browser_path, headless=True,
                                    args=["--no-sandbox", "--disable-gpu", "--disable-dev-shm-usage"])
        try:
            page = browser.new_page()
            page.on("console", lambda msg: problems.append(f"console {msg.type}: {msg.text}")
                    if msg.type in ("error", "warning") else None)
            page.on("pageerror", lambda exc: problems.append(f"page error: {exc}"))
            page.on("requestfailed", lambda req: problems.append(f"request failed: {req.url}"))
            page.goto(page_file.as_uri())
            img = page.locator("img[id$='-img']")
            label = page.locator("span[id$='-time']")
            img.wait_for()
            first_src, first_label = img.get_attribute("src"), label.inner_text()
            page.wait_for_function("(s) => document.querySelector(\"img[id$='-img']\").src !== s", arg=first_src,
                                   timeout=5000)                              # it plays: the frame changes
            assert label.inner_text() != first_label
            shot_a = img.screenshot()
            page.wait_for_timeout(250)
            shot_b = img.screenshot()
            assert shot_a != shot_b                                           # the drawn pixels move
            page.locator("button[id$='-play']").click()                       # pause
            held = img.get_attribute("src")
            page.wait_for_timeout(400)
            assert img.get_attribute("src") == held
            page.evaluate("""() => { const r = document.querySelector("input[type=range]");
                                     r.value = 7; r.dispatchEvent(new Event('input')); }""")
            assert label.inner_text() == "t = 0.700 s"                        # the scrubber's frame
            natural = page.evaluate("() => document.querySelector(\"img[id$='-img']\").naturalWidth")
            assert natural == 200
        finally:
            browser.close()
    assert problems == []
