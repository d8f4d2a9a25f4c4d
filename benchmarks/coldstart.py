"""Cold start of ``mech``: what a fresh process spends in imports (issue 12) and in wall time.

    python benchmarks/coldstart.py [--runs K] [-- mech ARGS ...]

Runs ``python -X importtime -m mechdsl ARGS`` K times (default 5; ARGS default: ``simulate
models/double_pendulum.mech``) and prints, per run, the sum of the top-level cumulative import
times (every module the process imported, Python's own start-up included) and numpy's own
cumulative import time in the same run, then the medians and their ratio.  Issue 12's goal:
imports < 2 x numpy.  Wall times of whole processes are measured with ``farm-bench`` (see
docs/performance.md, Cold start).
"""
from __future__ import annotations

import re
import statistics
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
LINE = re.compile(r"import time:\s+(\d+) \|\s+(\d+) \|( +)(\S+)")


def import_times(text: str) -> tuple[float, float | None, dict[str, float]]:
    """(sum of top-level cumulative ms, numpy's cumulative ms or None, {top-level module: ms})."""
    top: dict[str, float] = {}
    numpy_ms = None
    for line in text.splitlines():
        m = LINE.match(line)
        if not m:
            continue
        cum = int(m.group(2)) / 1000
        if len(m.group(3)) == 1:
            top[m.group(4)] = top.get(m.group(4), 0.0) + cum
        if m.group(4) == "numpy":
            numpy_ms = cum
    return sum(top.values()), numpy_ms, top


def measure(args: list[str], runs: int) -> None:
    totals, numpys = [], []
    for _ in range(runs):
        p = subprocess.run([sys.executable, "-X", "importtime", "-m", "mechdsl", *args], cwd=ROOT,
                           capture_output=True, text=True)
        total, numpy_ms, top = import_times(p.stderr)
        heavy = sorted(top.items(), key=lambda kv: -kv[1])[:4]
        print(f"imports {total:7.1f} ms, numpy {numpy_ms or 0:6.1f} ms, exit {p.returncode}; top: "
              + ", ".join(f"{k} {v:.0f}" for k, v in heavy))
        totals.append(total)
        numpys.append(numpy_ms or float("nan"))
    t, n = statistics.median(totals), statistics.median(numpys)
    print(f"median: imports {t:.1f} ms, numpy {n:.1f} ms, ratio {t / n:.2f} (goal < 2)")


def main(argv: list[str]) -> None:
    runs = 5
    if argv[:1] == ["--runs"]:
        runs, argv = int(argv[1]), argv[2:]
    if argv[:1] == ["--"]:
        argv = argv[1:]
    measure(argv or ["simulate", "models/double_pendulum.mech"], runs)


if __name__ == "__main__":
    main(sys.argv[1:])
