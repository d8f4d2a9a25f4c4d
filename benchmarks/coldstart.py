"""Cold start of ``mech``: what a fresh process spends in imports (issue 12) and in wall time
(issue 16).

    python benchmarks/coldstart.py [--runs K] [-- mech ARGS ...]     # imports of one command
    python benchmarks/coldstart.py --section [--runs K]             # the table of docs/performance.md

Imports: runs ``python -X importtime -m mechdsl ARGS`` K times (default 5; ARGS default:
``simulate models/double_pendulum.mech``, model cache warm) and prints, per run, the sum of the
top-level cumulative import times (every module the process imported, Python's own start-up
included), numpy's cumulative import time in the same run and numpy's cumulative import time
in a fresh ``python -c "import numpy"`` run just after it, then the medians and the ratios.
Issue 12's goal: imports < 2 x numpy's own import (numpy alone; see ``measure``).

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


def self_times(text: str, under: str | None = None) -> dict[str, float]:
    """{module: self ms} of an importtime log (``under``: only that module and those it imported)."""
    out: dict[str, float] = {}
    depth = None
    for line in reversed(text.splitlines()):    # a module's imports are logged before it
        m = LINE.match(line)
        if not m:
            continue
        d = len(m.group(3))
        if under is not None:
            if depth is None and m.group(4) != under:
                continue
            if depth is None:
                depth = d
            elif d <= depth:
                break
        out[m.group(4)] = out.get(m.group(4), 0.0) + int(m.group(1)) / 1000
    return out


def numpy_alone(env: dict) -> tuple[float, dict[str, float]]:
    """numpy's cumulative import time (ms) in a fresh ``python -c "import numpy"`` (what numpy's
    import costs by itself, Python's start-up not counted) and its modules' self times."""
    p = subprocess.run([sys.executable, "-X", "importtime", "-c", "import numpy"], capture_output=True, text=True,
                       env=env)
    return import_times(p.stderr)[1] or float("nan"), self_times(p.stderr, "numpy")


def least(runs: list[dict[str, float]]) -> float:
    """The sum over modules of each module's least self time over the runs: the steadiest
    figure on a shared machine (each module's time when nothing else competed)."""
    best: dict[str, float] = {}
    for r in runs:
        for k, v in r.items():
            best[k] = min(best.get(k, v), v)
    return sum(best.values())


def measure(args: list[str], runs: int, env: dict | None = None, quiet: bool = False) -> dict[str, float]:
    """Medians over ``runs`` processes of the imports, numpy's in that process and numpy's alone
    (ms: "imports", "numpy", "alone"), and the least-per-module sums of the imports and of numpy
    alone ("least", "least_numpy"); one warm-up run first (fills the model cache and the bytecode
    caches).

    Two denominators: numpy's cumulative time inside the measured process counts only the
    modules numpy imports *first* (the standard-library modules mechdsl imported before it,
    inspect, typing, enum, re..., count for mechdsl), so it is less than what ``import numpy``
    costs; the second is numpy imported alone in a fresh process, measured alternately with
    the run (side by side, under the same load)."""
    totals, numpys, alones, selfs, nselfs = [], [], [], [], []
    env = installed(env)
    subprocess.run([sys.executable, "-m", "mechdsl", *args], cwd=ROOT, capture_output=True, env=env)
    for _ in range(runs):
        p = subprocess.run([sys.executable, "-X", "importtime", "-m", "mechdsl", *args], cwd=ROOT,
                           capture_output=True, text=True, env=env)
        alone, nself = numpy_alone(env)
        selfs.append(self_times(p.stderr))
        nselfs.append(nself)
        total, numpy_ms, top = import_times(p.stderr)
        heavy = sorted(top.items(), key=lambda kv: -kv[1])[:4]
        if not quiet:
            print(f"imports {total:7.1f} ms, numpy {numpy_ms or 0:6.1f} ms (alone {alone:6.1f} ms), "
                  f"exit {p.returncode}; top: " + ", ".join(f"{k} {v:.0f}" for k, v in heavy))
        totals.append(total)
        numpys.append(numpy_ms or float("nan"))
        alones.append(alone)
    t, n, a = statistics.median(totals), statistics.median(numpys), statistics.median(alones)
    if not quiet:
        print(f"median: imports {t:.1f} ms, numpy {n:.1f} ms in the run (ratio {t / n:.2f}), "
              f"numpy alone {a:.1f} ms (ratio {t / a:.2f}; goal < 2)")
        # on a shared machine the least of each is the steadier figure (what an idle machine does)
        print(f"least:  imports {min(totals):.1f} ms, numpy {min(numpys):.1f} ms in the run "
              f"(ratio {min(totals) / min(numpys):.2f}), numpy alone {min(alones):.1f} ms "
              f"(ratio {min(totals) / min(alones):.2f})")
    ls, ln = least(selfs), least(nselfs)
    if not quiet:
        print(f"least per module: imports {ls:.1f} ms, numpy alone {ln:.1f} ms (ratio {ls / ln:.2f})")
    return {"imports": t, "numpy": n, "alone": a, "least": ls, "least_numpy": ln}


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
            m = measure(args, runs, env, quiet=True)
            t, n, a, ls, ln = m["imports"], m["numpy"], m["alone"], m["least"], m["least_numpy"]
            rows.append(f"| {label}, cache warm | {t:.0f} | {n:.0f} ({t / n:.2f}) | {a:.0f} ({t / a:.2f}) "
                        f"| {ls:.0f} / {ln:.0f} = {ls / ln:.2f} |")
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
        "| imports of a fresh process | all imports, median (ms) | numpy in the run (ratio) | numpy alone (ratio) "
        "| least per module: imports / numpy alone (goal < 2) |", "|---|---|---|---|---|",
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
