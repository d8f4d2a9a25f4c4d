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

__all__ = ["animate", "draw", "Animation", "VIEWS", "FORMATS", "frame_times", "pick_speed", "check_output"]

MAX_FRAMES = 20000
LONGEST_PLAY = 60.0        # s of playback, without --speed (pick_speed)


class Animation:
    """Frames of a mechanism ready to write or display.  ``figure`` is the matplotlib Figure,
    ``times`` the frame times, ``view`` the view used ('xy', 'xz', 'yz', '3d' or 'bars')."""

    def __init__(self, stage, fps: float, speed: float = 1.0):
        self.stage = stage
        self.fps = float(fps)
        self.speed = float(speed)

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


def pick_speed(duration: float) -> float:
    """The playback speed when none is given: real time (1), unless the run would play for
    under a second or for more than LONGEST_PLAY seconds; then the speed (1, 2 or 5 times a power
    of ten) that makes it play for at least 2 s (Andrews' squeezer, 0.03 s, plays at 0.01: 3 s)
    or at most a minute (a hundred Kepler orbits, 628 s, play at 20: 31 s, 943 frames at 30 fps
    rather than 18850)."""
    if not np.isfinite(duration) or duration <= 0:
        return 1.0
    if duration > LONGEST_PLAY:
        target = duration / LONGEST_PLAY
        e = 10.0 ** np.floor(np.log10(target))
        return float(min(m * e for m in (1, 2, 5, 10) if m * e >= target * (1 - 1e-12)))
    if duration >= 1.0:
        return 1.0
    target = duration / 2.0
    e = 10.0 ** np.floor(np.log10(target))
    return float(max(m * e for m in (1, 2, 5) if m * e <= target * (1 + 1e-12)))


def frame_times(t0: float, t1: float, fps: float, speed: float | None = None) -> np.ndarray:
    """Frame times: ``fps`` frames per second of playback, ``speed`` seconds of model time each
    (None: :func:`pick_speed`).  A speed so fast that a run of positive length would get a
    single frame is a usage error that says the fastest speed with frames."""
    if not (fps > 0 and np.isfinite(fps)):
        raise UsageError(f"--fps must be a positive number (got {fps:g})")
    if speed is None:
        speed = pick_speed(t1 - t0)
    if not (speed > 0 and np.isfinite(speed)):
        raise UsageError(f"--speed must be a positive number (got {speed:g})")
    n = int(np.floor((t1 - t0) * fps / speed + 1e-9)) + 1
    if n < 2 and t1 > t0:
        raise UsageError(f"--speed {speed:g} at {fps:g} fps leaves one frame of the {t1 - t0:g} s run; "
                         f"use --speed {(t1 - t0) * fps:.3g} or less (or leave --speed out: a run shorter "
                         "than a second is then slowed down to play for at least 2 s)")
    if n > MAX_FRAMES:
        raise UsageError(f"{n} frames is too many (at most {MAX_FRAMES}); lower --fps, raise --speed "
                         "or shorten the run")
    return t0 + np.arange(max(n, 1)) * speed / fps


def animate(result, model, *, fps: float = 30.0, speed: float | None = None, view: str = "auto", up=None,
            trails=(), size=(480, 400)) -> Animation:
    """An Animation of a simulation result of ``model`` (a mechdsl Model or its EOM).

    ``speed``: model seconds per second of playback (None: real time, or slow motion for a run
    shorter than a second, :func:`pick_speed`); ``up``: the screen's up direction (a vector or
    'x', '-z', ...; None: against gravity)."""
    check_view(view)
    f = frames_of(result, model, fps, speed, "animate")
    return Animation(_stage(f.eom, f.times, f.Q, view, up, f.events, f.title, trails, size), fps, f.speed)


def frames_of(result, model, fps: float, speed: float | None, verb: str = "animate"):
    """The frames of a result: eom, times, Q (coordinates at the frame times), speed (picked
    when None), title (saying where a failed run stopped) and the result's events."""
    from types import SimpleNamespace

    eom = getattr(model, "eom", model)
    t = np.asarray(result.t, float)
    if len(t) == 0:
        raise UsageError(f"the result has no time points to {verb}")
    if speed is None:
        speed = pick_speed(float(t[-1] - t[0]))
    times = frame_times(float(t[0]), float(t[-1]), fps, speed)
    failure = getattr(result, "failure", None)
    title = eom.name + (f" (stopped at t = {failure.time:.4g} s)" if failure is not None else "")
    return SimpleNamespace(eom=eom, times=times, Q=_resample(t, np.asarray(result.q, float), times), speed=speed,
                           title=title, events=list(getattr(result, "events", ())))


def draw(model, q=None, t: float = 0.0, *, view: str = "auto", up=None, trails=(), size=(480, 400)):
    """A still of the mechanism at coordinates q (default: the start values) and time t, as a
    matplotlib Figure."""
    check_view(view)
    eom = getattr(model, "eom", model)
    q = start_coordinates(eom, q)
    stage = _stage(eom, np.array([float(t)]), q, view, up, [], eom.name, trails, size)
    return stage.still(0)


def start_coordinates(eom, q=None) -> np.ndarray:
    """q as a (1, n) array: the given coordinates, else the model's start values."""
    if q is None:
        q = eom.start()[0]
    q = np.asarray(q, float).reshape(1, -1)
    if q.shape[1] != eom.n:
        raise UsageError(f"q has {q.shape[1]} entries; {eom.name} has {eom.n} coordinates")
    return q


def up_vector(up) -> np.ndarray | None:
    """None, a direction name ('z', '-y', ...) or a vector -> None or a unit vector."""
    from .camera import parse_up

    if up is None:
        return None
    if isinstance(up, str):
        return parse_up(up)
    v = np.asarray(up, float).ravel()
    n = float(np.linalg.norm(v)) if v.shape == (3,) else 0.0
    if not (np.isfinite(n) and n > 0):
        raise UsageError(f"up must be a direction such as 'z' or a nonzero 3-vector (got {up!r})")
    return v / n


def _stage(eom, times, Q, view, up, events, title, trails, size):
    from .geometry import build

    up = up_vector(up)
    geo = build(eom, traces=tuple(trails))
    if geo.empty:
        if trails:
            raise UsageError(f"--trail: {eom.name} has no points to trace (no bodies)")
        from .bars import BarStage

        return BarStage(eom.coords, coordinate_units(eom), times, Q, title=title, size=size)
    from .stage import Stage

    return Stage(geo, times, geo.positions(times, Q), view=view, up=up, events=events, title=title, size=size)


def coordinate_units(eom) -> list[str]:
    """The unit of every coordinate ('' when undeclared): the labels of the bars."""
    units = [getattr(c, "unit", None) or "" for c in (eom.model.coordinates if eom.model else ())]
    return units or [""] * eom.n


def _resample(t: np.ndarray, q: np.ndarray, times: np.ndarray) -> np.ndarray:
    """Coordinates at the frame times, linear between output points (exact on a matching grid)."""
    if len(t) == 1:
        return np.repeat(q[:1], len(times), axis=0)
    out = np.empty((len(times), q.shape[1]))
    for i in range(q.shape[1]):
        out[:, i] = np.interp(times, t, q[:, i])
    return out
