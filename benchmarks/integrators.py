"""Work-precision table: every method on the double pendulum (two point masses, 10 s from 90 deg),
or with --model nlink --n N on the N-rod chain of models/nlink_pendulum.mech (recursive route).

Error: max abs error of the state at the final time against a reference computed twice
(scipy DOP853 and CASADI cvodes-adams at rtol = atol = 1e-13; their difference is printed).
Time: minimum wall time of `repeats` runs after a warm-up (SciMLBenchmarks methodology).
A failed run is recorded as a failure.  Run:  PYTHONPATH=src python benchmarks/integrators.py
"""
from __future__ import annotations

import argparse
import os
import sys
import time

import numpy as np

sys.path.insert(0, os.path.dirname(__file__))
from _models import chain  # noqa: E402

from mechdsl.integrators import METHODS  # noqa: E402
from mechdsl.simulate import simulate  # noqa: E402


def main(argv=None):
    ap = argparse.ArgumentParser()
    ap.add_argument("--t-end", type=float, default=10.0)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--tols", default="1e-4,1e-6,1e-8,1e-10,1e-12")
    ap.add_argument("--methods", default=",".join(m for m in ["auto", *METHODS] if m != "cvodes"))
    ap.add_argument("--model", choices=("double", "nlink"), default="double")
    ap.add_argument("--n", type=int, default=10, help="links of the nlink model")
    ap.add_argument("--compiled", action="store_true")
    a = ap.parse_args(argv)
    if a.model == "double":
        e = chain(2)
    else:
        import mechdsl

        path = os.path.join(os.path.dirname(__file__), "..", "models", "nlink_pendulum.mech")
        e = mechdsl.load(path).with_params(N=a.n).eom
    kw = {"compiled": True} if a.compiled else {}
    ref1 = simulate(e, a.t_end, method="scipy-dop853", rtol=1e-13, atol=1e-13, points=2, **kw)
    ref2 = simulate(e, a.t_end, method="erk", rtol=1e-13, atol=1e-13, points=2, **kw)
    xr1 = np.r_[ref1.q[-1], ref1.qd[-1]]
    xr2 = np.r_[ref2.q[-1], ref2.qd[-1]]
    ref = xr1
    print(f"{e.name} ({e.n} coordinates), t_end = {a.t_end}{', compiled' if a.compiled else ''}; "
          f"reference disagreement (scipy DOP853 vs erk at 1e-13): "
          f"{np.abs(xr1 - xr2).max():.2e}")
    tols = [float(s) for s in a.tols.split(",")]
    print(f"{'method':14s} " + " ".join(f"{'rtol=' + format(tol, 'g'):>24s}" for tol in tols))
    print(f"{'':14s} " + " ".join(f"{'error':>11s} {'time [ms]':>12s}" for _ in tols))
    for m in a.methods.split(","):
        cells = []
        for tol in tols:
            best = None
            res = None
            try:
                simulate(e, a.t_end, method=m, rtol=tol, atol=tol, points=2, **kw)  # warm-up
                for _ in range(a.repeats):
                    t0 = time.perf_counter()
                    res = simulate(e, a.t_end, method=m, rtol=tol, atol=tol, points=2, **kw)
                    dt = time.perf_counter() - t0
                    best = dt if best is None else min(best, dt)
            except Exception as ex:  # noqa: BLE001
                cells.append(f"{'error: ' + type(ex).__name__:>24s}")
                continue
            if not res.success:
                cells.append(f"{'failed: ' + res.failure.cause[:14]:>24s}")
                continue
            err = np.abs(np.r_[res.q[-1], res.qd[-1]] - ref).max()
            cells.append(f"{err:11.2e} {best * 1e3:12.2f}")
        print(f"{m:14s} " + " ".join(cells), flush=True)


if __name__ == "__main__":
    main()
