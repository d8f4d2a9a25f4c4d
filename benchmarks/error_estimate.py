"""Calibration of the default error estimate (issue 23): on long, chaotic and constrained runs,
how the estimate ``metadata["accuracy"]["error_estimate"]`` compares with the true error.

The true error of a run is the largest |q - q_ref| over its recorded times and coordinates:
  A01      IFToMM A01, the 1 m pendulum released horizontally, 2000 s, in one angle
           (models/pendulum.mech): the exact solution by elliptic functions
  A01-xy   the same pendulum in Cartesian coordinates with the rod as a constraint (DAE,
           models/pendulum_cartesian.mech), 200 s: x = sin(theta), y = -cos(theta) exactly
  double   the double pendulum released from the horizontal (models/double_pendulum.mech),
           chaotic: 5, 10 and 20 s; reference: rtol = atol = 1e-14, accepted only where a second
           reference at 1e-13 agrees to a tenth of the error it judges
  fourbar  models/four_bar.mech, 5 s (DAE, projection); reference at rtol = atol = 1e-13, checked
           against one at 1e-12 the same way
  andrews  Andrews' squeezer (models/andrews.mech, the IVP Test Set), 0.03 s; reference at
           rtol = atol = 1e-12, checked against one at 1e-11 and shown against the Test Set's
           y(0.03) (tests/references: itself good to about 1e-10 relative)
over a range of tolerances (atol = rtol / 100).  A case counts as calibrated when
1/10 <= estimate / true error <= 10; the goal is 95 % of the cases.

Usage:  PYTHONPATH=src python benchmarks/error_estimate.py [--quick] [--tighter K] [--markdown]
--tighter K runs the companion K times tighter (the shipped value: simulation/estimate.py
TIGHTER) to compare choices side by side.  The table goes into docs/performance.md.
"""
from __future__ import annotations

import argparse
import json
import time
import warnings
from pathlib import Path

import numpy as np

import mechdsl
from mechdsl.simulation import estimate as E

ROOT = Path(__file__).resolve().parent.parent
MODELS = ROOT / "models"
REFS = [ROOT / "tests" / "references" / "andrews_squeezer.json", Path("/work/shared/references/andrews_squeezer.json")]


def a01_theta(t, L=1.0, g=9.81, a=np.pi / 2):
    """sin(theta/2) = k sn(K - w t | k^2): released at rest from theta = a."""
    from scipy.special import ellipj, ellipk

    k = np.sin(a / 2)
    sn = ellipj(ellipk(k * k) - np.sqrt(g / L) * np.asarray(t), k * k)[0]
    return 2 * np.arcsin(k * sn)


def run(m, t_end, **kw):
    t0 = time.process_time()
    r = m.simulate(t_end, **kw)
    return r, time.process_time() - t0


def reference(m, t_end, points, tight, check, **kw):
    """(q_ref, its own error bound): the run at ``tight`` and its difference to one at ``check``."""
    a, _ = run(m, t_end, rtol=tight, atol=tight, points=points, error_estimate="off", **kw)
    b, _ = run(m, t_end, rtol=check, atol=check, points=points, error_estimate="off", **kw)
    return a.q, float(np.abs(a.q - b.q).max())


def cases(quick: bool):
    """(family, label, model, t_end, points, rtol, reference q or None, reference error, options)."""
    pend = mechdsl.load(MODELS / "pendulum.mech", model="Pendulum")
    t = np.linspace(0, 2000, 2001)
    ref = a01_theta(t)[:, None]
    for tol in ([1e-6, 1e-8, 1e-10] if quick else [1e-5, 1e-6, 1e-7, 1e-8, 1e-9, 1e-10, 1e-11]):
        yield "A01", f"2000 s", pend, 2000.0, 2001, tol, ref, 0.0, {}
    xy = mechdsl.load(MODELS / "pendulum_cartesian.mech", model="PendulumCartesian")
    t = np.linspace(0, 200, 401)
    th = a01_theta(t)
    ref = np.c_[np.sin(th), -np.cos(th)]
    for tol in ([1e-6, 1e-8] if quick else [1e-5, 1e-6, 1e-7, 1e-8, 1e-9, 1e-10]):
        yield "A01-xy", "200 s (DAE)", xy, 200.0, 401, tol, ref, 0.0, {}
    dp = mechdsl.load(MODELS / "double_pendulum.mech", model="DoublePendulum")
    for T in ([10] if quick else [5, 10, 20]):
        qref, rerr = reference(dp, T, 1001, 1e-14, 1e-13)
        for tol in ([1e-6, 1e-9] if quick else [1e-5, 1e-6, 1e-7, 1e-8, 1e-9, 1e-10]):
            yield "double", f"{T} s (chaotic)", dp, float(T), 1001, tol, qref, rerr, {}
    fb = mechdsl.load(MODELS / "four_bar.mech", scene="Swing")
    qref, rerr = reference(fb, 5.0, 501, 1e-13, 1e-12)
    for tol in ([1e-6, 1e-9] if quick else [1e-5, 1e-6, 1e-7, 1e-8, 1e-9, 1e-10]):
        yield "fourbar", "5 s (DAE)", fb, 5.0, 501, tol, qref, rerr, {}
    an = mechdsl.load(MODELS / "andrews.mech", scene="Squeeze")
    qref, rerr = reference(an, 0.03, 31, 1e-12, 1e-11)
    src = next((p for p in REFS if p.exists()), None)
    if src is not None:        # the reference against the Test Set's y(0.03) (itself good to ~1e-10 relative)
        yref = np.array([float(v) for v in json.loads(src.read_text())["reference_t0.03"][:7]])
        print(f"andrews reference at t = 0.03 against the Test Set: {np.abs(qref[-1] - yref).max():.2e} "
              f"(relative {np.abs((qref[-1] - yref) / yref).max():.1e})")
    for tol in ([1e-6, 1e-8] if quick else [1e-5, 1e-6, 1e-7, 1e-8, 1e-9]):
        yield "andrews", "0.03 s (DAE)", an, 0.03, 31, tol, qref, rerr, {}


