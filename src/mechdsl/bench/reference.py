"""The reference solution of a benchmark: read from a CSV file or computed.

A reference file is a CSV in the format of ``mech simulate -o`` (first column ``time``,
then named columns).  Its times must lie on the benchmark's output grid, which is
linspace(t_start, T, points): they are equally spaced and end at T (one row at T alone
is allowed: the final-time error is then all there is).

``auto`` integrates the model twice at a tolerance below the sweep's tightest, with two
different methods (the pair depends on the model: non-stiff, stiff or constrained); the
first run is the reference, the difference between the two estimates its accuracy, in the
same norms as the benchmark errors.  Errors below that estimate are not resolved.  A
method that fails is replaced by the kind's next candidate, and when no two succeed the
tolerance is loosened a decade at a time (``reference_ladder``); the runs not used are
kept in ``notes``.  No pair at all is a simulation error (E880, exit 1).
"""
from __future__ import annotations

import csv
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..diagnostics import UsageError
from . import measure

CODE_REFERENCE = "E880"         # no automatic reference could be computed (a simulation error: exit 1)


@dataclass(kw_only=True)
class Reference:
    t: np.ndarray                                   # reference times (on the output grid)
    values: dict[str, np.ndarray]                   # column -> values at t
    source: str                                     # where it came from (file, or methods)
    methods: tuple[str, ...] = ()                   # auto: (reference, check) method labels
    tolerance: float | None = None                  # auto: rtol = atol of both runs
    accuracy: dict[str, float] = field(default_factory=dict)   # estimated error: final, l2
    cpu: dict[str, float] = field(default_factory=dict)        # auto: CPU seconds of each run
    notes: list[str] = field(default_factory=list)             # auto: runs tried and not used, and why

    def grid_points(self, t_start: float) -> tuple[int, np.ndarray]:
        """Number of output points of a grid from t_start to the last reference time that
        contains every reference time, and the indices of the reference times in it."""
        T = float(self.t[-1])
        span = T - t_start
        if not span > 0:
            raise UsageError(f"the reference ends at t = {T:g}, not after the start time {t_start:g}")
        if len(self.t) == 1:
            return 2, np.array([1])
        h = float(self.t[1] - self.t[0])
        if not h > 0 or not np.allclose(np.diff(self.t), h, rtol=1e-9, atol=1e-12 * max(1.0, abs(T))):
            raise UsageError("reference times must be equally spaced (the simulate output format)")
        n = span / h
        k0 = (float(self.t[0]) - t_start) / h
        if abs(n - round(n)) > 1e-6 * max(1.0, n) or abs(k0 - round(k0)) > 1e-6 * max(1.0, n):
            raise UsageError(f"reference times (every {h:g} from {self.t[0]:g}) do not fall on a grid "
                             f"from the start time {t_start:g}")
        idx = int(round(k0)) + np.arange(len(self.t))
        return int(round(n)) + 1, idx


def read_csv(path) -> Reference:
    p = Path(path)
    try:
        with open(p, newline="", encoding="utf-8") as f:
            rows = list(csv.reader(f))
    except OSError as e:
        raise UsageError(f"cannot read the reference {p}: {e.strerror or e}") from None
    rows = [r for r in rows if r and not r[0].startswith("#")]
    if len(rows) < 2 or rows[0][0].strip() != "time":
        raise UsageError(f"{p}: a reference CSV starts with a header line 'time,...' and has data rows")
    head = [h.strip() for h in rows[0]]
    try:
        data = np.array([[float(v) for v in r] for r in rows[1:]], float)
    except ValueError as e:
        raise UsageError(f"{p}: not a number in the data ({e})") from None
    if data.ndim != 2 or data.shape[1] != len(head):
        raise UsageError(f"{p}: every row must have {len(head)} values")
    t = data[:, 0]
    if np.any(np.diff(t) <= 0):
        raise UsageError(f"{p}: times must increase")
    return Reference(t=t, values={h: data[:, i] for i, h in enumerate(head) if i > 0}, source=f"file {p}")


def check_columns(ref: Reference, columns) -> None:
    missing = [c for c in columns if c not in ref.values]
    if missing:
        raise UsageError(f"the reference has no column {missing[0]!r} (it has: {', '.join(ref.values)})")
    bad = [c for c in columns if not np.isfinite(ref.values[c]).all()]
    if bad:
        raise UsageError(f"the reference column {bad[0]!r} is not finite")


