"""Unrolled against looped forward dynamics of the N-link chain (issue 16).

    PYTHONPATH=src python benchmarks/chain_kernel.py [--sizes 2,12,50,100,200] [--no-unrolled-above N]

For each N (models/nlink_pendulum.mech with N set) the ``ode`` Function (t, x, u, p) -> xdot in
its two forms: *unrolled* (one SX expression, mechanics/dynamics.py) and *looped* (per-link
kernels chained by mapaccum, mechanics/chain.py; none below 4 identical links).  Printed per form:

- C bytes: the generated C of the ode alone (CodeGenerator without comments, as
  ``codegen.compile_functions`` writes it); "code" leaves out the static index tables;
- gcc s: wall time of ``codegen.compile_functions`` for the ode alone (code generation, gcc at
  the flags mechdsl picks by size (``cflags_for``), link), fresh cache;
- compiled us / VM us: one evaluation through ``FastFunction`` (about 0.5 us of Python call
  overhead included), compiled and in CasADi's virtual machine; minimum over repeats;
- and the ratios looped / unrolled side by side.

Timings are minima over repeats (the machine may be shared).  The last line checks the goal of
issue 16: gcc time of the looped form at N = 200 at most 3x that at N = 50.
"""
from __future__ import annotations

import argparse
import os
import re
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "src"))
sys.path.insert(0, str(ROOT / "benchmarks"))

import casadi as ca  # noqa: E402

import mechdsl  # noqa: E402
from mechdsl.bench.report import markdown_table  # noqa: E402
from mechdsl.eom.codegen import FastFunction, build_ode, compile_functions  # noqa: E402
from nlink import fmt, mech_text  # noqa: E402


def c_sizes(f) -> tuple[int, int]:
    cg = ca.CodeGenerator("ode.c", {"with_header": False, "verbose": False})
    cg.add(f)
    code = cg.dump()
    return len(code), len(re.sub(r"static const casadi_(int|real) [^;]*;", "", code, flags=re.S))


def eval_us(f, N, pv, reps) -> float:
    call = FastFunction(f, copy=False).bind(u=np.zeros(0), p=pv)
    x = np.r_[np.linspace(-0.3, 0.4, N), np.linspace(-0.2, 0.3, N)]
    call(0.0, x)
    best = float("inf")
    for _ in range(5):
        t = time.perf_counter()
        for _ in range(reps):
            call(0.0, x)
        best = min(best, (time.perf_counter() - t) / reps)
    return best * 1e6


def measure(f, N, pv, compile_it: bool) -> dict:
    size, code = c_sizes(f)
    row = {"bytes": size, "code": code, "vm": eval_us(f, N, pv, max(50, 20000 // N))}
    if compile_it:
        with tempfile.TemporaryDirectory() as d:
            old = os.environ.get("MECHDSL_CACHE")
            os.environ["MECHDSL_CACHE"] = d
            try:
                t = time.perf_counter()
                loaded, note, _ = compile_functions([f], tag="bench", jacobian=False)
                row["gcc"] = time.perf_counter() - t
            finally:
                if old is None:
                    del os.environ["MECHDSL_CACHE"]
                else:
                    os.environ["MECHDSL_CACHE"] = old
            if loaded is None:
                raise SystemExit(f"compilation failed: {note}")
            row["flags"] = re.search(r"\((-O\d)\)", note).group(1)
            row["comp"] = eval_us(loaded["ode"], N, pv, max(500, 200000 // N))
    return row


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--sizes", default="2,12,50,100,200")
    ap.add_argument("--no-unrolled-above", type=int, default=None,
                    help="do not compile the unrolled form above this N (its gcc time: minutes)")
    a = ap.parse_args(argv)
    rows = []
    for N in (int(s) for s in a.sizes.split(",")):
        e = mechdsl.loads(mech_text(N)).eom
        pv = np.asarray(e.param_values, float)
        unrolled = build_ode(e)
        plan = e.qdd_loop
        looped = plan.ode(e) if plan is not None else None
        if looped is not None:
            x = np.r_[np.linspace(-0.3, 0.4, N), np.linspace(-0.2, 0.3, N)]
            a1, b1 = np.array(looped(0, x, [], pv)).ravel(), np.array(unrolled(0, x, [], pv)).ravel()
            err = float(np.max(np.abs(a1 - b1)) / max(1.0, np.max(np.abs(b1))))
        else:
            err = None
        skip = a.no_unrolled_above is not None and N > a.no_unrolled_above
        u = measure(unrolled, N, pv, not skip)
        lo = measure(looped, N, pv, True) if looped is not None else {}
        rows.append({"N": N, "u": u, "l": lo, "err": err, "ops": unrolled.n_instructions()})
        print(f"# N={N} done", file=sys.stderr, flush=True)

    def ratio(r, k):
        a_, b_ = r["l"].get(k), r["u"].get(k)
        return None if a_ is None or b_ is None else a_ / b_

    head = ["N", "unrolled SX ops", "C bytes unrolled / looped (code)", "gcc s unrolled / looped (flags)",
            "ratio gcc", "compiled us unrolled / looped", "ratio compiled", "VM us unrolled / looped", "ratio VM",
            "looped - unrolled"]
    body = []
    for r in rows:
        u, lo = r["u"], r["l"]
        flags = "/".join(x for x in (u.get("flags"), lo.get("flags")) if x)
        body.append([r["N"], r["ops"], f"{u['bytes']} / {fmt(lo.get('bytes'), 'd')} ({fmt(lo.get('code'), 'd')})",
                     f"{fmt(u.get('gcc'), '.2f')} / {fmt(lo.get('gcc'), '.2f')} ({flags})", fmt(ratio(r, "gcc"), ".2f"),
                     f"{fmt(u.get('comp'), '.3g')} / {fmt(lo.get('comp'), '.3g')}", fmt(ratio(r, "comp"), ".2f"),
                     f"{u['vm']:.3g} / {fmt(lo.get('vm'), '.3g')}", fmt(ratio(r, "vm"), ".1f"), fmt(r["err"], ".1e")])
    print(markdown_table(head, body))
    by = {r["N"]: r for r in rows}
    if 50 in by and 200 in by and by[50]["l"] and by[200]["l"]:
        g50, g200 = by[50]["l"]["gcc"], by[200]["l"]["gcc"]
        verdict = "holds" if g200 <= 3 * g50 else "FAILS"
        print(f"\ngoal gcc(N = 200) <= 3 x gcc(N = 50), looped: {g200:.2f} s / {g50:.2f} s = {g200 / g50:.2f} "
              f"({verdict})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
