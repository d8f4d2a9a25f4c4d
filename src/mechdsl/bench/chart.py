"""The work-precision chart: error against CPU time, log-log, one line per method.

Panels: final-time error, L2 error over the output grid, and the drift of the main
invariant (energy, or the constraint residual of a constrained model) when the runs record
one.  Points of a line are the tolerances of the sweep, loose to tight; the first and last
are labelled.  Failed runs are crosses on the upper edge at their CPU time; runs that do
not apply, raised an error or were skipped are listed under the chart.  The estimated
accuracy of a computed reference is a dashed line: errors below it are not resolved.
"""
from __future__ import annotations

import math
from pathlib import Path

from ..diagnostics import UsageError
from ..output.fileio import atomic_target, check_writable, commit, output_folder
from . import measure

FLOOR = 1e-17        # zero errors are drawn here (log axes)
MARKERS = "osD^v<>ph*Xd"


def _setup_mpl():
    import matplotlib

    matplotlib.use("Agg", force=True)
    import matplotlib.pyplot as plt

    matplotlib.rcParams["svg.hashsalt"] = "mechdsl"
    return plt


def draw(res, title: str | None = None):
    """A matplotlib Figure of the benchmark ``res`` (runner.BenchResult)."""
    plt = _setup_mpl()
    panels, inv_key = _panels(res)
    fig, axes = plt.subplots(1, len(panels), figsize=(5.2 * len(panels), 4.8), squeeze=False)
    axes = axes[0]
    cmap = plt.get_cmap("tab10" if len(res.variants()) <= 10 else "tab20")
    notes = []
    for vi, label in enumerate(res.variants()):
        notes += _variant(axes, panels, inv_key, res.rows_of(label), label, cmap(vi % cmap.N),
                          MARKERS[vi % len(MARKERS)])
    _style(axes, panels, res)
    s = res.setup
    fig.suptitle(title or f"{s.name or s.eom.name}" + (f" (scene {s.scene})" if s.scene else "")
                 + f": t = {s.t_start:g} .. {s.t_end:g} s, compared {_cols(res.columns)}; "
                   f"x at the top = failed run", fontsize="medium")
    bottom = 0.0
    if notes:
        text = "\n".join(notes[:8] + ([f"... and {len(notes) - 8} more (see the table)"] if len(notes) > 8 else []))
        fig.text(0.01, 0.01, text, fontsize="x-small", va="bottom", ha="left", family="monospace")
        bottom = min(0.45, 0.035 * (min(len(notes), 9) + 1))
    fig.tight_layout(rect=(0, bottom, 1, 0.95))
    return fig


def _panels(res) -> tuple[list, str | None]:
    """The panels ((key, y label): final error, L2 error, and the drift of the main invariant
    when the rows have one) and that invariant's key."""
    inv_key = None
    for r in res.rows:
        mi = measure.main_invariant(r.invariants)
        if mi and r.status in ("ok", "failed"):
            inv_key = mi[0]
            break
    panels = [("err_final", "error at the final time (relative)"), ("err_l2", "L2 error over the output grid (relative)")]
    if inv_key:
        panels.append(("inv", {"energy": "energy drift max |E - E(0)| (relative)",
                               "residual": "constraint residual max |g|"}.get(inv_key, f"drift of {inv_key}")))
    return panels, inv_key


