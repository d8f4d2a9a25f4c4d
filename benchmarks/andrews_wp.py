"""Work-precision of the DAE formulations on Andrews' squeezing mechanism.

    PYTHONPATH=src python benchmarks/andrews_wp.py OUT [--repeats 3] [--quick]

For each formulation (projection, ggl, baumgarte, partitioning) and rtol = atol from 1e-3
to 1e-10 in half decades: the error is the largest relative error of the seven positions
at t = 0.03 against the IVP Test Set reference (tests/references, copied from ../shared/references); the time is the
CPU time of the integration (setup and integrator construction excluded), the minimum
over `repeats` runs after one warm-up run.  A failed run is shown as a failure.

A last line, "idas index-3", hands the plain index-3 form straight to CasADi's IDAS with
the index guard bypassed, to show what the guard prevents.

Writes OUT.png and OUT.svg (log-log error against CPU time, one line per formulation,
failures marked with x at the top) and prints the table.
"""
from __future__ import annotations

import argparse
import json
import sys
import time
import warnings
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path[:0] = [str(HERE.parent / "src"), str(HERE.parent / "tests")]

from dae_models import andrews_data, andrews_eom  # noqa: E402
from mechdsl.dae import FORMULATIONS, simulate_dae  # noqa: E402
from mechdsl.output.fileio import atomic_target, commit  # noqa: E402

REF = np.array(andrews_data()["reference_t0.03"][:7])


def rel_error(q):
    return float(np.max(np.abs(np.asarray(q) - REF) / np.abs(REF)))


def run_formulation(formulation, tol):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        r = simulate_dae(andrews_eom(), 0.03, formulation=formulation, rtol=tol, atol=tol, points=2)
    if not r.success:
        return None, r.stats.get("solve_cpu_time", float("nan")), r.message
    return rel_error(r.q[-1]), r.stats["solve_cpu_time"], ""


def run_raw_index3(tol):
    """The plain index-3 form in IDAS, guard bypassed (force): what the guard prevents."""
    import casadi as ca

    from mechdsl.dae.ggl import raw_index3_dae
    from mechdsl.dae.index import guarded_idas
    from mechdsl.dae.constrained_system import ConstrainedSystem

    e = andrews_eom()
    s = ConstrainedSystem.build(e)
    q0, qd0 = e.start()
    a0, lam0 = s.accel(q0, qd0, 0.0)
    opts = {"abstol": tol, "reltol": tol, "calc_ic": False, "init_xdot": list(np.concatenate([qd0, a0])),
            "max_num_steps": 100000, "disable_internal_warnings": True}
    F, index = guarded_idas("raw", raw_index3_dae(s), np.concatenate([q0, qd0]), np.concatenate([a0, lam0]),
                            e.param_values, 0.0, [0.03], opts, force=True)
    c0 = time.process_time()
    try:
        import contextlib
        import io

        with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):
            r = F(x0=np.concatenate([q0, qd0]), z0=np.concatenate([a0, lam0]), p=e.param_values)
    except RuntimeError as ex:
        msg = [ln for ln in str(ex).splitlines() if "returned" in ln]
        return None, time.process_time() - c0, (msg[-1].strip() if msg else "IDAS failed")
    q = np.array(r["xf"], float).ravel()[:7]
    if not np.all(np.isfinite(q)):
        return None, time.process_time() - c0, "non-finite result"
    return rel_error(q), time.process_time() - c0, f"index {index} accepted blindly"


def measure(fn, tol, repeats):
    fn(tol)                                        # warm-up
    best, err, msg = float("inf"), None, ""
    for _ in range(repeats):
        err, t, msg = fn(tol)
        if err is None:
            return None, t, msg
        best = min(best, t)
    return err, best, msg


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("out", help="output path for the chart (OUT.png and OUT.svg are written)")
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--quick", action="store_true", help="three tolerances only (a smoke run)")
    ap.add_argument("--json", help="also write the numbers as JSON to this file")
    args = ap.parse_args(argv)
    tols = [10 ** (-e) for e in np.arange(3.0, 10.01, 0.5)]
    if args.quick:
        tols = [1e-4, 1e-7, 1e-10]
    methods = {f: (lambda tol, f=f: run_formulation(f, tol)) for f in FORMULATIONS}
    methods["idas index-3"] = run_raw_index3
    rows = {name: [] for name in methods}
    print(f"Andrews' squeezer, t = 0.03: max relative position error / CPU seconds "
          f"(min of {args.repeats} after a warm-up)")
    print(f"{'tol':>8} " + " ".join(f"{name:>24}" for name in methods))
    for tol in tols:
        cells = []
        for name, fn in methods.items():
            err, t, msg = measure(fn, tol, args.repeats)
            rows[name].append({"tol": tol, "error": err, "cpu": t, "message": msg})
            cells.append(f"{'FAIL':>11} {t:>11.4f}" if err is None else f"{err:>11.2e} {t:>11.4f}")
        print(f"{tol:>8.1e} " + " ".join(f"{c:>24}" for c in cells), flush=True)
    for name in methods:
        fails = [r for r in rows[name] if r["error"] is None]
        if fails:
            print(f"{name}: {len(fails)} failure(s); e.g. at tol {fails[0]['tol']:.1e}: {fails[0]['message']}")
    plot(rows, args.out)
    if args.json:
        Path(args.json).write_text(json.dumps(rows, indent=1))
    return 0


def plot(rows, out):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7.5, 5.5))
    markers = dict(zip(rows, "osD^v"))
    top = max([r["error"] for rs in rows.values() for r in rs if r["error"] is not None] + [1.0]) * 10
    for name, rs in rows.items():
        ok = [r for r in rs if r["error"] is not None]
        bad = [r for r in rs if r["error"] is None]
        line = None
        if ok:
            (line,) = ax.loglog([r["cpu"] for r in ok], [r["error"] for r in ok], marker=markers[name], label=name)
        if bad:
            ax.scatter([max(r["cpu"], 1e-4) for r in bad], [top] * len(bad), marker="x", s=60,
                       color=line.get_color() if line else None,
                       label=None if ok else f"{name} (failed)")
    ax.axhline(top, color="0.7", lw=0.8, ls=":")
    ax.text(ax.get_xlim()[0], top, " failures", va="bottom", fontsize=8, color="0.4")
    ax.set_xlabel("CPU time of the integration [s] (min over repeats)")
    ax.set_ylabel("max relative error of the positions at t = 0.03")
    ax.set_title("Andrews' squeezing mechanism: work-precision by formulation\n"
                 "rtol = atol from 1e-3 to 1e-10 in half decades")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8)
    base = Path(out)
    base = base.with_suffix("") if base.suffix in (".png", ".svg") else base
    for ext in (".png", ".svg"):
        tmp, final = atomic_target(str(base) + ext)
        fig.savefig(tmp, format=ext[1:], dpi=120, bbox_inches="tight")
        commit(tmp, final)
        print(f"wrote {final}")


if __name__ == "__main__":
    sys.exit(main())
