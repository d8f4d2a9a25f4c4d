"""Importing a URDF arm (issue 26's goal: a 7-joint arm in under 2 s).

    python benchmarks/import_urdf.py [--runs K]

For the 7-joint arms of example-robot-data (xArm7, Franka Panda, Unitree Z1, TALOS's left arm)
and the UR5 (6 joints), prints per arm:

- ``convert``: CPU time of ``mechdsl.urdf.convert`` in this process (read the URDF, merge fixed
  links, read the meshes' bounding boxes, write the text, and check it with mechdsl's front end),
  the minimum of K runs (default 5) after one warm-up run (imports, the parser's tables);
- ``mesh files``: the mesh files read and their size;
- ``mech import``: CPU time (user + system, children included) of a whole fresh process
  ``python -m mechdsl import ARM.urdf -o ARM.mech --force``, minimum of K, and its wall time;
- ``derive + start check``: CPU time of the first ``mechdsl.loads(text).eom`` and the start check
  (not part of the import; what `mech check` adds).

CPU times, not wall times, are the measure (a shared machine); the goal is read on the
``mech import`` column, which counts everything a user waits for.
"""
from __future__ import annotations

import argparse
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
ARMS = {
    "xarm7": "xarm_description/urdf/xarm7.urdf",
    "panda": "panda_description/urdf/panda.urdf",
    "z1": "z1_description/urdf/z1.urdf",
    "talos_left_arm": "talos_data/robots/talos_left_arm.urdf",
    "ur5": "ur_description/urdf/ur5_robot.urdf",
}


def robots() -> Path:
    import importlib.metadata

    return Path(importlib.metadata.distribution("example-robot-data").locate_file(
        "cmeel.prefix/share/example-robot-data/robots"))


def cpu() -> float:
    return time.process_time()


def child_cpu() -> float:
    r = resource.getrusage(resource.RUSAGE_CHILDREN)
    return r.ru_utime + r.ru_stime


def main() -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--runs", type=int, default=5)
    args = ap.parse_args()
    sys.path.insert(0, str(ROOT / "src"))
    import mechdsl
    from mechdsl.eom.preflight import check_start
    from mechdsl.urdf import convert

    base = robots()
    convert(base / ARMS["ur5"])                         # warm-up: imports and the parser's tables
    print("| arm | joints | convert CPU s (min) | mesh files | mech import CPU s (min) | wall s | "
          "derive + start check CPU s |")
    print("|---|---|---|---|---|---|---|")
    env = dict(os.environ, PYTHONPATH=str(ROOT / "src"))
    for name, rel in ARMS.items():
        path = base / rel
        times = []
        for _ in range(args.runs):
            t0 = cpu()
            imp = convert(path)
            times.append(cpu() - t0)
        meshes = {v.filename for lk in _links(path) for v in lk}
        size = sum(_size(path, f) for f in meshes)
        proc_cpu, walls = [], []
        with tempfile.TemporaryDirectory() as tmp:
            out = Path(tmp) / f"{name}.mech"
            for _ in range(args.runs):
                c0, w0 = child_cpu(), time.perf_counter()
                subprocess.run([sys.executable, "-m", "mechdsl", "import", str(path), "-o", str(out), "--force"],
                               env=env, check=True, capture_output=True)
                proc_cpu.append(child_cpu() - c0)
                walls.append(time.perf_counter() - w0)
        t0 = cpu()
        m = mechdsl.loads(imp.text)
        check_start(m.eom)
        derive = cpu() - t0
        n = sum(len(c) for c in imp.coordinates.values())
        print(f"| {name} | {n} | {min(times):.3f} | {len(meshes)} ({size / 1e6:.1f} MB) | {min(proc_cpu):.2f} | "
              f"{min(walls):.2f} | {derive:.2f} |")
    return 0


def _links(path):
    from mechdsl.urdf import robot, xmltree

    r = robot.read_robot(xmltree.read_bytes(str(path)), str(path))
    return [[v for v in lk.visuals if v.kind == "mesh"] for lk in r.links.values()]


def _size(urdf: Path, filename: str) -> int:
    from mechdsl.urdf.meshes import resolve

    p, _ = resolve(filename, urdf.parent, {})
    return p.stat().st_size if p is not None else 0


if __name__ == "__main__":
    sys.exit(main())
