"""What preparing a problem once saves (issue 22): N runs of one model at other parameter
values, each a direct run (``solve(formulate(eom, settings at the values))``: method auto chosen
from the start's Jacobian, Functions looked up, integrator options built) against the runs of
one ``prepare(problem)`` at the values (``solve(prep.at(p=...))``).  Same numbers (asserted);
CPU time per run, minimum of repeats, side by side in one process.

    PYTHONPATH=src python benchmarks/prepared.py [--runs 20] [--repeats 3]
"""
from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

import mechdsl
from mechdsl.simulation import formulate, solve
from mechdsl.simulation.prepared import prepare

MODELS = Path(__file__).resolve().parent.parent / "models"


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--runs", type=int, default=20)
    ap.add_argument("--repeats", type=int, default=3)
    args = ap.parse_args()
    print(f"{'model':18} {'direct ms/run':>14} {'prepared ms/run':>16} {'ratio':>7}")
    for file, name, span in (("double_pendulum.mech", "l", 1.0), ("nlink_pendulum.mech", "g", 0.5)):
        m = mechdsl.load(MODELS / file)
        settings = m.settings(t_end=span, points=51, compiled=False)
        values = [{name: float(v)} for v in np.linspace(0.8, 1.2, args.runs) * m.parameters[name]]
        prep = prepare(formulate(m.eom, settings))
        solve(prep)                                             # warm: integrator built, caches filled
        direct_s = settings                                     # auto: chosen again by every direct run
        best = {}
        for how in ("direct", "prepared"):
            times = []
            for _ in range(args.repeats):
                t0 = time.process_time()
                for p in values:
                    if how == "direct":
                        solve(formulate(m.eom, direct_s.replace(p=p)))
                    else:
                        solve(prep.at(p=p))
                times.append((time.process_time() - t0) / len(values))
            best[how] = min(times)
        a = solve(formulate(m.eom, direct_s.replace(p=values[0])))
        b = solve(prep.at(p=values[0]))
        assert a.metadata["method"] == b.metadata["method"] and np.array_equal(a.q, b.q)
        print(f"{m.name:18} {best['direct'] * 1e3:14.2f} {best['prepared'] * 1e3:16.2f} "
              f"{best['direct'] / best['prepared']:7.2f}")


if __name__ == "__main__":
    main()
