"""CPU time and size of `mech view models/arm7.mech -o arm.html` (a seven-joint arm, 10 s at
30 frames a second: 301 frames), the goals being under 5 s of CPU and under 5 MB (issue 26).

    python benchmarks/view.py            # one line per phase, then the whole command

CPU time (process_time), not wall time: the machine is shared.  The whole command is timed as
a child process (user + sys of the child, Python's start-up and imports included), once with an
empty model cache (parse, analyse, derive and compile anew) and once with the cache it left.
"""
from __future__ import annotations

import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
MODEL = ROOT / "models" / "arm7.mech"


def phases() -> None:
    import mechdsl
    from mechdsl.view import view

    t = time.process_time()
    m = mechdsl.load(MODEL)
    m.eom
    t_load = time.process_time() - t
    t = time.process_time()
    r = m.simulate(10.0, points=301)
    t_sim = time.process_time() - t
    t = time.process_time()
    v = view(r, m, fps=30)
    t_scene = time.process_time() - t
    with tempfile.TemporaryDirectory() as d:
        t = time.process_time()
        path = v.save(os.path.join(d, "arm.html"))
        t_write = time.process_time() - t
        size = path.stat().st_size
    data = len(v.data["poses"]) + len(v.data.get("points", ""))
    print(f"load + derive        {t_load:6.2f} s CPU")
    print(f"simulate (301 pts)   {t_sim:6.2f} s CPU")
    print(f"scene data           {t_scene:6.2f} s CPU  ({len(v)} frames, {len(v.data['bodies'])} posed bodies, "
          f"{data / 1e3:.0f} kB of base64 poses and points)")
    print(f"page                 {t_write:6.2f} s CPU  ({size / 1e6:.2f} MB, three.js included)")


def whole_command(cache: str, label: str) -> None:
    env = dict(os.environ, MECHDSL_CACHE=cache)
    with tempfile.TemporaryDirectory() as d:
        out = os.path.join(d, "arm.html")
        before = resource.getrusage(resource.RUSAGE_CHILDREN)
        subprocess.run([sys.executable, "-m", "mechdsl", "view", str(MODEL), "-o", out], check=True,
                       stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, env=env)
        after = resource.getrusage(resource.RUSAGE_CHILDREN)
        size = os.path.getsize(out)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    print(f"whole command, {label:11s} {cpu:6.2f} s CPU, {size / 1e6:.2f} MB  (goals: under 5 s, under 5 MB)")


if __name__ == "__main__":
    phases()
    with tempfile.TemporaryDirectory() as cache:
        whole_command(cache, "cold cache")
        whole_command(cache, "warm cache")