def auto_candidates(kind: str, formulation: str | None = None) -> tuple[str, ...]:
    """Reference and check methods by kind of model, in order of preference: the first two
    that succeed are the reference and its check.  A constrained model whose scene chooses a
    formulation is referenced in that formulation first (the A02 scene's `augmented` is the
    only one that crosses its singular configurations: the others cannot reach its horizon)."""
    base = {"ode": ("scipy-dop853", "erk", "cvodes-adams"),
            "stiff": ("rosenbrock", "scipy-radau", "cvodes-bdf"),
            "dae": ("projection+cvodes-adams", "ggl+idas", "projection+cvodes-bdf", "baumgarte+cvodes-adams")}[kind]
    if kind != "dae" or not formulation:
        return base
    first = tuple(f"{formulation}+{m}" for m in ("cvodes-adams", "erk", "cvodes-bdf"))
    return first + tuple(c for c in base if c not in first)


def auto_pair(kind: str) -> tuple[str, str]:
    """The preferred reference and check methods."""
    a, b = auto_candidates(kind)[:2]
    return a, b


def reference_ladder(tol: float, steps: int = 3) -> list[float]:
    """The reference tolerance, then up to ``steps - 1`` decades looser, not above 1e-8."""
    out = [tol]
    while len(out) < steps and out[-1] * 10 <= 1e-8 * (1 + 1e-9):
        out.append(float(f"{out[-1] * 10:.6g}"))
    return out


def failure_text(result) -> str:
    f = result.failure
    if f is None:
        return "failed"
    return f"failed at t = {f.time:.6g}: {f.cause}" + (f" ({f.detail})" if f.detail else "")


def reference_failed(failures, span, given: bool):
    """The MechError (E880) of an automatic reference that no method could compute."""
    from ..diagnostics import Diagnostic, MechError, Span

    what = "the given reference methods" if given else "no pair of reference methods"
    msg = f"cannot compute the automatic reference: {what} succeeded (" + "; ".join(failures) + ")"
    hint = ("choose other methods with --reference-methods, a shorter --t-end, or give a reference file "
            "with --reference")
    return MechError(Diagnostic(CODE_REFERENCE, msg, span or Span(), hint))


def reference_tolerance(tolerances) -> float:
    """Two decades below the tightest tolerance of the sweep, within [1e-13, 1e-8]."""
    return float(min(max(min(tolerances) * 1e-2, 1e-13), 1e-8))


def from_runs(primary, check, columns, t_start_rows: np.ndarray, labels, tol, cpu) -> Reference:
    """A computed reference from two Results (primary, check) on the same grid."""
    for r, lab in ((primary, labels[0]), (check, labels[1])):
        if not r.success:
            raise reference_failed([f"{lab} at tolerance {tol:g}: {failure_text(r)}"], None, True)
    R = measure.extract(primary, columns, t_start_rows)
    C = measure.extract(check, columns, t_start_rows)
    values = {c: R[:, i] for i, c in enumerate(columns)}
    scales = measure.component_scales(values, columns)
    acc = measure.errors(C, R, scales)
    t = np.asarray(primary.t, float)[t_start_rows]
    notes = []
    ev = getattr(primary, "events", None)
    if ev is not None and (primary.metadata or {}).get("run", {}).get("problem") == "hybrid":
        # a contact scene: the events the compared runs go through
        times = [float(e["time"]) for e in ev]
        notes.append(f"events in the reference run: {len(times)}" + (f" (t = {min(times):.6g} .. {max(times):.6g})"
                                                                      if times else " (free flight only)"))
    return Reference(t=t, values=values, source=f"auto: {labels[0]} at rtol = atol = {tol:g}",
                     methods=tuple(labels), tolerance=tol, accuracy=acc, cpu=dict(zip(labels, cpu)), notes=notes)


def fmt_accuracy(ref: Reference) -> str:
    if not ref.accuracy:
        return "accuracy not estimated (given file)"
    a = ref.accuracy
    return (f"estimated accuracy (difference from {ref.methods[1]} at the same tolerance): "
            f"final {a['final']:.2e}, L2 {a['l2']:.2e}")


def is_floor(err: float | None, ref: Reference, norm: str = "final") -> bool:
    """An error within 3x of the reference's own estimated error (in the same norm) is not
    resolved: the reference cannot tell it from zero."""
    if err is None or not ref.accuracy or not math.isfinite(err):
        return False
    return err <= 3 * ref.accuracy.get(norm, 0.0)
