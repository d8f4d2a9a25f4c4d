"""A model without geometry (equation layer only: no bodies to draw) is shown as its
coordinates moving as horizontal bars, one per coordinate, labelled with its unit; same frame
interface as :class:`mechdsl.animate.stage.Stage`."""
from __future__ import annotations

import numpy as np

from .stage import INK, Blitted


class BarStage(Blitted):
    view = "bars"

    def __init__(self, names, units, t, Q, *, title="", size=(480, 400), dpi=80):
        from matplotlib.backends.backend_agg import FigureCanvasAgg
        from ..output.plot import colours, new_figure

        self.t = np.asarray(t, float)
        self.Q = np.asarray(Q, float).reshape(len(self.t), -1)
        self.n_frames = len(self.t)
        n = self.Q.shape[1]
        self.figure = fig = new_figure(figsize=(size[0] / dpi, size[1] / dpi), dpi=dpi)
        FigureCanvasAgg(fig)
        ax = self.ax = fig.add_axes((0.3, 0.12, 0.62, 0.72))
        labels = [f"{c} [{u}]" if u else c for c, u in zip(names, units)]
        lo = min(0.0, float(self.Q.min())) if self.Q.size else -1.0
        hi = max(0.0, float(self.Q.max())) if self.Q.size else 1.0
        pad = 0.05 * ((hi - lo) or 1.0)
        ax.set_xlim(lo - pad, hi + pad)
        ax.set_ylim(-0.6, n - 0.4)
        ax.set_yticks(range(n), labels)
        ax.invert_yaxis()
        ax.axvline(0.0, color=INK, lw=0.8)
        ax.grid(True, axis="x", alpha=0.3)
        ax.set_xlabel("coordinate value (each in its unit)")
        self.swatch = colours(n) + [INK, "#ffffff"]
        self.bars = ax.barh(range(n), np.zeros(n), color=self.swatch[:n], animated=True)
        fig.text(0.5, 0.96, (title + ": " if title else "") + "no bodies to draw; coordinates shown as bars",
                 ha="center", va="top", fontsize=10, color="#555555")
        self.clock = fig.text(0.02, 0.90, "", fontsize=11, family="monospace", color=INK, animated=True)
        self.moving = list(self.bars) + [self.clock]
        self._background = None

    def _update(self, k):
        for b, v in zip(self.bars, self.Q[k]):
            b.set_width(v)
