"""Animation files: GIF (Pillow, which matplotlib already needs), a self-contained HTML page
with play/pause and a scrubber (PNG frames inlined, a few lines of JavaScript, no network),
and MP4 when an ``ffmpeg`` program is on the PATH.  Written atomically (``fileio``)."""
from __future__ import annotations

import base64
import hashlib
import io
import json
import shutil
import subprocess
from pathlib import Path

import numpy as np

from ..diagnostics import UsageError
from ..output.fileio import atomic_target, check_writable, commit

OWN_MARK = '"generator": "mechdsl"'      # what fileio.is_own_output looks for: a rerun may replace the file
FORMATS = {".gif": "animated GIF", ".html": "a web page with play/pause and a scrubber",
           ".mp4": "H.264 video (needs ffmpeg on the PATH)"}


GIF_MAX_FPS = 50                         # GIF delays are whole centiseconds; browsers stretch delays under 2 cs


def check_output(path, overwrite: bool = False, fps: float | None = None) -> Path:
    """The output's format is one we can write here (at this frame rate), and its place is
    writable (before any work)."""
    suffix = Path(path).suffix.lower()
    if suffix not in FORMATS:
        raise UsageError(f"cannot write '{suffix or Path(path).name}' animations; supported: "
                         + ", ".join(f"{k} ({v})" for k, v in FORMATS.items()))
    if suffix == ".gif" and fps is not None and fps > GIF_MAX_FPS:
        raise UsageError(f"a GIF cannot play {fps:g} frames per second: its frame delays are whole hundredths "
                         f"of a second and browsers stretch delays under 0.02 s; use --fps {GIF_MAX_FPS} or less, "
                         "or write .html or .mp4")
    if suffix == ".mp4" and shutil.which("ffmpeg") is None:
        raise UsageError("cannot write .mp4 here: no 'ffmpeg' program on the PATH; write .gif or .html instead")
    return check_writable(path, overwrite)


class AnimationInterrupted(KeyboardInterrupt):
    """Ctrl-C while the frames were drawn: the frames drawn so far were written (``path``,
    ``frames`` of ``total``), and the interrupt goes on."""

    def __init__(self, path: Path, frames: int, total: int):
        super().__init__("interrupted")
        self.path, self.frames, self.total = path, frames, total


class _Partial(Exception):
    def __init__(self, frames: int):
        self.frames = frames


def save(stage, path, fps: float, overwrite: bool = False) -> Path:
    """Write the animation atomically.  Ctrl-C while drawing: the frames drawn so far are
    written as a shorter animation and AnimationInterrupted (a KeyboardInterrupt) is raised."""
    final = check_output(path, overwrite, fps)
    suffix = final.suffix.lower()
    tmp, final = atomic_target(final, overwrite=overwrite)
    try:
        if suffix == ".gif":
            _gif(stage, tmp, fps)
        elif suffix == ".html":
            frames = frames_png(stage, partial=True)
            tmp.write_text(html_page(stage, fps, title=Path(final).stem, frames=frames), encoding="utf-8")
            if len(frames) < stage.n_frames:
                raise _Partial(len(frames))
        else:
            _mp4(stage, tmp, fps)
    except _Partial as p:
        raise AnimationInterrupted(commit(tmp, final), p.frames, stage.n_frames) from None
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    return commit(tmp, final)


def _drawn(images, first: int = 1) -> list:
    """The frames of ``images`` up to a Ctrl-C (at least ``first``, else the interrupt goes on)."""
    out = []
    try:
        for im in images:
            out.append(im)
    except KeyboardInterrupt:
        if len(out) < first:
            raise
    return out


def _images(stage):
    """Frames as palette images sharing one palette: fast, and no colour flickers between frames.
    The palette comes from a few sample frames and a swatch of every colour the stage uses (so
    a colour seen in few frames, like an impact's flash, keeps its hue)."""
    from matplotlib.colors import to_rgb
    from PIL import Image

    def rgb(k):
        return np.asarray(stage.frame(k))[:, :, :3].copy()

    samples = [rgb(int(k)) for k in np.unique(np.linspace(0, stage.n_frames - 1, 5).round())]
    w = samples[0].shape[1]
    swatch = np.zeros((8, w, 3), np.uint8)
    for i, c in enumerate(getattr(stage, "swatch", ())):
        x = (i * 8) % w
        swatch[:, x: x + 8] = np.round(np.array(to_rgb(c)) * 255)
    palette = Image.fromarray(np.vstack(samples + [swatch])).quantize(colors=192, method=Image.Quantize.MEDIANCUT)
    # Pillow's palette lookup is approximate: white may land on a near-white entry; that entry is
    # made pure white in the frames' palette, so the background stays white
    white = Image.new("RGB", (1, 1), "white").quantize(palette=palette, dither=Image.Dither.NONE).getpixel((0, 0))
    entries = list(palette.getpalette())
    entries[3 * white: 3 * white + 3] = [255, 255, 255]
    for k in range(stage.n_frames):
        im = Image.fromarray(rgb(k)).quantize(palette=palette, dither=Image.Dither.NONE)
        im.putpalette(entries)
        yield im


def gif_durations(n: int, fps: float) -> list[int]:
    """Frame delays in ms, each a whole number of centiseconds (all a GIF can store), chosen so
    that frame k starts at the centisecond nearest k / fps: 30 fps alternates 30 and 40 ms
    (33.3 ms on average) instead of playing every frame for 30 ms, 11% fast."""
    edges = np.round(np.arange(n + 1) * 100.0 / fps).astype(int)
    return [int(10 * d) for d in np.diff(edges)]


