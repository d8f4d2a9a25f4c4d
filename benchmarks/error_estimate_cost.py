"""What the default error estimate costs (issue 23): every scene of the shipped models (a model
without scenes: its default run of 10 s), each run warm, side by side in one process:

  off    CPU of Model.simulate with error_estimate="off" (minimum of --repeat runs)
  on     CPU of Model.simulate with the default estimate (the companion run included)
  ratio  on / off: what a run costs with its estimate
  estimate, x tol  the estimate and its ratio to the tolerance class; "warns" when the run warns
  cli off/on  with --cli: CPU of the whole `mech simulate` command (a new process: start-up,
              the model cache, the run, the summary), --error-estimate off against the default

Usage:  PYTHONPATH=src python benchmarks/error_estimate_cost.py [--repeat 3] [--only NAME] [--cli]
The table goes into docs/simulate.md ("The error estimate").
"""
from __future__ import annotations

import argparse
import statistics
import time
import warnings
from pathlib import Path

import mechdsl

MODELS = Path(__file__).resolve().parent.parent / "models"
SKIP = {"nfourbar.mech:NFourBar", "nlink_pendulum.mech:NLinkPendulum"}   # parts of scenes listed separately


def targets():
    """(label, file, scene or None, model or None) for every scene, and every model no scene uses."""
    out = []
    for path in sorted(MODELS.glob("*.mech")):
        text = path.read_text()
        scenes = [line.split()[1] for line in text.splitlines() if line.startswith("scene ")]
        models = [line.split()[1] for line in text.splitlines() if line.startswith("model ")]
        used = set()
        for sc in scenes:
            out.append((f"{path.stem}:{sc}", path, sc, None))
            used |= {m for m in models if f"model {m}" in _scene_text(text, sc)}
        for m in models:
            if m not in used and f"{path.name}:{m}" not in SKIP:
                out.append((f"{path.stem}:{m}", path, None, m))
    return out


def _scene_text(text: str, scene: str) -> str:
    start = text.index(f"scene {scene}")
    return text[start:text.index(f"end {scene};", start)]


def cpu(fn, repeat: int) -> tuple[float, object]:
    times, r = [], None
    for _ in range(repeat):
        t0 = time.process_time()
        r = fn()
        times.append(time.process_time() - t0)
    return min(times), r


def cli_cpu(path, scene, model, t_end, estimate: str, repeat: int) -> float:
    """Child CPU [s] of `mech simulate` (minimum of repeat), the model cache warm."""
    import resource
    import subprocess
    import sys

    cmd = [sys.executable, "-m", "mechdsl", "simulate", str(path), "--no-progress", "--error-estimate", estimate]
    cmd += ["--scene", scene] if scene else ["--model", model]
    if t_end is not None:
        cmd += ["--t-end", str(t_end)]
    best = float("inf")
    for _ in range(repeat + 1):             # the first fills the model cache
        before = resource.getrusage(resource.RUSAGE_CHILDREN)
        subprocess.run(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, check=False)
        after = resource.getrusage(resource.RUSAGE_CHILDREN)
        best = min(best, after.ru_utime - before.ru_utime + after.ru_stime - before.ru_stime)
    return best


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--only", default=None, help="run only targets whose label contains this")
    ap.add_argument("--cli", action="store_true", help="also time the whole `mech simulate` command")
    args = ap.parse_args()
    warnings.simplefilter("ignore")
    rows = []
    print(f"{'run':38s} {'off [s]':>9s} {'on [s]':>9s} {'ratio':>6s} {'estimate':>9s} {'x tol':>9s} {'warns':>5s}"
          + (f" {'cli off':>8s} {'cli on':>8s}" if args.cli else ""))
    for label, path, scene, model in targets():
        if args.only and args.only not in label:
            continue
        m = mechdsl.load(path, scene=scene, model=model)
        t_end = None if scene is not None and m.scene_settings.get("stop_time") is not None else 10.0
        try:
            m.simulate(t_end, error_estimate="off")                   # warm: derivation, compilation
            m.simulate(t_end)
            off, _ = cpu(lambda: m.simulate(t_end, error_estimate="off"), args.repeat)
            on, r = cpu(lambda: m.simulate(t_end), args.repeat)
        except Exception as e:  # noqa: BLE001 - a model that does not run here: say so
            print(f"{label:38s} {'(' + type(e).__name__ + ')':>9s}")
            continue
        acc = r.metadata.get("accuracy") or {}
        est, ratio = acc.get("error_estimate"), acc.get("error_estimate_ratio")
        cli = ""
        if args.cli:
            c_off = cli_cpu(path, scene, model, t_end, "off", args.repeat)
            c_on = cli_cpu(path, scene, model, t_end, "on", args.repeat)
            cli = f" {c_off:8.3f} {c_on:8.3f}"
            rows.append((label, off, on, c_off, c_on))
        else:
            rows.append((label, off, on))
        print(f"{label:38s} {off:9.4f} {on:9.4f} {on / off:6.2f} "
              f"{'-' if est is None else f'{est:9.2g}':>9s} {'-' if ratio is None else f'{ratio:9.2g}':>9s} "
              f"{'yes' if acc.get('warning') else '':>5s}{cli}"
              + ("" if est is not None else f"  ({acc.get('error_estimate_unavailable')})"), flush=True)
    if rows:
        ratios = [row[2] / row[1] for row in rows]
        print(f"\n{len(rows)} runs: on/off median {statistics.median(ratios):.2f}, "
              f"max {max(ratios):.2f}; total CPU off {sum(r[1] for r in rows):.3f} s, on {sum(r[2] for r in rows):.3f} s")
        if args.cli:
            cl = [r[4] / r[3] for r in rows]
            print(f"the whole command: on/off median {statistics.median(cl):.2f}, max {max(cl):.2f}; total CPU "
                  f"off {sum(r[3] for r in rows):.2f} s, on {sum(r[4] for r in rows):.2f} s")


if __name__ == "__main__":
    main()
