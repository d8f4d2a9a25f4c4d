"""Per-run metrics of a sweep and the heat map over its two grid axes (``mech sweep --plot``)."""
from __future__ import annotations

import math

import numpy as np

from ..diagnostics import UsageError, did_you_mean


def metric(ds, spec: str) -> np.ndarray:
    """One number per run: ``flip:A+B`` (first time |A + B| > pi, NaN if never),
    ``final:V`` (last value reached), ``max:V`` (max |V|) or a status column."""
    from . import first_time

    kind, sep, expr = str(spec).partition(":")
    if not sep:
        per_run = [v for v in ds.data_vars if ds[v].dims == ("run",) and ds[v].dtype.kind in "fiub"]
        if spec in per_run:
            return np.asarray(ds[spec].values, float)
        hint = did_you_mean(spec, per_run)
        raise UsageError(f"--metric {spec!r}: not a status column (" + ", ".join(per_run) + ")"
                         + (f"; {hint}" if hint else "") + "; or use flip:EXPR, final:VAR, max:VAR")
    values = _sum(ds, expr)
    if kind == "flip":
        return first_time(ds, values, math.pi)
    if kind == "max":
        with np.errstate(invalid="ignore"):
            return np.nanmax(np.abs(values), axis=1)
    if kind == "final":
        out = np.full(values.shape[0], np.nan)
        for i, row in enumerate(values):
            ok = np.flatnonzero(np.isfinite(row))
            if ok.size:
                out[i] = row[ok[-1]]
        return out
    raise UsageError(f"--metric {spec!r}: unknown kind '{kind}' (flip, final, max)")


def _sum(ds, expr: str) -> np.ndarray:
    total = None
    for name in [t.strip() for t in expr.split("+")]:
        if name not in ds.data_vars or ds[name].dims != ("run", "time"):
            known = [v for v in ds.data_vars if ds[v].dims == ("run", "time")]
            hint = did_you_mean(name, known)
            raise UsageError(f"--metric: '{name}' is not a recorded variable ({', '.join(known)})"
                             + (f"; {hint}" if hint else ""))
        v = np.asarray(ds[name].values, float)
        total = v if total is None else total + v
    return total


def metric_unit(ds, spec: str) -> str:
    """The unit of a --metric: flip -> s, final/max -> the variable's, a status column -> its own."""
    kind, sep, expr = str(spec).partition(":")
    if not sep:
        return _unit(ds, spec)
    if kind == "flip":
        return "s"
    units = {_unit(ds, n.strip()) for n in expr.split("+")}
    return units.pop() if len(units) == 1 else ""


def _unit(ds, name: str) -> str:
    try:
        return str(ds[name].attrs.get("units", ""))
    except KeyError:
        return ""


def _labelled(name: str, unit: str) -> str:
    return f"{name} [{unit}]" if unit else name


def heat_map_figure(ds, values: np.ndarray, label: str):
    """The Figure of ``heat_map``: axes and colour bar labelled with their units."""
    from matplotlib.figure import Figure

    axes = [a for a in str(ds.attrs.get("grid_axes", "")).split(",") if a]
    if len(axes) not in (1, 2):
        raise UsageError(f"--plot draws a map over one or two --grid axes; this sweep has {len(axes) or 'no'} "
                         "grid axes")
    fig = Figure(figsize=(6.4, 5.0))
    ax = fig.add_subplot()
    cols = [np.unique(np.asarray(ds[a].values, float)) for a in axes]
    value_label = _labelled(label, metric_unit(ds, label))
    if len(axes) == 1:
        ax.plot(np.asarray(ds[axes[0]].values, float), values, ".-")
        ax.set_xlabel(_labelled(axes[0], _unit(ds, axes[0])))
        ax.set_ylabel(value_label)
    else:
        Z = np.asarray(values, float).reshape(len(cols[0]), len(cols[1]))    # grid order: last axis fastest
        im = ax.pcolormesh(cols[1], cols[0], np.ma.masked_invalid(Z), shading="nearest", cmap="viridis")
        fig.colorbar(im, ax=ax, label=value_label + " (white: never / failed)")
        ax.set_xlabel(_labelled(axes[1], _unit(ds, axes[1])))
        ax.set_ylabel(_labelled(axes[0], _unit(ds, axes[0])))
    ax.set_title(f"{ds.attrs.get('model', '')}: {ds.attrs.get('summary', '')}", fontsize=9)
    return fig


def heat_map(ds, values: np.ndarray, label: str, path, overwrite: bool = True):
    """A heat map of ``values`` over the sweep's two grid axes (a line over one axis), saved."""
    from ..output.plot import save_figure

    return save_figure(heat_map_figure(ds, values, label), path, overwrite=overwrite)