def _gif(stage, path: Path, fps: float) -> None:
    frames = _drawn(_images(stage))
    durations = gif_durations(len(frames), fps)
    with open(path, "wb") as f:
        frames[0].save(f, format="GIF", save_all=True, append_images=frames[1:],
                       duration=durations if len(frames) > 1 else durations[0], loop=0,
                       optimize=False, disposal=1, comment=OWN_MARK.encode())
    if len(frames) < stage.n_frames:
        raise _Partial(len(frames))


def _mp4(stage, path: Path, fps: float) -> None:
    h, w = np.asarray(stage.frame(0)).shape[:2]
    cmd = [shutil.which("ffmpeg"), "-loglevel", "error", "-y", "-f", "rawvideo", "-pix_fmt", "rgba",
           "-s", f"{w}x{h}", "-r", f"{fps:g}", "-i", "-", "-vf", "pad=ceil(iw/2)*2:ceil(ih/2)*2",
           "-pix_fmt", "yuv420p", "-metadata", f"comment={OWN_MARK}", "-movflags", "+faststart",
           "-f", "mp4", str(path)]
    proc = subprocess.Popen(cmd, stdin=subprocess.PIPE, stderr=subprocess.PIPE)
    k = 0
    try:
        try:
            for k in range(stage.n_frames):
                proc.stdin.write(np.ascontiguousarray(stage.frame(k)).tobytes())
        except (KeyboardInterrupt, BrokenPipeError):
            # Ctrl-C (ffmpeg, in the same process group, got it too and ends the file itself)
            try:
                proc.stdin.close()
            except OSError:
                pass
            proc.wait(30)
            if k < 1 or not path.exists() or path.stat().st_size == 0:
                raise KeyboardInterrupt from None
            raise _Partial(k) from None
        proc.stdin.close()
        err = proc.stderr.read().decode(errors="replace")
        if proc.wait() != 0:
            raise UsageError(f"ffmpeg could not write the video: {err.strip()[:300]}")
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()


def frames_png(stage, partial: bool = False) -> list[str]:
    """The frames as base64 PNG; ``partial``: up to a Ctrl-C (fewer than stage.n_frames)."""
    def pngs():
        for im in _images(stage):
            buf = io.BytesIO()
            im.save(buf, format="PNG", optimize=False)
            yield base64.b64encode(buf.getvalue()).decode("ascii")

    return _drawn(pngs()) if partial else list(pngs())


def html_fragment(stage, fps: float, frames: list[str] | None = None) -> str:
    """The player as an HTML fragment (a div and a script): for notebooks and the page."""
    frames = frames_png(stage) if frames is None else frames
    times = [round(float(t), 6) for t in stage.t][:len(frames)]
    uid = "mechdsl-" + hashlib.sha256("".join(frames[:1] + frames[-1:]).encode()).hexdigest()[:10]
    h, w = np.asarray(stage.frame(0)).shape[:2]
    data = json.dumps({"frames": frames, "times": times, "interval": 1000.0 / fps})
    return f"""<div class="mechdsl-animation" id="{uid}" style="font-family:sans-serif;font-size:13px">
<img id="{uid}-img" width="{w}" height="{h}" alt="mechanism animation frame" style="display:block">
<div style="margin-top:4px;display:flex;gap:8px;align-items:center">
<button type="button" id="{uid}-play" aria-label="play or pause">pause</button>
<input type="range" id="{uid}-range" min="0" max="{len(frames) - 1}" value="0" step="1" style="width:{max(w - 160, 80)}px"
 aria-label="time">
<span id="{uid}-time" style="font-family:monospace"></span>
</div></div>
<script>
(function() {{
  var d = {data};
  var img = document.getElementById("{uid}-img"), range = document.getElementById("{uid}-range"),
      btn = document.getElementById("{uid}-play"), label = document.getElementById("{uid}-time");
  var k = 0, timer = null, t0 = 0;
  function show(i) {{
    k = i; img.src = "data:image/png;base64," + d.frames[k]; range.value = k;
    label.textContent = "t = " + d.times[k].toFixed(3) + " s";
  }}
  function step() {{                 // the frame due by the clock: no drift from late timer calls
    var i = Math.floor((performance.now() - t0) / d.interval) % d.frames.length;
    if (i !== k) show(i);
  }}
  function play() {{
    if (timer === null) {{
      t0 = performance.now() - k * d.interval;
      timer = setInterval(step, Math.min(d.interval / 2, 15)); btn.textContent = "pause";
    }}
  }}
  function pause() {{ if (timer !== null) {{ clearInterval(timer); timer = null; }} btn.textContent = "play"; }}
  btn.addEventListener("click", function() {{ if (timer === null) play(); else pause(); }});
  range.addEventListener("input", function() {{ pause(); show(parseInt(range.value, 10)); }});
  show(0); play();
}})();
</script>"""


def html_page(stage, fps: float, title: str = "mechdsl animation", frames: list[str] | None = None) -> str:
    import html

    return (f'<!DOCTYPE html>\n<html lang="en">\n<head>\n<meta charset="utf-8">\n<title>{html.escape(title)}</title>\n'
            f'<meta name="generator" content="mechdsl">\n<!-- {OWN_MARK} -->\n</head>\n<body>\n{html_fragment(stage, fps, frames)}\n</body>\n</html>\n')