def calibrate(quick: bool = False, log=print) -> list[dict]:
    """Every case: true error, estimate, their ratio, the ratio to the tolerance class, whether
    the run warns, and the cost of the run with its estimate over the run alone."""
    rows = []
    warm = set()
    for fam, label, m, t_end, points, tol, qref, rerr, kw in cases(quick):
        if (id(m), tol) not in warm:          # compiled loops, caches: not part of the cost
            warm.add((id(m), tol))
            run(m, min(t_end, 1.0), rtol=tol, atol=tol / 100, points=points, **kw)
        off, c_off = run(m, t_end, rtol=tol, atol=tol / 100, points=points, error_estimate="off", **kw)
        r, c_on = run(m, t_end, rtol=tol, atol=tol / 100, points=points, **kw)
        n = min(len(r.t), len(qref))
        true = float(np.abs(r.q[:n] - qref[:n]).max())
        acc = r.metadata.get("accuracy") or {}
        est = acc.get("error_estimate")
        row = dict(case=fam, run=label, rtol=tol, true=true, estimate=est, cost=c_on / c_off,
                   tol_ratio=acc.get("error_estimate_ratio"), warns=bool(acc.get("warning")))
        if not r.success or est is None or true < 10 * rerr:
            row["skipped"] = ("failed" if not r.success else "no estimate" if est is None else
                              f"reference not accurate enough ({rerr:.1e})")
        else:
            row["ratio"] = est / true
        rows.append(row)
        log(_line(row))
    return rows


def _line(row) -> str:
    head = f"{row['case']:8s} {row['run']:16s} {row['rtol']:7.0e} {row['true']:11.3e}"
    if "skipped" in row:
        return head + f" {'-':>10s}  ({row['skipped']}: not counted)"
    ok = 0.1 <= row["ratio"] <= 10
    return (head + f" {row['estimate']:10.3e} {row['ratio']:7.2f} {row['tol_ratio']:8.2g} "
            f"{'yes' if row['warns'] else '':>5s} {row['cost']:5.2f}" + ("" if ok else "   <- outside [0.1, 10]"))


def summary(rows) -> list[str]:
    counted = [r for r in rows if "ratio" in r]
    inside = sum(1 for r in counted if 0.1 <= r["ratio"] <= 10)
    ratios = [r["ratio"] for r in counted]
    true_x = [r["true"] / (r["estimate"] / r["tol_ratio"]) for r in counted]     # true error / tolerance class
    missed = sum(1 for r, x in zip(counted, true_x) if x > 100 and not r["warns"])
    return [f"{inside} of {len(counted)} cases ({100 * inside / max(len(counted), 1):.0f} %) within a factor 10 of "
            f"the true error; ratio estimate/true: median {np.median(ratios):.2f}, min {min(ratios):.2f}, "
            f"max {max(ratios):.2f}",
            f"runs off by more than 100x their tolerance class without a warning: {missed}"]


def markdown(rows) -> str:
    """The table of docs/performance.md ("The error estimate")."""
    out = ["| case | run | rtol | true error | estimate | estimate / true | x tolerance class | warns | cost |",
           "|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        if "ratio" not in r:
            out.append(f"| {r['case']} | {r['run']} | {r['rtol']:.0e} | {r['true']:.2e} | - | "
                       f"({r['skipped']}) | | | |")
            continue
        out.append(f"| {r['case']} | {r['run']} | {r['rtol']:.0e} | {r['true']:.2e} | {r['estimate']:.2e} | "
                   f"{r['ratio']:.2f} | {r['tol_ratio']:.2g} | {'yes' if r['warns'] else 'no'} | {r['cost']:.2f} |")
    return "\n".join(out) + "\n\n" + "\n".join(f"- {line}" for line in summary(rows)) + "\n"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="fewer tolerances")
    ap.add_argument("--tighter", type=float, default=None, help=f"companion factor (default {E.TIGHTER:g})")
    ap.add_argument("--markdown", action="store_true", help="also print the table as markdown")
    args = ap.parse_args()
    if args.tighter:
        E.TIGHTER = args.tighter
    warnings.simplefilter("ignore")
    print(f"companion {E.TIGHTER:g}x tighter\n")
    print(f"{'case':8s} {'run':16s} {'rtol':>7s} {'true error':>11s} {'estimate':>10s} {'ratio':>7s} "
          f"{'x tol':>8s} {'warns':>5s} {'cost':>5s}")
    rows = calibrate(args.quick)
    print()
    print("\n".join(summary(rows)))
    if args.markdown:
        print()
        print(markdown(rows))


if __name__ == "__main__":
    main()
