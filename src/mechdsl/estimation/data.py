"""Measured data for a fit: ``experiments(data, settings, signals) -> [Experiment]``.

A table is a CSV file (a header line of names, then rows of numbers: what ``mech simulate
-o out.csv`` writes), a pandas DataFrame (time a column or the index) or a dict of arrays,
with a time column ``time`` (or ``t``) in seconds and columns named like recorded signals:
coordinates, their speeds ``der(c)``, outputs, energies.  Several experiments: a list of
tables, and ``experiments=[{...}, ...]`` with each one's settings (start values ``x0``,
``inputs``, ``p`` of parameters not fitted).

Every problem is a located error (MechError, exit 1 on the command line), nothing is fitted:
a column that names no recorded signal (E771, at its header cell), times that are missing,
not increasing or outside the run (E772, at the row), and values that are not finite numbers
(E773, at the cell).  A CSV file's errors show its line with a caret.
"""
from __future__ import annotations

import csv
import io
import os

import numpy as np

from ..diagnostics import Diagnostic, MechError, Span, UsageError, did_you_mean, remember_source
from ..model.records import record

TIME_NAMES = ("time", "t")
CODE_COLUMN, CODE_TIMES, CODE_VALUE = "E771", "E772", "E773"
MAX_ROWS = 10_000_000


@record
class Experiment:
    label: str                     # the file's path, or "data" / "data[k]" for tables in memory
    t: np.ndarray                  # (N,) strictly increasing
    columns: tuple[str, ...]       # recorded signals measured
    Y: np.ndarray                  # (len(columns), N)
    settings: dict                 # this experiment's run settings (x0, inputs, p)
    where: dict                    # column -> (line, col) of its header cell (a CSV file; else empty)
    rows: tuple[int, ...] = ()     # the file line of each sample (a CSV file; else empty)
    time_name: str = "time"        # the time column's name

    def span(self, line: int = 0, col: int = 0) -> Span:
        return Span(self.label, line, col, line, col + 1 if line else 0)


def experiments(data, settings, what: str = "data") -> list[Experiment]:
    """The tables and their settings as Experiments (columns not yet checked against a model)."""
    tables = list(data) if isinstance(data, (list, tuple)) else [data]
    if not tables:
        raise UsageError(f"{what}: no table given")
    if settings is None:
        settings = [{}] * len(tables)
    elif isinstance(settings, dict):
        settings = [settings]
    settings = list(settings)
    if len(settings) != len(tables):
        raise UsageError(f"experiments: {len(settings)} settings for {len(tables)} table(s): give one dict per table")
    out = []
    for k, (tab, st) in enumerate(zip(tables, settings)):
        if not isinstance(st, dict):
            raise UsageError(f"experiments[{k}]: a dict of run settings (x0, inputs, p, ...), got {type(st).__name__}")
        label = what if len(tables) == 1 else f"{what}[{k}]"
        out.append(_one(tab, dict(st), label))
    return out


def _one(tab, st, label) -> Experiment:
    if isinstance(tab, (str, os.PathLike)):
        return _csv(os.fspath(tab), st)
    if type(tab).__name__ == "DataFrame" and hasattr(tab, "columns"):
        cols = {str(c): np.asarray(tab[c]) for c in tab.columns}
        index = getattr(tab, "index", None)
        if not any(n in cols for n in TIME_NAMES) and index is not None and str(index.name) in TIME_NAMES:
            cols = {str(index.name): np.asarray(index), **cols}
        return _table(cols, st, label)
    if isinstance(tab, dict):
        return _table({str(k): v for k, v in tab.items()}, st, label)
    raise UsageError(f"{label}: a table is a CSV path, a pandas DataFrame or a dict of arrays "
                     f"(got {type(tab).__name__})")


