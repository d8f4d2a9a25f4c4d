"""Sweep benchmark (issue 14): the double pendulum's release-angle grid, 10 s, rtol 1e-8.

    python benchmarks/sweep.py [--runs 10000] [--compare 1000] [--points 101] [--repeat 3]

Reports, per run: a hand-written CasADi ``Function.map`` of the same integrator (the floor),
the vectorized sweep on 1 thread and on every core, the processes back end, and a Dask
LocalCluster with 2 workers (bit-identical check against the in-process run, scheduling
overhead per run).  The full --runs sweep runs vectorized on every core.  Every sweep here
is method erk (the mapped CasADi integrator); the default sweep (the stepping loop's ensemble
call) against the map and mujoco.rollout is benchmarks/ensemble.py.
"""
from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

import mechdsl
from mechdsl.simulation import formulate
from mechdsl.simulation.prepared import prepare
from mechdsl.sweep.runs import mapped_integrator, scheme_parameter

MODEL = Path(__file__).resolve().parents[1] / "models" / "double_pendulum.mech"


def grid(n):
    k = int(round(np.sqrt(n)))
    return {"j1.phi": np.linspace(-3, 3, k), "j2.phi": np.linspace(-3, 3, max(1, n // k))}


def hand_map(m, starts, points, threads):
    """The floor: the integrator a single run uses, mapped by hand, called once."""
    s = m.settings(t_end=10.0, rtol=1e-8, method="erk", points=points)
    eom = m.eom
    a, b = np.meshgrid(starts["j1.phi"], starts["j2.phi"], indexing="ij")
    N = a.size
    X0 = np.vstack([a.ravel(), b.ravel(), np.zeros(N), np.zeros(N)])
    P = np.tile(scheme_parameter(m.parameter_values)[:, None], (1, N))
    F = mapped_integrator(prepare(formulate(eom, s)), N, threads)
    t0 = time.perf_counter()
    xf = np.asarray(F(x0=X0, p=P)["xf"])
    return (time.perf_counter() - t0) / N, xf


def timed(m, starts, points, **kw):
    t0 = time.perf_counter()
    ds = m.sweep(starts=starts, t_end=10.0, rtol=1e-8, method="erk", points=points, progress=False, **kw)
    return (time.perf_counter() - t0) / ds.sizes["run"], ds


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--runs", type=int, default=10_000)
    ap.add_argument("--compare", type=int, default=1000)
    ap.add_argument("--points", type=int, default=101)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--full-scheduler", default="vectorized")
    a = ap.parse_args()
    m = mechdsl.load(MODEL, model="DoublePendulum")
    st = grid(a.compare)
    n = len(st["j1.phi"]) * len(st["j2.phi"])
    print(f"double pendulum, 10 s, rtol 1e-8, erk, {a.points} points; comparison sweeps of {n} runs")
    # interleaved, best of 3: the machine is shared, so the load changes between measurements
    h1 = h2 = v1 = v2 = float("inf")
    for _ in range(a.repeat):
        h1 = min(h1, hand_map(m, st, a.points, 1)[0])
        t, d1 = timed(m, st, a.points, workers=1)
        v1 = min(v1, t)
        h2 = min(h2, hand_map(m, st, a.points, 2)[0])
        t, d2 = timed(m, st, a.points, workers=2)
        v2 = min(v2, t)
    print(f"hand-written Function.map: {h1 * 1e3:.3f} ms/run (1 thread), {h2 * 1e3:.3f} ms/run (2 threads)")
    print(f"vectorized sweep:          {v1 * 1e3:.3f} ms/run (1 thread, {v1 / h1:.2f}x the map), "
          f"{v2 * 1e3:.3f} ms/run (2 threads, {v2 / h2:.2f}x the map); speed-up 2 vs 1 thread {v1 / v2:.2f}x")
    p1, dp = timed(m, st, a.points, scheduler="processes")
    print(f"processes (2 workers):     {p1 * 1e3:.3f} ms/run (incl. start of the pool); "
          f"identical: {np.array_equal(dp['j1.phi'].values, d2['j1.phi'].values)}")
    k1, dk = timed(m, st, a.points, scheduler="dask", workers=2)
    same = np.array_equal(dk["j1.phi"].values, d2["j1.phi"].values, equal_nan=True)
    print(f"dask LocalCluster (2):     {k1 * 1e3:.3f} ms/run (incl. cluster start); bit-identical: {same}; "
          f"overhead over processes {(k1 - p1) * 1e3:+.3f} ms/run")
    st = grid(a.runs)
    t0 = time.perf_counter()
    ds = m.sweep(starts=st, t_end=10.0, rtol=1e-8, method="erk", points=a.points, progress=False,
                 scheduler=a.full_scheduler)
    wall = time.perf_counter() - t0
    print(f"full sweep: {ds.attrs['summary']} in {wall:.1f} s ({wall / ds.sizes['run'] * 1e3:.2f} ms/run, "
          f"{ds.attrs['scheduler']}, {ds.attrs['workers']} workers, {ds.attrs['threads']} threads)")


if __name__ == "__main__":
    main()
