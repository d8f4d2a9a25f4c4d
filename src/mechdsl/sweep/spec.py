"""What a sweep varies: grids, tables and samplers -> one table of runs (the design).

    grid     a plain dict {name: values}: the Cartesian product (last name fastest)
    table    mechdsl.sweep.table({name: values}) or a pandas DataFrame: one run per row
    sampler  mechdsl.sample.uniform / normal(..., n, seed): one run per drawn row

``params=`` and ``starts=`` may each be any of these; given both, every params row runs
with every starts row.  Names are classified once against the model (``classify``):
Real parameters (numbers only), Integer/Boolean parameters (structural: the model is
re-analysed), and start values (``c`` or ``c.start`` for a coordinate, ``der(c)`` or
``c.speed`` for its speed).
"""
from __future__ import annotations

import itertools
import math
from dataclasses import dataclass

import numpy as np

from ..diagnostics import UsageError, did_you_mean
from ..model.names import split_state

MAX_RUNS = 100_000_000


class Table(dict):
    """A dict of equal-length arrays meant as one run per row (not a grid)."""


def table(values) -> Table:
    """Mark ``{name: values}`` (equal lengths) as a table: one run per row."""
    return Table(values)


@dataclass
class Design:
    names: tuple[str, ...]
    values: dict[str, np.ndarray]        # name -> array of n_runs
    axes: tuple[tuple[str, np.ndarray], ...] = ()   # grid axes (name, values) when the design is one grid
    n: int = 0


def design(params, starts) -> Design:
    parts = [d for d in (_one(params, "params"), _one(starts, "starts")) if d is not None]
    if not parts:
        raise UsageError("a sweep needs params= or starts= (a grid, a table or a sampler)")
    if len(parts) == 1:
        return parts[0]
    a, b = parts
    clash = set(a.names) & set(b.names)
    if clash:
        raise UsageError(f"{', '.join(sorted(clash))} given in both params and starts")
    n = a.n * b.n
    _check_size(n)
    ia, ib = np.repeat(np.arange(a.n), b.n), np.tile(np.arange(b.n), a.n)
    values = {k: v[ia] for k, v in a.values.items()}
    values.update({k: v[ib] for k, v in b.values.items()})
    axes = a.axes + b.axes if (a.axes and b.axes) else ()
    return Design(a.names + b.names, values, axes, n)


def _one(spec, what) -> Design | None:
    from ..sample import Sampler

    if spec is None:
        return None
    if isinstance(spec, Sampler):
        return _rows(spec.table(), what)
    if isinstance(spec, Table):
        return _rows(dict(spec), what)
    if type(spec).__name__ == "DataFrame" and hasattr(spec, "columns"):
        return _rows({str(c): spec[c].to_numpy() for c in spec.columns}, what)
    if isinstance(spec, dict):
        return _grid(spec, what)
    raise UsageError(f"{what} must be a dict (a grid), mechdsl.sweep.table(...), a pandas DataFrame or a "
                     f"sampler (mechdsl.sample.uniform/normal/sobol/latin_hypercube); got {type(spec).__name__}")


def _array(name, v, what) -> np.ndarray:
    try:
        a = np.atleast_1d(np.asarray(v, dtype=float))
    except (TypeError, ValueError):
        raise UsageError(f"{what}: the values of '{name}' must be numbers") from None
    if a.ndim != 1:
        raise UsageError(f"{what}: the values of '{name}' must be a list of numbers (got shape {a.shape})")
    if a.size == 0:
        raise UsageError(f"{what}: '{name}' has no values (a sweep needs at least one run)")
    if not np.isfinite(a).all():
        raise UsageError(f"{what}: '{name}' has a value that is not finite")
    return a


def _grid(spec: dict, what) -> Design:
    if not spec:
        raise UsageError(f"{what}: the grid is empty")
    axes = tuple((str(k), _array(k, v, what)) for k, v in spec.items())
    n = math.prod(a.size for _, a in axes)
    _check_size(n)
    cols = list(zip(*itertools.product(*(range(a.size) for _, a in axes))))
    values = {k: a[np.asarray(c, int)] for (k, a), c in zip(axes, cols)}
    return Design(tuple(k for k, _ in axes), values, axes, n)