def _table(cols: dict, st, label) -> Experiment:
    tname = next((n for n in TIME_NAMES if n in cols), None)
    if tname is None:
        raise MechError(Diagnostic(CODE_TIMES, f"{label}: no time column (columns: {', '.join(cols) or 'none'})",
                                   Span(label), help="name the column of times 'time' (or 't'), in seconds"))
    arrays = {}
    for name, v in cols.items():
        try:
            a = np.asarray(v, dtype=float).ravel()
        except (TypeError, ValueError):
            raise MechError(Diagnostic(CODE_VALUE, f"{label}: column '{name}' holds values that are not numbers",
                                       Span(label), help="every value must be a finite number")) from None
        arrays[name] = a
    n = {a.size for a in arrays.values()}
    if len(n) != 1:
        raise UsageError(f"{label}: the columns have different lengths ({', '.join(f'{k}: {a.size}' for k, a in arrays.items())})")
    t = arrays.pop(tname)
    exp = Experiment(label, t, tuple(arrays), np.array(list(arrays.values()), float).reshape(len(arrays), t.size),
                     st, {}, (), tname)
    _check_values(exp, tname)
    return exp


def _csv(path: str, st) -> Experiment:
    try:
        with open(path, newline="", encoding="utf-8") as fh:
            text = fh.read()
    except (OSError, UnicodeDecodeError) as e:
        raise UsageError(f"cannot read the data file {path}: {getattr(e, 'strerror', None) or e}") from None
    remember_source(path, text)
    lines = text.split("\n")
    rows = [(i + 1, r) for i, r in enumerate(csv.reader(io.StringIO(text))) if r and any(c.strip() for c in r)]
    if not rows:
        raise MechError(Diagnostic(CODE_TIMES, f"the data file {path} is empty", Span(path),
                                   help="a header line of names (time, then recorded signals), then rows of numbers"))
    head_line, header = rows[0]
    header = [h.strip() for h in header]
    where = {h: (head_line, _col(lines[head_line - 1], j)) for j, h in enumerate(header)}
    tcol = next((header.index(n) for n in TIME_NAMES if n in header), None)
    if tcol is None:
        raise MechError(Diagnostic(CODE_TIMES, f"no time column in {path} (columns: {', '.join(header)})",
                                   Span(path, head_line, 1, head_line, len(lines[head_line - 1]) + 1),
                                   help="name the column of times 'time' (or 't'), in seconds"))
    dup = sorted({h for h in header if header.count(h) > 1})
    if dup:
        line, col = where[dup[0]]
        raise MechError(Diagnostic(CODE_COLUMN, f"the column '{dup[0]}' appears twice", Span(path, line, col),
                                   help="name each measured signal once"))
    if len(rows) - 1 > MAX_ROWS:
        raise UsageError(f"{path}: more than {MAX_ROWS} rows")
    data = np.empty((len(rows) - 1, len(header)))
    for k, (line, r) in enumerate(rows[1:]):
        if len(r) != len(header):
            raise MechError(Diagnostic(CODE_VALUE, f"line {line} has {len(r)} value{'s' if len(r) != 1 else ''} for {len(header)} columns",
                                       Span(path, line, 1, line, len(lines[line - 1]) + 1),
                                       help="one value per column on every line"))
        for j, c in enumerate(r):
            try:
                v = float(c)
            except ValueError:
                v = None
            if v is None or not np.isfinite(v):
                col = _col(lines[line - 1], j)
                what = "a number" if v is None else "a finite number"
                raise MechError(Diagnostic(CODE_VALUE, f"the value {c.strip()!r} of '{header[j]}' at line {line} is not "
                                           f"{what}", Span(path, line, col, line, col + max(1, len(c))),
                                           help="every value must be a finite number; drop samples that were not "
                                                "measured (a row, or a column from the fit)"))
            data[k, j] = v
    if len(rows) == 1:
        raise MechError(Diagnostic(CODE_TIMES, f"no samples in {path}: a header line and no rows",
                                   Span(path, head_line, 1, head_line, len(lines[head_line - 1]) + 1),
                                   help="a fit needs measured samples: rows of numbers under the header"))
    t = data[:, tcol]
    keep = [j for j in range(len(header)) if j != tcol]
    exp = Experiment(path, t, tuple(header[j] for j in keep), data[:, keep].T.copy(), st, where,
                     tuple(line for line, _ in rows[1:]), header[tcol])
    _check_values(exp, header[tcol])
    return exp


