"""Whole-process cost of ``mech simulate`` on a cold and a warm cache (issue 24, items 3 and 8).

    PYTHONPATH=src python benchmarks/first_run.py [--sizes 12,25,50,100,200] [--runs K]

For the N-link chain (models/nlink_pendulum.mech --set N=... --t-end 5) runs ``python -m
mechdsl simulate ... --no-progress`` as a fresh process and reads its CPU time (user + system)
and peak resident memory from the operating system (os.wait4: the process and the compiler
processes it waited for).  Five states of the cache folder ($MECHDSL_CACHE):

- ``empty``: a new, empty folder (nothing compiled, nothing derived: a first run on a new
  machine).  The stepping loop's runtime library (crk.c + vm.c) comes with the install
  (hatch_build.py; with PYTHONPATH=src the checkout's copy, which ``pip install -e .`` builds
  into src/mechdsl/simulation/backends/_runtime/; without it, it is compiled in this run);
- ``new model``: a folder where another model ran before (the chain never seen: parsed and
  derived in this run);
- ``warm``: the same command a second time (everything read from the cache: the prepared warm
  run, simulation/warm_run.py, which imports no CasADi, when the run is short enough to keep);
- ``third``: and a third time.  A model the cache has not compiled runs interpreted until its
  interpreted evaluations, counted in the cache, have paid for its compile
  (simulation/backends/payback.py: 100,000 x (1 + 400 / operations) evaluations; the 12-link
  chain, ~14,500 a 5 s run with its error estimate, pays in its tenth run, the 200-link chain,
  ~27,700 against ~100,000, in its fourth): the run that crosses that line pays gcc, the runs
  after it are compiled; so the empty, new-model, warm and third runs here are interpreted;
- ``model cache``: the same command with the prepared run removed (the normal path: the model
  cache, the compiled library; what a warm run cost before prepared runs).

Beside them, measured in the same loop: ``python -c pass`` (the interpreter's own start, the
floor of any process) and ``python -c "import numpy"``; the last columns are the warm run's
ratios to the normal path (model cache) and to ``python -c pass``.

Each figure is the least CPU time of K processes (default 3; the peak: the largest), one new folder per process for the
first two states; Python's bytecode caches are written (as after ``pip install``: the
PYTHONDONTWRITEBYTECODE variable is removed).  Goals: the 12-link chain warm 0.15 s and from
an empty cache 0.5 s (item 8); the 200-link chain's first run at most 3 s and 200 MB, growing
linearly with N (item 3).
"""
from __future__ import annotations

import argparse
import os
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def env(cache):
    e = dict(os.environ)
    e.pop("PYTHONDONTWRITEBYTECODE", None)
    e["MECHDSL_CACHE"] = str(cache)
    e["PYTHONPATH"] = str(ROOT / "src") + os.pathsep + e.get("PYTHONPATH", "")
    return e


def process(args, cache, python=False) -> tuple[float, float]:
    """(CPU seconds, peak MB) of one process and the processes it waited for (``python``: the
    interpreter with ``args``, else ``python -m mechdsl args``)."""
    p = subprocess.Popen([sys.executable, *([] if python else ["-m", "mechdsl"]), *args], cwd=ROOT, env=env(cache),
                         stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    _, status, ru = os.wait4(p.pid, 0)
    err = p.stderr.read().decode(errors="replace")
    p.stderr.close()
    p.returncode = os.waitstatus_to_exitcode(status)
    if p.returncode != 0:
        raise RuntimeError(f"mech {' '.join(args)} failed ({p.returncode}): {err[-800:]}")
    return ru.ru_utime + ru.ru_stime, ru.ru_maxrss / 1024


def chain_args(n):
    return ["simulate", "models/nlink_pendulum.mech", "--set", f"N={n}", "--t-end", "5", "--no-progress"]


def measure(n, runs) -> dict:
    out = {}
    empty, new, warm, third, normal, bare, numpy = [], [], [], [], [], [], []
    for _ in range(runs):
        bare.append(process(["-c", "pass"], ROOT, python=True))
        numpy.append(process(["-c", "import numpy"], ROOT, python=True))
        d = Path(tempfile.mkdtemp(prefix="mechdsl-first-"))
        try:
            empty.append(process(chain_args(n), d))
        finally:
            shutil.rmtree(d, ignore_errors=True)
        d = Path(tempfile.mkdtemp(prefix="mechdsl-first-"))
        try:
            process(["simulate", "models/pendulum.mech", "--t-end", "1", "--no-progress"], d)   # builds the runtime
            new.append(process(chain_args(n), d))
            warm.append(process(chain_args(n), d))
            third.append(process(chain_args(n), d))
            shutil.rmtree(d / "runs", ignore_errors=True)
            normal.append(process(chain_args(n), d))
        finally:
            shutil.rmtree(d, ignore_errors=True)
    for key, vals in (("empty", empty), ("new model", new), ("warm", warm), ("third", third),
                      ("model cache", normal), ("python", bare), ("numpy", numpy)):
        out[key] = (min(v[0] for v in vals), max(v[1] for v in vals))
    return out


def table(sizes, runs) -> str:
    lines = [f"`benchmarks/first_run.py` (least of {runs} processes; CPU = user + system of the process and the "
             "compilers it ran; peak = largest resident size)", "",
             "| chain | empty cache: CPU s | peak MB | new model: CPU s | peak MB | warm: CPU s | peak MB "
             "| third run: CPU s | peak MB | model cache: CPU s | peak MB | `python -c pass`: CPU s "
             "| `import numpy`: CPU s | warm / model cache | warm / python |",
             "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|"]
    for n in sizes:
        m = measure(n, runs)
        lines.append(f"| N = {n} | " + " | ".join(f"{m[k][0]:.2f} | {m[k][1]:.0f}" for k in ("empty", "new model",
                                                                                              "warm", "third",
                                                                                              "model cache"))
                     + f" | {m['python'][0]:.3f} | {m['numpy'][0]:.3f}"
                     + f" | {m['warm'][0] / m['model cache'][0]:.2f} | {m['warm'][0] / m['python'][0]:.1f} |")
    return "\n".join(lines)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", default="12,25,50,100,200")
    ap.add_argument("--runs", type=int, default=3)
    a = ap.parse_args(argv)
    print(table([int(s) for s in a.sizes.split(",")], a.runs))


if __name__ == "__main__":
    main()
