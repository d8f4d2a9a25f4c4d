"""Plots of simulation results that read: units on every axis, one axis per unit, legends
outside the data, colours that never repeat (matplotlib Figures, imported lazily; no pyplot,
no global matplotlib state)."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from .fileio import atomic_target, check_figure, commit
from .units import signal_units

MAX_LEGEND = 12
_BASE = ("#1f77b4", "#ff7f0e", "#2ca02c", "#d62728", "#9467bd", "#8c564b", "#e377c2", "#7f7f7f",
         "#bcbd22", "#17becf")          # matplotlib's tab10


_DISPLAY_FIGURE = None


def new_figure(**kw):
    """A matplotlib Figure (no pyplot) that also shows itself in a notebook: ``_repr_png_``
    renders it, since without pyplot no inline backend registers a display for it."""
    global _DISPLAY_FIGURE
    if _DISPLAY_FIGURE is None:
        from matplotlib.figure import Figure

        class DisplayFigure(Figure):
            def _repr_png_(self) -> bytes:
                import io

                buf = io.BytesIO()
                self.savefig(buf, format="png", dpi=80, metadata=FIGURE_METADATA[".png"])
                return buf.getvalue()

        DisplayFigure.__qualname__ = "DisplayFigure"
        _DISPLAY_FIGURE = DisplayFigure
    return _DISPLAY_FIGURE(**kw)


def colours(n: int) -> list[str]:
    """n distinct colours: tab10 first, then hues spaced by the golden angle at alternating
    lightness, so no two curves of one plot share a colour however many there are."""
    import colorsys

    out = list(_BASE[:n])
    k = 0
    while len(out) < n:
        h = (0.05 + k * 0.6180339887498949) % 1.0
        light, sat = (0.35, 0.85) if k % 2 == 0 else (0.6, 0.65)
        r, g, b = colorsys.hls_to_rgb(h, light, sat)
        out.append(f"#{round(255 * r):02x}{round(255 * g):02x}{round(255 * b):02x}")
        k += 1
    return out


QUANTITY = {"rad": "angle", "deg": "angle", "m": "length", "m/s": "speed", "rad/s": "angular speed",
            "J": "energy", "N": "force", "N.m": "torque", "N*m": "torque", "kg": "mass", "s": "time"}


def _axis_label(unit: str, names) -> str:
    q = QUANTITY.get(unit)
    if not unit:
        return "value (no unit given)" if len(names) > 1 else f"{names[0]} (no unit given)"
    return f"{q or (names[0] if len(names) == 1 else 'value')} [{unit}]"


def result_figure(result, *signals, energy: bool = True, drift: bool = False, model=None,
                  title: str | None = None, width: float = 9.0):
    """A matplotlib Figure of a result (no pyplot, no global state): the coordinates, or the
    named ``signals``, on one axis per unit (angles apart from lengths), each axis labelled
    with its quantity and unit; kinetic, potential and total energy [J] below when recorded
    (``energy=False`` leaves them out); with ``drift=True`` the energy drift E(t) - E(0) as its
    own panel.  Legends sit outside the data, right of each axis; colours never repeat within
    a figure.  A failed run is drawn up to its last point with the failure marked."""
    from ..diagnostics import UsageError

    units = signal_units(result, model)
    names = list(signals) if signals else list(result.coordinates)
    for n in names:
        if n not in result:
            raise UsageError(f"no signal named {n!r}; recorded: {', '.join(result.columns)}")
    groups: dict[str, list[str]] = {}
    for n in names:
        groups.setdefault(units.get(n, ""), []).append(n)
    has_energy = energy and "energy" in result.signals and not signals
    panels = [("curves", u, ns) for u, ns in groups.items()]
    if has_energy:
        panels.append(("energy", "J", ["kinetic_energy", "potential_energy", "energy"]))
    if drift:
        if "energy" not in result.signals:
            raise UsageError("drift=True needs the energy, which this result did not record")
        panels.append(("drift", "J", ["energy"]))
    if not panels:
        panels = [("curves", "", [])]
    palette = dict(zip(names, colours(len(names))))
    heights = [1.0 if kind == "curves" else 0.8 for kind, _, _ in panels]
    fig = new_figure(figsize=(width, 1.2 + 2.4 * sum(heights)), layout="constrained")   # no pyplot
    axes = fig.subplots(len(panels), 1, sharex=True, squeeze=False, gridspec_kw={"height_ratios": heights})[:, 0]
    t = result.t
    for ax, (kind, unit, ns) in zip(axes, panels):
        if kind == "curves":
            for n in ns:
                ax.plot(t, result[n], label=n, color=palette[n], lw=1.2)
            ax.set_ylabel(_axis_label(unit, ns) if ns else "")
        elif kind == "energy":
            for n, label, c in zip(ns, ("T (kinetic)", "V (potential)", "E = T + V"), ("#1f77b4", "#ff7f0e", "#222222")):
                ax.plot(t, result.signals[n], label=label, color=c, lw=1.6 if n == "energy" else 1.2)
            ax.set_ylabel("energy [J]")
        else:
            E = np.asarray(result.signals["energy"], float)
            ax.plot(t, E - E[0], color="#d62728", lw=1.2, label="E(t) - E(0)")
            ax.set_ylabel("energy drift [J]")
        if ax.get_legend_handles_labels()[0]:
            _legend_outside(ax)
        ax.grid(True, alpha=0.3)
    model_name = result.metadata.get("model", "")
    method = result.metadata.get("method", "")
    axes[0].set_title(title or f"{model_name}" + (f" ({method})" if method else ""))
    axes[-1].set_xlabel("time [s]")
    if result.failure is not None:
        for a in axes:
            a.axvline(result.failure.time, color="r", ls="--", lw=1)
        axes[0].annotate(f"failed: {result.failure.cause}", xy=(result.failure.time, 1), xycoords=("data", "axes fraction"),
                         xytext=(-4, -12), textcoords="offset points", ha="right", color="r", fontsize="small")
    return fig


def _legend_outside(ax) -> None:
    handles, labels = ax.get_legend_handles_labels()
    extra = len(labels) - MAX_LEGEND
    if extra > 0:
        handles, labels = handles[:MAX_LEGEND], labels[:MAX_LEGEND]
    ax.legend(handles, labels, loc="upper left", bbox_to_anchor=(1.01, 1.0), borderaxespad=0.0, fontsize="small",
              title=f"{extra} more not labelled" if extra > 0 else None, title_fontsize="small", frameon=False)


def plot_result(result, path, *, overwrite: bool = False, title: str | None = None, model=None,
                drift: bool = False) -> Path:
    """Write :func:`result_figure` to a file; the format follows the suffix (.png, .svg, .pdf)
    and the file is written atomically."""
    check_figure(path, overwrite)
    return save_figure(result_figure(result, model=model, title=title, drift=drift), path, overwrite=overwrite)


FIGURE_METADATA = {".png": {"Software": "mechdsl"}, ".svg": {"Date": None, "Creator": "mechdsl"},
                   ".pdf": {"CreationDate": None, "Creator": "mechdsl"}}


def save_figure(fig, path, *, overwrite: bool = False, dpi: int = 110) -> Path:
    """Write a matplotlib figure atomically, deterministically (no dates, fixed SVG ids) and
    marked as mechdsl's (so a rerun may replace it), then close it if pyplot manages it.
    Format by suffix: png, svg, pdf.  No global matplotlib state is changed."""
    import matplotlib

    final = check_figure(path, overwrite)
    suffix = final.suffix.lower()
    tmp, final = atomic_target(final, overwrite=overwrite)
    try:
        with matplotlib.rc_context({"svg.hashsalt": "mechdsl"}):
            fig.savefig(tmp, dpi=dpi, format=suffix[1:], metadata=FIGURE_METADATA[suffix])
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    finally:
        if getattr(fig.canvas, "manager", None) is not None:      # a pyplot figure
            import matplotlib.pyplot as plt

            plt.close(fig)
    return commit(tmp, final)
