"""Cost of calling CasADi Functions from Python: plain call vs buffer call vs compiled code.

For the N-link chain (Lagrange route, numeric QR solve of M qdd = bias) this prints, per N,
the time of one `ode` evaluation through
  plain      f(t, x, p)                    (CasADi's Python call: DM conversions)
  fast       codegen.FastFunction          (Function.buffer(), copies in and out)
  bound      FastFunction.bind(u=, p=)      (what the scipy integrators call: rhs(t, x))
  buffer     the bare buffer eval          (lower bound from Python)
  c-plain    compiled library, plain call
  c-fast     compiled library, FastFunction
and the ratios plain/fast and fast/c-fast, all measured in this one run.
Run:  PYTHONPATH=src python benchmarks/calls.py [--sizes 2,5,10]
"""
from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time

import numpy as np

sys.path.insert(0, os.path.dirname(__file__))
from _models import chain  # noqa: E402

from mechdsl.eom.codegen import FastFunction, casadi_functions  # noqa: E402


def per_call(fn, min_time=0.2):
    fn()
    n, t = 1, 0.0
    while True:
        t0 = time.perf_counter()
        for _ in range(n):
            fn()
        t = time.perf_counter() - t0
        if t > min_time:
            return t / n
        n *= 4


def main(argv=None):
    ap = argparse.ArgumentParser()
    ap.add_argument("--sizes", default="1,2,5,10")
    a = ap.parse_args(argv)
    os.environ.setdefault("MECHDSL_CACHE", os.path.join(tempfile.gettempdir(), "mechdsl-bench-cache"))
    print(f"{'N':>3s} {'plain':>9s} {'fast':>9s} {'bound':>9s} {'buffer':>9s} {'c-plain':>9s} {'c-fast':>9s}   "
          f"{'plain/bound':>11s} {'fast/c-fast':>11s}   (microseconds per ode call)")
    for N in [int(s) for s in a.sizes.split(",")]:
        e = chain(N)
        p = e.param_values
        x = np.random.default_rng(0).uniform(-1, 1, 2 * N)
        vm = casadi_functions(e)["ode"]
        cf = casadi_functions(e, compiled=True, names=("ode",))
        cfun = cf["ode"]
        fast = FastFunction(vm)
        raw = FastFunction(vm, copy=False)
        fast.__call__(0.0, x, [], p)
        ev = raw._eval
        cfast = FastFunction(cfun)
        t_plain = per_call(lambda: vm(0.0, x, [], p))
        t_fast = per_call(lambda: fast(0.0, x, [], p))
        bound = FastFunction(vm).bind(u=[], p=p)
        t_bound = per_call(lambda: bound(0.0, x))
        t_buf = per_call(ev)
        t_cplain = per_call(lambda: cfun(0.0, x, [], p))
        t_cfast = per_call(lambda: cfast(0.0, x, [], p))
        tag = "" if cf.compiled else "  (no compiler: c-* are the VM)"
        print(f"{N:3d} {t_plain * 1e6:9.2f} {t_fast * 1e6:9.2f} {t_bound * 1e6:9.2f} {t_buf * 1e6:9.2f} {t_cplain * 1e6:9.2f} "
              f"{t_cfast * 1e6:9.2f}   {t_plain / t_bound:11.1f} {t_fast / t_cfast:11.1f}{tag}", flush=True)


if __name__ == "__main__":
    main()
