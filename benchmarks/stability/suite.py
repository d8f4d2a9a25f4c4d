"""Shared pieces of the stability cases: Check, Case, model loading, figure saving."""
from __future__ import annotations

import sys
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

HERE = Path(__file__).resolve().parent
ROOT = HERE.parents[1]
if str(ROOT / "src") not in sys.path:
    sys.path.insert(0, str(ROOT / "src"))

SIZES = ("small", "full")


@dataclass(kw_only=True)
class Check:
    claim: str                 # what should hold
    holds: bool
    detail: str                # the numbers behind it

    def line(self) -> str:
        return f"  [{'holds' if self.holds else 'FAILS'}] {self.claim}: {self.detail}"


@dataclass(kw_only=True)
class Case:
    name: str
    title: str
    size: str
    checks: list[Check] = field(default_factory=list)
    data: dict[str, Any] = field(default_factory=dict)
    table: list[str] = field(default_factory=list)     # printed lines (numbers measured in the run)

    def check(self, claim: str, holds: bool, detail: str) -> bool:
        self.checks.append(Check(claim=claim, holds=bool(holds), detail=detail))
        return bool(holds)

    @property
    def holds(self) -> bool:
        return all(c.holds for c in self.checks)

    def report(self) -> str:
        return "\n".join([f"{self.title} ({self.size})", *self.table, *(c.line() for c in self.checks)])


def check_size(size: str) -> str:
    if size not in SIZES:
        raise ValueError(f"size must be one of {SIZES}")
    return size


def load(path: str, **kw):
    import mechdsl

    p = Path(path)
    if not p.is_absolute():
        p = ROOT / p
    return mechdsl.load(str(p), **kw)


def save(fig, out_dir, stem) -> list[Path]:
    """PNG and SVG, written atomically (mechdsl.output.fileio)."""
    import matplotlib.pyplot as plt

    from mechdsl.bench.chart import save as save_one

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    try:
        return [save_one(fig, out / f"{stem}{ext}") for ext in (".png", ".svg")]
    finally:
        plt.close(fig)


def pyplot():
    from mechdsl.bench.chart import _setup_mpl

    return _setup_mpl()


def fmt_fail(r) -> str:
    return "ok" if r.success else f"failed at t = {r.failure.time:.4g}: {r.failure.cause}"
