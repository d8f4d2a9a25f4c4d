"""Cold start of ``mech``: what a fresh process spends in imports (issue 12) and in wall time
(issue 16).

    python benchmarks/coldstart.py [--runs K] [-- mech ARGS ...]     # imports of one command
    python benchmarks/coldstart.py --section [--runs K]             # the table of docs/performance.md

Imports: runs ``python -X importtime -m mechdsl ARGS`` K times (default 5; ARGS default:
``simulate models/double_pendulum.mech``, model cache warm) and prints, per run, the sum of the
top-level cumulative import times (every module the process imported, Python's own start-up
included) and numpy's own cumulative import time in the same run, then the medians and their
ratio.  Issue 12's goal: imports < 2 x numpy.

Wall times (``--section``): whole processes from start to exit, median of K, for ``mech
--version``, ``mech check`` of a small model, and ``mech simulate`` of the 12-link chain with
the model cache warm (second invocation) and cold (a fresh cache folder each run; the LALR
tables of the parser stay cached, as after any earlier use of mechdsl).
"""
from __future__ import annotations

import os
import re
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
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


def installed(env: dict | None) -> dict:
    """The environment of a measured process: bytecode caches written and used, as after
    ``pip install`` (PYTHONDONTWRITEBYTECODE would compile every mechdsl module from source at
    each start, while numpy's come compiled)."""
    e = dict(os.environ if env is None else env)
    e.pop("PYTHONDONTWRITEBYTECODE", None)
    return e


def measure(args: list[str], runs: int, env: dict | None = None, quiet: bool = False) -> tuple[float, float]:
    """Median (imports ms, numpy ms) over ``runs`` processes; one warm-up run first (fills the
    model cache and the bytecode caches)."""
    totals, numpys = [], []
    env = installed(env)
    subprocess.run([sys.executable, "-m", "mechdsl", *args], cwd=ROOT, capture_output=True, env=env)
    for _ in range(runs):
        p = subprocess.run([sys.executable, "-X", "importtime", "-m", "mechdsl", *args], cwd=ROOT,
                           capture_output=True, text=True, env=env)
        total, numpy_ms, top = import_times(p.stderr)
        heavy = sorted(top.items(), key=lambda kv: -kv[1])[:4]
        if not quiet:
            print(f"imports {total:7.1f} ms, numpy {numpy_ms or 0:6.1f} ms, exit {p.returncode}; top: "
                  + ", ".join(f"{k} {v:.0f}" for k, v in heavy))
        totals.append(total)
        numpys.append(numpy_ms or float("nan"))
    t, n = statistics.median(totals), statistics.median(numpys)
    if not quiet:
        print(f"median: imports {t:.1f} ms, numpy {n:.1f} ms, ratio {t / n:.2f} (goal < 2)")
        # on a shared machine the least of each is the steadier figure (what an idle machine does)
        print(f"least:  imports {min(totals):.1f} ms, numpy {min(numpys):.1f} ms, "
              f"ratio {min(totals) / min(numpys):.2f}")
    return t, n


def wall(args: list[str], runs: int, env: dict | None = None, fresh_cache: bool = False) -> float:
    """Median wall seconds of ``python -m mechdsl ARGS`` (fresh_cache: a new cache folder each run)."""
    times = []
    for _ in range(runs):
        e = installed(env)
        tmp = tempfile.mkdtemp(prefix="mechdsl-cold-") if fresh_cache else None
        if tmp:
            e["MECHDSL_CACHE"] = tmp
        t0 = time.perf_counter()
        p = subprocess.run([sys.executable, "-m", "mechdsl", *args], cwd=ROOT, capture_output=True, env=e)
        times.append(time.perf_counter() - t0)
        if tmp:
            shutil.rmtree(tmp, ignore_errors=True)
        if p.returncode != 0:
            raise RuntimeError(f"mech {' '.join(args)} failed: {p.stderr.decode()[-500:]}")
    return statistics.median(times)


CHAIN = ["simulate", "models/nlink_pendulum.mech", "--set", "N=12", "--t-end", "5", "--no-progress"]


def section(runs: int = 5) -> str:
    """The cold-start table of docs/performance.md (markdown)."""
    cache = tempfile.mkdtemp(prefix="mechdsl-coldstart-")
    env = {**os.environ, "MECHDSL_CACHE": cache}
    try:
        rows = []
        for label, args in (("`mech simulate models/double_pendulum.mech`", ["simulate", "models/double_pendulum.mech",
                                                                             "--no-progress"]),
                            ("`mech simulate` 12-link chain, 5 s", CHAIN)):
            t, n = measure(args, runs, env, quiet=True)
            rows.append(f"| {label}, cache warm | {t:.0f} | {n:.0f} | {t / n:.2f} |")
        walls = [("`mech --version`", wall(["--version"], runs, env)),
                 ("`mech check models/pendulum.mech`", wall(["check", "models/pendulum.mech"], runs, env)),
                 ("`mech simulate` 12-link chain, 5 s: cache warm (second invocation)", wall(CHAIN, runs, env)),
                 ("`mech simulate` 12-link chain, 5 s: cache cold (first invocation)",
                  wall(CHAIN, runs, env, fresh_cache=True))]
    finally:
        shutil.rmtree(cache, ignore_errors=True)
    load = ", ".join(f"{x:.2f}" for x in os.getloadavg())
    return "\n".join([
        f"`benchmarks/coldstart.py --section` (median of {runs} processes; load average {load} at the end).", "",
        "| imports of a fresh process | all imports (ms) | numpy (ms) | ratio (goal < 2) |", "|---|---|---|---|",
        *rows, "", "| whole process | wall (s) |", "|---|---|",
        *(f"| {k} | {v:.3f} |" for k, v in walls)])


def main(argv: list[str]) -> None:
    runs = 5
    show = "--section" in argv
    argv = [a for a in argv if a != "--section"]
    if argv[:1] == ["--runs"]:
        runs, argv = int(argv[1]), argv[2:]
    if show:
        print(section(runs))
        return
    if argv[:1] == ["--"]:
        argv = argv[1:]
    measure(argv or ["simulate", "models/double_pendulum.mech"], runs)


if __name__ == "__main__":
    main(sys.argv[1:])