def _col(line: str, j: int) -> int:
    """1-based character column where field j of a CSV line starts."""
    field, quoted = 0, False
    for i, ch in enumerate(line):
        if field == j:
            return i + 1
        if ch == '"':
            quoted = not quoted
        elif ch == "," and not quoted:
            field += 1
    return len(line) + 1


def _who(exp: Experiment) -> str:
    """The message's prefix naming the table: none for a CSV file (its diagnostic names the file)."""
    return "" if exp.rows or exp.where else f"{exp.label}: "


def _row_span(exp: Experiment, k: int, name: str | None = None) -> Span:
    if exp.rows:
        line = exp.rows[k]
        col = exp.where.get(name, (0, 1))[1] if name else 1
        return Span(exp.label, line, col, line, col + 1)
    return Span(exp.label)


def _check_values(exp: Experiment, tname: str) -> None:
    """Times and values finite, times increasing."""
    if exp.t.size == 0:
        raise MechError(Diagnostic(CODE_TIMES, f"{_who(exp)}no samples (a header and no rows)", Span(exp.label),
                                   help="a fit needs measured samples"))
    bad = np.flatnonzero(~np.isfinite(exp.t))
    if bad.size:
        raise MechError(Diagnostic(CODE_VALUE, f"{_who(exp)}the time of sample {bad[0] + 1} is not a finite number",
                                   _row_span(exp, int(bad[0]), tname), help="every time must be a finite number"))
    for i, name in enumerate(exp.columns):
        bad = np.flatnonzero(~np.isfinite(exp.Y[i]))
        if bad.size:
            k = int(bad[0])
            raise MechError(Diagnostic(
                CODE_VALUE, f"{_who(exp)}the value of '{name}' at t = {exp.t[k]:g} s (sample {k + 1}) is not a "
                f"finite number ({exp.Y[i, k]})", _row_span(exp, k, name),
                help="every value must be a finite number; drop samples that were not measured (a row, or the "
                     "column from the fit)"))
    step = np.diff(exp.t)
    if (step <= 0).any():
        k = int(np.flatnonzero(step <= 0)[0]) + 1
        raise MechError(Diagnostic(CODE_TIMES, f"{_who(exp)}the times are not increasing: t = {exp.t[k]:g} s "
                                   f"(sample {k + 1}) after t = {exp.t[k - 1]:g} s", _row_span(exp, k, tname),
                                   help="sort the samples by time, one sample per time"))


def check_columns(exp: Experiment, signals, model: str) -> None:
    """Every column names a recorded signal (E771 at its header cell, with did-you-mean)."""
    signals = list(signals)
    if not exp.columns:
        line, col = next(iter(exp.where.values()), (0, 0))
        raise MechError(Diagnostic(CODE_COLUMN, f"{_who(exp)}no measured column besides the time",
                                   exp.span(line, col),
                                   help=f"name columns like the recorded signals of {model}: {', '.join(signals)}"))
    for name in exp.columns:
        if name not in signals:
            hint = did_you_mean(name, signals)
            line, col = exp.where.get(name, (0, 0))
            raise MechError(Diagnostic(CODE_COLUMN, f"the column '{name}' names no recorded signal of {model}",
                                       Span(exp.label, line, col, line, col + len(name) if line else 0),
                                       help=(hint + " " if hint else "") + f"(signals: {', '.join(signals)})"))


def check_times(exp: Experiment, t_start: float, t_end: float) -> None:
    """Every sample time lies in the run [t_start, t_end] (E772 at the first that does not)."""
    tol = 1e-9 * max(1.0, abs(t_start), abs(t_end))
    out = np.flatnonzero((exp.t < t_start - tol) | (exp.t > t_end + tol))
    if out.size:
        k = int(out[0])
        raise MechError(Diagnostic(CODE_TIMES, f"{_who(exp)}t = {exp.t[k]:g} s (sample {k + 1}) is outside the run "
                                   f"[{t_start:g}, {t_end:g}] s", _row_span(exp, k, exp.time_name),
                                   help="the run starts at the scene's start_time (t_start) and ends at the last "
                                        "sample unless t_end is given: drop the samples outside it or move the start"))
