"""The interactive 3-D view (docs/animate.md): a self-contained HTML page with a three.js scene
you turn, zoom and pan, playing the motion with play/pause, a time scrubber and a speed menu.

    v = view(result, model, fps=30, speed=None, up=None, trails=("rod2.b",))   # a View
    v.save("dp.html")            # one file, no network needed to open it
    v                            # in Jupyter: the page inline (an iframe)
    still(model, q=None)         # the mechanism at q (default: its start), to turn around

Frames are sampled at ``fps`` per second of playback (``speed`` model seconds each); the page
interpolates between them.  Bodies are drawn as in :mod:`mechdsl.animate` (their shapes, else
the equivalent ellipsoid of their inertia), up against gravity unless ``up`` says otherwise.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from ..diagnostics import UsageError

__all__ = ["View", "view", "still", "check_output", "SUFFIXES"]

SUFFIXES = (".html", ".htm")


class View:
    """An interactive 3-D view ready to save or display; ``data`` is the page's scene data."""

    def __init__(self, data: dict, title: str):
        self.data = data
        self.title = title

    @property
    def mode(self) -> str:
        """'3d', or 'bars' for a model without bodies."""
        return self.data["mode"]

    def __len__(self) -> int:
        return int(self.data["n_frames"])

    @property
    def times(self) -> np.ndarray:
        """The model times of the page's frames [s]."""
        import base64

        return np.frombuffer(base64.b64decode(self.data["times"]), "<f8")

    def to_html(self) -> str:
        """The whole page."""
        from .page import page

        return page(self.data, self.title)

    def save(self, path, overwrite: bool = False) -> Path:
        """Write the page (atomically); returns the path."""
        from ..output.fileio import write_atomic

        check_output(path, overwrite)
        return write_atomic(path, self.to_html(), overwrite=overwrite)

    def _repr_html_(self) -> str:
        from .page import iframe

        return iframe(self.to_html())

    def __repr__(self) -> str:
        what = "bars of the coordinates" if self.mode == "bars" else f"{len(self.data['bodies'])} posed bodies"
        return f"<mechdsl View of {self.title}: {len(self)} frames, {what}>"


def check_output(path, overwrite: bool = False) -> Path:
    """The page's name ends in .html and its place is writable (before any work)."""
    from ..output.fileio import check_writable

    if Path(path).suffix.lower() not in SUFFIXES:
        raise UsageError(f"mech view writes an HTML page: the output must end in .html (got {str(path)!r})")
    return check_writable(path, overwrite)


def view(result, model, *, fps: float = 30.0, speed: float | None = None, up=None, trails=()) -> View:
    """The View of a simulation result of ``model`` (a mechdsl Model or its EOM)."""
    from ..animate import frames_of

    f = frames_of(result, model, fps, speed, "view")
    return _make(f.eom, f.times, f.Q, up, trails, f.title, f.speed, f.events)


def still(model, q=None, t: float = 0.0, *, up=None, trails=()) -> View:
    """The View of the mechanism at coordinates q (default: the start values) and time t."""
    from ..animate import start_coordinates

    eom = getattr(model, "eom", model)
    return _make(eom, np.array([float(t)]), start_coordinates(eom, q), up, trails, eom.name, 1.0, [])


def _make(eom, times, Q, up, trails, title, speed, events) -> View:
    from ..animate import coordinate_units, up_vector
    from ..animate.geometry import build
    from .scene import bars_scene, build_scene

    up = up_vector(up)
    geo = build(eom, traces=tuple(trails))
    if geo.empty:
        if trails:
            raise UsageError(f"--trail: {eom.name} has no points to trace (no bodies)")
        data = bars_scene(list(eom.coords), coordinate_units(eom), times, Q, title=title, speed=speed)
    else:
        data = build_scene(geo, times, Q, up=up, title=title, speed=speed, events=events)
    return View(data, title)
