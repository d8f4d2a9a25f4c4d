"""CPU time of `mech animate models/double_pendulum.mech -o dp.gif` (20 s at 30 fps: 601
frames), the goal being under 10 s of CPU, split into its phases.

    python benchmarks/animate.py            # prints one line per phase and the total

CPU time (process_time), not wall time: the machine is shared.  The whole command is also
timed as a child process (user + sys of the child), which includes Python's start-up and
imports.
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


def phases() -> None:
    import mechdsl
    from mechdsl.animate import animate

    t = time.process_time()
    m = mechdsl.load(ROOT / "models" / "double_pendulum.mech")
    m.eom
    t_load = time.process_time() - t
    t = time.process_time()
    r = m.simulate(20.0, points=601)
    t_sim = time.process_time() - t
    t = time.process_time()
    anim = animate(r, m, fps=30)
    t_geo = time.process_time() - t
    with tempfile.TemporaryDirectory() as d:
        t = time.process_time()
        anim.save(os.path.join(d, "dp.gif"))
        t_write = time.process_time() - t
        size = os.path.getsize(os.path.join(d, "dp.gif"))
    print(f"load + derive      {t_load:6.2f} s CPU")
    print(f"simulate (601 pts) {t_sim:6.2f} s CPU")
    print(f"geometry + stage   {t_geo:6.2f} s CPU  ({len(anim)} frames, view {anim.view})")
    print(f"render + GIF       {t_write:6.2f} s CPU  ({1000 * t_write / len(anim):.1f} ms a frame, {size / 1e6:.2f} MB)")


def whole_command() -> None:
    with tempfile.TemporaryDirectory() as d:
        before = resource.getrusage(resource.RUSAGE_CHILDREN)
        subprocess.run([sys.executable, "-m", "mechdsl", "animate", str(ROOT / "models" / "double_pendulum.mech"),
                        "-o", os.path.join(d, "dp.gif")], check=True, stdout=subprocess.DEVNULL)
        after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    print(f"whole command      {cpu:6.2f} s CPU  (goal: under 10 s)")


if __name__ == "__main__":
    phases()
    whole_command()