def _rows(spec: dict, what) -> Design:
    if not spec:
        raise UsageError(f"{what}: the table has no columns")
    values = {str(k): _array(k, v, what) for k, v in spec.items()}
    sizes = {k: v.size for k, v in values.items()}
    if len(set(sizes.values())) != 1:
        raise UsageError(f"{what}: a table needs columns of equal length (got "
                         + ", ".join(f"{k}: {s}" for k, s in sizes.items()) + "); use a dict for a grid")
    n = next(iter(sizes.values()))
    _check_size(n)
    return Design(tuple(values), values, (), n)


def _check_size(n: int) -> None:
    if n < 1:
        raise UsageError("the sweep has no runs")
    if n > MAX_RUNS:
        raise UsageError(f"the sweep has {n:.3g} runs, more than {MAX_RUNS:g}")


@dataclass
class Names:
    real: tuple[str, ...]                 # Real parameters
    structural: tuple[str, ...]           # Integer / Boolean parameters
    starts: dict[str, str]                # sweep name -> start_vector key ("c" or "der(c)")


def classify(model, names) -> Names:
    """Sort swept names into Real parameters, structural parameters and start values."""
    by_name = {p.name: p for p in model.model.parameters}
    coords = list(model.coordinates)
    real, structural, starts = [], [], {}
    for name in names:
        p = by_name.get(name)
        if p is not None:
            (structural if p.integer else real).append(name)
            continue
        key = _start_key(name, coords)
        if key is None:
            known = list(by_name) + coords + [f"der({c})" for c in coords]
            hint = did_you_mean(name, known)
            raise UsageError(f"'{name}' is neither a parameter nor a coordinate of {model.name}"
                             + (f"; {hint}" if hint else f" (parameters: {', '.join(by_name) or 'none'}; "
                                f"coordinates: {', '.join(coords) or 'none'})"))
        starts[name] = key
    keys = list(starts.values())
    dup = {k for k in keys if keys.count(k) > 1}
    if dup:
        raise UsageError(f"the start value {', '.join(sorted(dup))} is swept under two names")
    return Names(tuple(real), tuple(structural), starts)


def _start_key(name: str, coords) -> str | None:
    if name in coords:
        return name
    coord, speed = split_state(name)
    if speed and coord in coords:
        return name
    for suffix, fmt in ((".start", "{}"), (".speed", "der({})")):
        if name.endswith(suffix) and name[: -len(suffix)] in coords:
            return fmt.format(name[: -len(suffix)])
    return None


def parse_range(text: str, unit_of=None) -> tuple[str, np.ndarray]:
    """The CLI's ``--grid NAME=A:B:N`` (N values from A to B) or ``NAME=v1,v2,...``; values in
    NAME's declared unit (``unit_of(name)``; ``30 deg`` converted to it: numbers.in_declared_unit)."""
    from ..numbers import in_declared_unit, number as plain

    name, sep, rhs = str(text).partition("=")
    name = name.strip()
    unit = unit_of(name) if unit_of is not None and name else None

    def number(v, what):
        return in_declared_unit(v.strip(), unit, what)

    if not sep or not name:
        raise UsageError(f"--grid {text!r}: expected NAME=START:STOP:COUNT or NAME=V1,V2,...")
    if ":" in rhs:
        parts = rhs.split(":")
        if len(parts) != 3:
            raise UsageError(f"--grid {text!r}: a range is START:STOP:COUNT (three fields)")
        a, b = number(parts[0], f"--grid {name}"), number(parts[1], f"--grid {name}")
        c = plain(parts[2], f"--grid {name}")
        if c != int(c) or c < 1:
            raise UsageError(f"--grid {name}: the count must be an integer >= 1 (got {parts[2].strip()})")
        if c > MAX_RUNS:
            raise UsageError(f"--grid {name}: the count {c:g} is more than {MAX_RUNS:g}")
        return name, np.linspace(a, b, int(c))
    vals = [v for v in rhs.split(",") if v.strip()]
    if not vals:
        raise UsageError(f"--grid {name}: no values")
    return name, np.array([number(v, f"--grid {name}") for v in vals])
