"""Run the stability suite: every case, its checks and its chart.

    PYTHONPATH=src python benchmarks/stability/run.py [--size small|full] [--cases stiff,energy,...] [-o DIR]

Prints each case's measured table and checks; writes stability_<case>.png/.svg to DIR
(default docs/figures).  Exit status 1 when a check fails.
"""
from __future__ import annotations

import argparse
import importlib
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
if str(HERE.parent) not in sys.path:
    sys.path.insert(0, str(HERE.parent))

from stability.suite import ROOT  # noqa: E402

ODE_CASES = ["stiff", "energy", "gimbal", "chaos"]
DAE_CASES = ["cartesian", "fourbar", "bricard", "andrews"]


def available_cases() -> list[str]:
    """The ODE cases always; the constrained ones when mechdsl.dae is installed."""
    try:
        importlib.import_module("mechdsl.dae")
        dae = True
    except ImportError:
        dae = False
    return ODE_CASES + ([c for c in DAE_CASES if (HERE / f"{c}.py").exists()] if dae else [])


def run_cases(names, size, out_dir=None, log=print):
    results = []
    for name in names:
        mod = importlib.import_module(f"stability.{name}")
        c0, w0 = time.process_time(), time.perf_counter()
        case = mod.run(size)
        case.data["_cpu"] = time.process_time() - c0
        case.data["_wall"] = time.perf_counter() - w0
        files = mod.chart(case, out_dir) if out_dir is not None else []
        case.data["_files"] = files
        log(case.report())
        log(f"  ({case.data['_cpu']:.1f} s CPU, {case.data['_wall']:.1f} s wall)")
        results.append(case)
    return results


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--size", choices=("small", "full"), default="full")
    ap.add_argument("--cases", default=None, help="comma-separated (default: all available)")
    ap.add_argument("-o", "--out", default=str(ROOT / "docs" / "figures"))
    a = ap.parse_args(argv)
    names = a.cases.split(",") if a.cases else available_cases()
    missing = sorted(set(DAE_CASES) & set(names) - set(available_cases()))
    if missing:
        print(f"cases {', '.join(missing)} need mechdsl.dae (constrained models), which is not installed",
              file=sys.stderr)
        return 2
    results = run_cases(names, a.size, a.out)
    bad = [c.name for c in results if not c.holds]
    print("all checks hold" if not bad else f"checks FAIL in: {', '.join(bad)}")
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