def _variant(axes, panels, inv_key, rows, label: str, color, marker) -> list[str]:
    """Plot one variant's rows on every panel (failed runs as x); returns the notes of its rows
    that did not run (n/a, error, skipped)."""
    notes = []
    ok = [r for r in rows if r.ok]
    failed = [r for r in rows if r.status == "failed"]
    groups: dict = {}
    for r in rows:
        if r.status in ("n/a", "error", "skipped"):
            groups.setdefault((r.status, r.message), []).append(r.tolerance)
    for (status, msg), tols in groups.items():
        tt = [t for t in tols if t is not None]
        where = "" if not tt else (f" at {tt[0]:.0e}" if len(tt) == 1 else f" at {tt[0]:.0e} .. {tt[-1]:.0e}")
        notes.append(f"{label}{where}: {status}" + (f" ({_short(msg)})" if msg else ""))
    name = label + (f" ({len(failed)} failed)" if failed else "")
    for ax, (key, _) in zip(axes, panels):
        xs = [r.cpu for r in ok]
        ys = [_y(r, key, inv_key) for r in ok]
        pts = [(x, y) for x, y in zip(xs, ys) if y is not None and x is not None and x > 0]
        if pts:
            ax.plot([p[0] for p in pts], [p[1] for p in pts], marker=marker, color=color, lw=1.3, ms=4.5,
                    label=name if ax is axes[0] else None)
            if ax is axes[0] and ok[0].tolerance is not None:
                _tag(ax, pts[0], ok[0].tolerance, color)
                if len(pts) > 1:
                    _tag(ax, pts[-1], ok[-1].tolerance, color)
        elif ax is axes[0]:
            ax.plot([], [], marker=marker, color=color, lw=1.3, label=name)
        for r in failed:
            if r.cpu and r.cpu > 0:
                y = _y(r, key, inv_key) if key == "inv" else None
                if y is not None:
                    ax.plot([r.cpu], [y], marker="x", color=color, ms=8, mew=2, ls="none")
                else:
                    ax.plot([r.cpu], [0.97], marker="x", color=color, ms=8, mew=2, ls="none",
                            transform=ax.get_xaxis_transform(), clip_on=False)
    return notes


def _style(axes, panels, res) -> None:
    """Log axes, labels, grids, the reference's accuracy line and the legend."""
    from matplotlib.ticker import NullFormatter

    ref = res.reference
    for ax, (key, ylabel) in zip(axes, panels):
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.xaxis.set_minor_formatter(NullFormatter())      # narrow ranges: minor labels overlap
        ax.yaxis.set_minor_formatter(NullFormatter())
        ax.set_xlabel(f"CPU time [s] ({res.timer})")
        ax.set_ylabel(ylabel)
        ax.grid(True, which="major", alpha=0.35)
        ax.grid(True, which="minor", alpha=0.1)
        acc = ref.accuracy.get({"err_final": "final", "err_l2": "l2"}.get(key, ""), None) if ref.accuracy else None
        if acc is not None and acc > 0 and math.isfinite(acc):
            ax.axhline(acc, color="0.4", ls="--", lw=1)
            ax.annotate("reference accuracy (estimated)", xy=(0.02, acc), xycoords=("axes fraction", "data"),
                        xytext=(0, 3), textcoords="offset points", fontsize="x-small", color="0.35")
    axes[0].legend(fontsize="x-small", loc="best")


def _y(r, key, inv_key):
    if key == "inv":
        v = r.invariants.get(inv_key)
    else:
        v = getattr(r, key)
    if v is None or not math.isfinite(v):
        return None
    return max(v, FLOOR)


def _tag(ax, pt, tol, color):
    ax.annotate(f"{tol:.0e}", xy=pt, xytext=(3, 3), textcoords="offset points", fontsize="xx-small", color=color)


def _cols(cols) -> str:
    return ", ".join(cols) if len(cols) <= 4 else f"{', '.join(cols[:3])}, ... ({len(cols)} columns)"


def _short(msg: str, n: int = 80) -> str:
    msg = " ".join(msg.split())
    return msg if len(msg) <= n else msg[: n - 3] + "..."


def save(fig, path, overwrite=True) -> Path:
    suffix = Path(path).suffix.lower()
    if suffix not in (".png", ".svg", ".pdf"):
        raise UsageError(f"chart file must end in .png, .svg or .pdf (got {str(path)!r})")
    plt = _setup_mpl()
    tmp, final = atomic_target(path, overwrite=overwrite)
    try:
        meta = {".png": {"Software": "mechdsl"}, ".svg": {"Date": None, "Creator": "mechdsl"},
                ".pdf": {"CreationDate": None, "Creator": "mechdsl"}}[suffix]
        fig.savefig(tmp, dpi=110, format=suffix[1:], metadata=meta)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    del plt
    return commit(tmp, final)


def write_chart(res, out_dir, stem="work_precision", overwrite=False, title=None) -> list[Path]:
    plt = _setup_mpl()
    paths = [output_folder(out_dir) / f"{stem}{ext}" for ext in (".png", ".svg")]
    for p in paths:
        check_writable(p, overwrite)
    fig = draw(res, title)
    try:
        return [save(fig, p, overwrite) for p in paths]
    finally:
        plt.close(fig)
