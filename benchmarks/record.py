"""Cost of recording a trajectory: states at 501 points -> the signals of a Result.

For models/double_pendulum.mech and models/nlink_pendulum.mech with N = 30 this integrates
once, then times ``mechdsl.simulation.monitors.compute_signals`` (the recorder of an unconstrained run:
outputs, energies, invariants, first integrals, singularity monitors) on the 501 recorded
states:
  cold   the first call on a fresh model of that structure (builds the Functions and maps)
  warm   later calls (what every further run of the model pays), median of --repeat
The first-integral search is done before timing (it has its own disk cache and is not
recording).  To compare two versions, run the script under each source tree:
  PYTHONPATH=src python benchmarks/record.py
  PYTHONPATH=/path/to/other/src python benchmarks/record.py
(The script accepts both the current signature and the one before simulation/record.py,
which also took the codegen FunctionSet ``post``.)
"""
from __future__ import annotations

import argparse
import inspect
import statistics
import time
from pathlib import Path

import numpy as np

import mechdsl
from mechdsl.simulation import monitors as S

MODELS = Path(__file__).resolve().parent.parent / "models"
CASES = {"double_pendulum": ("double_pendulum.mech", {}), "chain30": ("nlink_pendulum.mech", {"N": 30})}


def recorder(eom, out_names):
    """A callable (t, X, pv) -> signals, for this source tree's compute_signals."""
    if "post" in inspect.signature(S.compute_signals).parameters:      # before simulation/record.py
        from mechdsl.eom.codegen import casadi_functions

        post = casadi_functions(eom, names=("energy", "outputs", "singularity", "mass_matrix"), outputs=out_names)
        return lambda t, X, pv: S.compute_signals(eom, post, t, X, pv, out_names)
    return lambda t, X, pv: S.compute_signals(eom, t, X, pv, out_names)


def search_integrals(eom, t, X, pv) -> None:
    """Run (or read from its cache) the first-integral search before timing."""
    if hasattr(S, "_integral_search"):
        S._integral_search(eom, pv)
    else:                                                               # before simulation/record.py
        S._first_integrals(eom, t, X, pv)


def measure(case: str, repeat: int) -> dict:
    file, params = CASES[case]
    m = mechdsl.load(MODELS / file)
    if params:
        m = m.with_params(**params)
    r = m.simulate(2.0, points=501)
    X = np.hstack([r.q, r.qd])
    eom = m.eom
    pv = eom.param_values
    out = tuple(eom.outputs)
    search_integrals(eom, r.t, X, pv)
    # cold: a fresh model of the same structure (its own EOM copy and caches)
    fresh = mechdsl.load(MODELS / file)
    fresh = fresh.with_params(**params) if params else fresh
    e2 = fresh.eom
    search_integrals(e2, r.t, X, pv)
    rec = recorder(e2, out)
    t0 = time.perf_counter()
    sig = rec(r.t, X, pv)
    cold = time.perf_counter() - t0
    warm = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        rec(r.t, X, pv)
        warm.append(time.perf_counter() - t0)
    return {"case": case, "n": eom.n, "points": len(r.t), "signals": len(sig),
            "cold_ms": 1e3 * cold, "warm_ms": 1e3 * statistics.median(warm), "warm_min_ms": 1e3 * min(warm)}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=20)
    ap.add_argument("--cases", default=",".join(CASES))
    a = ap.parse_args()
    print(f"{'case':16s} {'n':>3s} {'points':>6s} {'signals':>7s} {'cold ms':>9s} {'warm ms':>9s} {'min ms':>9s}")
    for case in a.cases.split(","):
        d = measure(case, a.repeat)
        print(f"{d['case']:16s} {d['n']:3d} {d['points']:6d} {d['signals']:7d} {d['cold_ms']:9.2f} "
              f"{d['warm_ms']:9.2f} {d['warm_min_ms']:9.2f}")


if __name__ == "__main__":
    main()
