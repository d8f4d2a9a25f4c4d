"""Drawing and animating a mechanism (docs/animate.md).

    anim = animate(result, model, fps=30, speed=1.0, view="auto", trails=("rod2.b",))
    anim.save("dp.gif")          # .gif, .html (play/pause + scrubber), .mp4 (with ffmpeg)
    anim                         # displays inline in Jupyter (the HTML player)
    fig = draw(model, q=None, t=0.0)    # one still as a matplotlib Figure

Positions of everything drawn come from ONE CasADi Function of (t, q, p) evaluated mapped over
all frames (:mod:`.geometry`); :mod:`.stage` draws them with matplotlib (no pyplot), blitting
the moving artists; :mod:`.writer` writes the files.  Models without bodies are shown as bars
of their coordinates (:mod:`.bars`).
"""
from __future__ import annotations

import numpy as np

from ..diagnostics import UsageError
from .stage import VIEWS, check_view
from .writer import FORMATS, check_output

__all__ = ["animate", "draw", "Animation", "VIEWS", "FORMATS", "frame_times", "check_output"]

MAX_FRAMES = 20000


class Animation:
    """Frames of a mechanism ready to write or display.  ``figure`` is the matplotlib Figure,
    ``times`` the frame times, ``view`` the view used ('xy', 'xz', 'yz', '3d' or 'bars')."""

    def __init__(self, stage, fps: float):
        self.stage = stage
        self.fps = float(fps)

    @property
    def figure(self):
        """The matplotlib Figure the frames are drawn on."""
        return self.stage.figure

    @property
    def times(self) -> np.ndarray:
        """The model time [s] of each frame."""
        return self.stage.t

    @property
    def view(self) -> str:
        """The view drawn: 'xy', 'xz', 'yz', '3d' or 'bars'."""
        return self.stage.view

    def __len__(self) -> int:
        return self.stage.n_frames

    def frame(self, k: int) -> np.ndarray:
        """RGBA pixels of frame k."""
        return self.stage.frame(k)

    def save(self, path, overwrite: bool = False):
        """Write .gif, .html or .mp4 (atomically); returns the path."""
        from .writer import save

        return save(self.stage, path, self.fps, overwrite=overwrite)

    def to_html(self) -> str:
        """A self-contained HTML fragment that plays the frames (play/pause and a scrubber)."""
        from .writer import html_fragment

        return html_fragment(self.stage, self.fps)

    def _repr_html_(self) -> str:
        return self.to_html()

    def __repr__(self) -> str:
        return f"<mechdsl Animation: {len(self)} frames at {self.fps:g} fps, view {self.view}>"


def frame_times(t0: float, t1: float, fps: float, speed: float) -> np.ndarray:
    """Frame times: ``fps`` frames per second of playback, ``speed`` seconds of model time each."""
    if not (fps > 0 and np.isfinite(fps)):
        raise UsageError(f"--fps must be a positive number (got {fps:g})")
    if not (speed > 0 and np.isfinite(speed)):
        raise UsageError(f"--speed must be a positive number (got {speed:g})")
    n = int(np.floor((t1 - t0) * fps / speed + 1e-9)) + 1
    if n > MAX_FRAMES:
        raise UsageError(f"{n} frames is too many (at most {MAX_FRAMES}); lower --fps, raise --speed "
                         "or shorten the run")
    return t0 + np.arange(max(n, 1)) * speed / fps


def animate(result, model, *, fps: float = 30.0, speed: float = 1.0, view: str = "auto", trails=(),
            size=(480, 400)) -> Animation:
    """An Animation of a simulation result of ``model`` (a mechdsl Model or its EOM)."""
    check_view(view)
    eom = getattr(model, "eom", model)
    t = np.asarray(result.t, float)
    if len(t) == 0:
        raise UsageError("the result has no time points to animate")
    times = frame_times(float(t[0]), float(t[-1]), fps, speed)
    Q = _resample(t, np.asarray(result.q, float), times)
    title = eom.name + (f" (stopped at t = {result.failure.time:.4g} s)" if result.failure is not None else "")
    return Animation(_stage(eom, times, Q, view, list(result.events), title, trails, size), fps)


def draw(model, q=None, t: float = 0.0, *, view: str = "auto", trails=(), size=(480, 400)):
    """A still of the mechanism at coordinates q (default: the start values) and time t, as a
    matplotlib Figure."""
    check_view(view)
    eom = getattr(model, "eom", model)
    if q is None:
        q = eom.start()[0]
    q = np.asarray(q, float).reshape(1, -1)
    if q.shape[1] != eom.n:
        raise UsageError(f"q has {q.shape[1]} entries; {eom.name} has {eom.n} coordinates")
    stage = _stage(eom, np.array([float(t)]), q, view, [], eom.name, trails, size)
    return stage.still(0)


def _stage(eom, times, Q, view, events, title, trails, size):
    from .geometry import build

    geo = build(eom, traces=tuple(trails))
    if geo.empty:
        if trails:
            raise UsageError(f"--trail: {eom.name} has no points to trace (no bodies)")
        from .bars import BarStage

        units = [getattr(c, "unit", None) or "" for c in (eom.model.coordinates if eom.model else ())]
        return BarStage(eom.coords, units or [""] * eom.n, times, Q, title=title, size=size)
    from .stage import Stage

    return Stage(geo, times, geo.positions(times, Q), view=view, events=events, title=title, size=size)


def _resample(t: np.ndarray, q: np.ndarray, times: np.ndarray) -> np.ndarray:
    """Coordinates at the frame times, linear between output points (exact on a matching grid)."""
    if len(t) == 1:
        return np.repeat(q[:1], len(times), axis=0)
    out = np.empty((len(times), q.shape[1]))
    for i in range(q.shape[1]):
        out[:, i] = np.interp(times, t, q[:, i])
    return out
