"""Plots of simulation results (matplotlib, Agg backend, imported lazily)."""
from __future__ import annotations

from pathlib import Path

from .fileio import atomic_target, check_figure, commit

MAX_LEGEND = 12


def plot_result(result, path, *, overwrite: bool = False, title: str | None = None) -> Path:
    """Coordinates against time (top) and kinetic, potential and total energy (bottom).

    The format follows the suffix (.png, .svg, .pdf); the file is written atomically.  A
    failed run is plotted up to its last point with the failure marked.
    """
    check_figure(path, overwrite)
    from matplotlib.figure import Figure      # no pyplot: no global backend or figure registry touched

    has_energy = "energy" in result.signals
    fig = Figure(figsize=(8, 6.5 if has_energy else 4))
    axes = fig.subplots(2 if has_energy else 1, 1, sharex=True, squeeze=False)
    ax = axes[0, 0]
    for i, name in enumerate(result.coordinates):
        ax.plot(result.t, result.q[:, i], label=name if i < MAX_LEGEND else None, lw=1.2)
    ax.set_ylabel("coordinates")
    if result.coordinates:
        ax.legend(loc="best", fontsize="small", ncol=2 if len(result.coordinates) > 6 else 1,
                  title=(f"{len(result.coordinates) - MAX_LEGEND} more not labelled"
                         if len(result.coordinates) > MAX_LEGEND else None))
    ax.grid(True, alpha=0.3)
    model = result.metadata.get("model", "")
    method = result.metadata.get("method", "")
    ax.set_title(title or f"{model}" + (f" ({method})" if method else ""))
    if has_energy:
        ax2 = axes[1, 0]
        ax2.plot(result.t, result.signals["kinetic_energy"], label="T (kinetic)", lw=1.2)
        ax2.plot(result.t, result.signals["potential_energy"], label="V (potential)", lw=1.2)
        ax2.plot(result.t, result.signals["energy"], label="E = T + V", lw=1.6, color="k")
        ax2.set_ylabel("energy")
        ax2.legend(loc="best", fontsize="small")
        ax2.grid(True, alpha=0.3)
    axes[-1, 0].set_xlabel("time")
    if result.failure is not None:
        for a in axes[:, 0]:
            a.axvline(result.failure.time, color="r", ls="--", lw=1)
        axes[0, 0].annotate(f"failed: {result.failure.cause}", xy=(result.failure.time, 1), xycoords=("data", "axes fraction"),
                            xytext=(-4, -12), textcoords="offset points", ha="right", color="r", fontsize="small")
    fig.tight_layout()
    return save_figure(fig, path, overwrite=overwrite)


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
