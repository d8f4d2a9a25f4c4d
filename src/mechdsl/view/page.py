"""The self-contained HTML page of the 3-D view: the scene's data as JSON, three.js (vendored,
inlined as text) and viewer.js, with the controls (play/pause, scrubber, speed, reset view).
No network at view time; the page works from a file:// URL and, wrapped in an iframe's srcdoc,
inline in Jupyter."""
from __future__ import annotations

import html
import json
from functools import lru_cache
from importlib import resources

OWN_MARK = '"generator": "mechdsl"'         # fileio.is_own_output: a rerun may replace the page
SPEEDS = (0.1, 0.25, 0.5, 1.0, 2.0, 4.0)   # multiples of the scene's speed offered by the menu
THREE_VERSION = "0.185.1"                # the npm release vendored (vendor/three/README.md)
_VENDOR = ("three.core.min.js", "three.module.min.js", "OrbitControls.js")

_STYLE = """
html, body { margin: 0; height: 100%; font-family: sans-serif; font-size: 13px; color: #222; }
#mv-root { position: relative; display: flex; flex-direction: column; height: 100%; min-height: 240px; }
#mv-canvas { flex: 1 1 auto; width: 100%; min-height: 0; display: block; touch-action: none; }
#mv-title { position: absolute; top: 6px; left: 10px; color: #555; pointer-events: none; }
#mv-clock { font-family: monospace; min-width: 12ch; }
#mv-note { position: absolute; top: 6px; right: 10px; color: #777; font-size: 11px; pointer-events: none; text-align: right; }
#mv-status { display: none; position: absolute; top: 40%; left: 10%; right: 10%; text-align: center; color: #a00; }
#mv-bar { display: flex; gap: 8px; align-items: center; padding: 4px 8px; border-top: 1px solid #ddd; }
#mv-range { flex: 1 1 auto; }
"""


@lru_cache(maxsize=1)
def _assets() -> dict[str, str]:
    base = resources.files("mechdsl.view")
    out = {name: (base / "vendor" / "three" / name).read_text(encoding="utf-8") for name in _VENDOR}
    out["viewer.js"] = (base / "viewer.js").read_text(encoding="utf-8")
    for name, text in out.items():
        if "</script" in text.lower() or "<!--" in text:
            raise RuntimeError(f"{name} cannot be inlined in a script element (it holds '</script' or '<!--')")
    return out


def _json(data) -> str:
    """JSON safe inside a script element ('</' cannot end it)."""
    return json.dumps(data, separators=(",", ":"), allow_nan=False).replace("</", "<\\/")


def page(data: dict, title: str = "mechdsl view") -> str:
    """The whole page for scene data from :mod:`.scene`."""
    a = _assets()
    t = html.escape(title)
    speeds = "".join(f'<option value="{s:g}"{" selected" if s == 1.0 else ""}>{s:g}x</option>' for s in SPEEDS)
    base = data.get("speed", 1.0)
    up = f"{data['up_label']} up" if data.get("mode") == "3d" else ""
    help_text = ("drag: turn; right-drag or shift-drag: pan; wheel: zoom; axes x red, y green, z blue"
                 if data.get("mode") == "3d" else "")
    return f"""<!DOCTYPE html>
<html lang="en">
<head>
<meta charset="utf-8">
<meta name="viewport" content="width=device-width, initial-scale=1">
<title>{t}</title>
<meta name="generator" content="mechdsl">
<!-- {OWN_MARK}; three.js {THREE_VERSION} (MIT, see mechdsl/view/vendor/three/LICENSE) -->
<style>{_STYLE}</style>
</head>
<body>
<div id="mv-root">
<canvas id="mv-canvas" aria-label="the mechanism in 3-D"></canvas>
<div id="mv-title">{t}</div>
<div id="mv-note">{html.escape(up)}<br>{html.escape(help_text)}</div>
<div id="mv-status" role="alert"></div>
<div id="mv-bar">
<button type="button" id="mv-play" aria-label="play or pause">pause</button>
<input type="range" id="mv-range" min="0" max="0" value="0" step="1" aria-label="time">
<span id="mv-clock"></span>
<label>speed <select id="mv-speed" aria-label="playback speed">{speeds}</select></label>
<span title="model seconds per second of playback at 1x">({"real time" if base == 1 else f"1x = {base:g} s per s"})</span>
<button type="button" id="mv-reset">reset view</button>
</div>
</div>
<script type="application/json" id="mv-data">{_json(data)}</script>
<script type="text/plain" id="mv-three-core">{a["three.core.min.js"]}</script>
<script type="text/plain" id="mv-three-module">{a["three.module.min.js"]}</script>
<script type="text/plain" id="mv-orbit">{a["OrbitControls.js"]}</script>
<script>
{a["viewer.js"]}
</script>
</body>
</html>
"""


def iframe(page_html: str, height: int = 480) -> str:
    """The page inside an iframe (srcdoc): how notebooks show it, isolated from the notebook's page."""
    return (f'<iframe srcdoc="{html.escape(page_html, quote=True)}" style="width:100%;height:{int(height)}px;'
            f'border:1px solid #ddd" title="mechdsl 3-D view"></iframe>')
