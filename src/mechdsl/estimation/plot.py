"""The figure of a fit (``FitResult.plot``): measured samples and the fitted model, one panel
per measured signal, every experiment in its panel (matplotlib's Figure, no pyplot)."""
from __future__ import annotations

import numpy as np


MAX_PANELS = 12


def fit_figure(result, title: str | None = None):
    from matplotlib.figure import Figure

    from .sensitivity import signal_units

    columns = list(dict.fromkeys(c for e in result.experiments for c in e.columns))
    shown = columns[:MAX_PANELS]
    fig = Figure(figsize=(8.0, 1.9 * len(shown) + 1.0))
    axes = fig.subplots(len(shown), 1, squeeze=False, sharex=True)[:, 0]
    units = signal_units(result.source_model, columns)
    colors = [f"C{k % 10}" for k in range(len(result.experiments))]
    for ax, c in zip(axes, shown):
        for k, (e, fitted) in enumerate(zip(result.experiments, result.fitted)):
            if c not in e.columns:
                continue
            i = e.columns.index(c)
            many = len(result.experiments) > 1
            ax.plot(e.t, e.Y[i], ".", ms=2.5, color=colors[k], alpha=0.6,
                    label=f"measured{' (' + e.label + ')' if many else ''}")
            ax.plot(e.t, fitted[c], "-", lw=1.2, color="k" if not many else colors[k],
                    label=f"fitted model{' (' + e.label + ')' if many else ''}")
        unit = units.get(c, "")
        ax.set_ylabel(f"{c} [{unit}]" if unit else c, fontsize=8)
        ax.grid(alpha=0.3)
    axes[0].legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.01, 1.0))
    axes[-1].set_xlabel("time [s]")
    est = ", ".join((f"{n} = {result.estimates[n]:.4g}" + (f" {result.units[n]}" if result.units[n] else ""))
                    if np.isfinite(result.standard_errors[n]) else f"{n} not determined" for n in result.names[:6])
    more = f" (+{len(columns) - len(shown)} signals not shown)" if len(columns) > len(shown) else ""
    fig.suptitle(title or f"{result.model_name}: fit ({est}){more}", fontsize=9)
    fig.tight_layout()
    return fig


