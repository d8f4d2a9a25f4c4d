"""method = auto against every method, tolerance by tolerance (issue 24, item 1).

    PYTHONPATH=src python benchmarks/auto_wp.py [--quick] [--repeats K] [--models dp,n5,n30]

For each model (double pendulum Chaos, 10 s; the N-link chain at N = 5 and 30, 5 s) one
``mech bench`` sweep (mechdsl.bench.run_bench: CPU time = time.process_time of a whole
``simulate`` call, minimum of K runs after a warm-up; error at the final time against a
reference two decades tighter) of ``auto`` and the methods mechdsl offers for a non-stiff
model: the stepping loop's ``dop853`` and ``dopri5`` (compiled), ``erk``, ``cvodes-adams``,
``cvodes-bdf``, ``scipy-dop853``, ``scipy-lsoda``.  Printed per tolerance:

- ``auto`` CPU, the method it ran, its final-time error;
- the repeats of all methods at one tolerance are interleaved (run_bench: round-robin, the
  order reversed every other round), so a change of the machine's load hits them alike, and a
  fast run is repeated until its timed runs add up to MIN_TOTAL (the minimum of five 1 ms
  runs on a loaded machine was 30 % off);
- ``best same tol``: the cheapest other method at that tolerance and auto / it;
- ``best as accurate``: the cheapest run of any other method (any tolerance) whose error is at
  most auto's, and auto / it (the work-precision reading: goal at most 1.2);
- ``x ran``: auto / the method it ran, run by name at the same tolerance (the same steps:
  auto's own overhead plus the timing noise);
- ``monotone``: auto's CPU at this tolerance / its CPU at the next tighter one (goal <= 1,
  a loosened tolerance never costs more; above 1 within the timing noise: see the repeated
  runs' spread in ``noise``, the ratio of the second-best to the best repeat of auto).
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "src"))

import mechdsl  # noqa: E402
from mechdsl.bench import Setup, parse_tolerances, parse_variants, run_bench  # noqa: E402

MIN_TOTAL = 0.05      # CPU s: a row's timed runs add up to at least this (a 1 ms run is timed about 50 times)
METHODS = "auto,dop853,dopri5,erk,cvodes-adams,cvodes-bdf,scipy-dop853,scipy-lsoda"
MODELS = {"dp": ("double pendulum (Chaos), 10 s", "models/double_pendulum.mech", dict(scene="Chaos"), {}, 10.0),
          "n5": ("5-link chain, 5 s", "models/nlink_pendulum.mech", {}, {"N": 5}, 5.0),
          "n30": ("30-link chain, 5 s", "models/nlink_pendulum.mech", {}, {"N": 30}, 5.0)}


def sweep(key, tolerances, repeats, log=None):
    title, path, kw, params, t_end = MODELS[key]
    m = mechdsl.load(str(ROOT / path), **kw)
    if params:
        m = m.with_params(**params)
    st = Setup.from_model(m, t_end=t_end, points=101, source=path)
    return title, run_bench(st, variants=parse_variants(METHODS), tolerances=parse_tolerances(tolerances),
                            repeats=repeats, budget=20.0, min_total=MIN_TOTAL, log=log)


def table(title, res) -> tuple[str, dict]:
    rows = [r for r in res.rows if r.ok]
    auto = {r.tolerance: r for r in rows if r.label == "auto"}
    others = [r for r in rows if r.label != "auto"]
    tols = sorted(auto, reverse=True)
    out = [f"{title}: CPU ms (min of at least {res.repeats} runs after a warm-up, interleaved across the methods, "
           f"more until a row's runs add up to {MIN_TOTAL * 1e3:g} ms), error = relative error of the coordinates at "
           "the final time",
           f"{'tol':>7} {'auto ms':>8} {'ran':>7} {'error':>8} | {'best same tol':>22} {'x':>5} | "
           f"{'best as accurate':>30} {'x':>5} | {'monotone':>8} | {'x ran':>5}"]
    worst = {"same": 0.0, "accurate": 0.0, "monotone": 0.0, "ran": 0.0}
    for i, tol in enumerate(tols):
        a = auto[tol]
        same = min((r for r in others if r.tolerance == tol), key=lambda r: r.cpu, default=None)
        acc = min((r for r in others if r.err_final <= a.err_final), key=lambda r: r.cpu, default=None)
        tighter = auto.get(tols[i + 1]) if i + 1 < len(tols) else None
        mono = a.cpu / tighter.cpu if tighter else None
        x_same = a.cpu / same.cpu if same else None
        x_acc = a.cpu / acc.cpu if acc else None
        twin = next((r for r in others if r.tolerance == tol and r.label == a.ran), None)
        x_ran = a.cpu / twin.cpu if twin else None
        for k, v in (("same", x_same), ("accurate", x_acc), ("monotone", mono), ("ran", x_ran)):
            if v is not None:
                worst[k] = max(worst[k], v)
        ran = a.ran or "?"
        out.append(f"{tol:7.0e} {a.cpu * 1e3:8.2f} {ran:>7} {a.err_final:8.1e} | "
                   + (f"{same.label:>12} {same.cpu * 1e3:7.2f} ms {x_same:5.2f}" if same else f"{'-':>22} {'':>5}")
                   + " | "
                   + (f"{acc.label:>12} {acc.tolerance:.0e} {acc.cpu * 1e3:7.2f} ms {x_acc:5.2f}" if acc
                      else f"{'none as accurate':>30} {'':>5}")
                   + " | " + (f"{mono:8.2f}" if mono is not None else f"{'-':>8}")
                   + " | " + (f"{x_ran:5.2f}" if x_ran is not None else f"{'-':>5}"))
    out.append(f"worst: auto / best at the same tolerance {worst['same']:.2f}, auto / best as accurate "
               f"{worst['accurate']:.2f} (goal <= 1.2), loosening the tolerance costs at most x{worst['monotone']:.2f}; "
               f"auto / the same method run by name at the same tolerance at most {worst['ran']:.2f} (its overhead and "
               "the timing noise)")
    return "\n".join(out), worst


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="three tolerances, one repeat (a smoke test)")
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--models", default="dp,n5,n30")
    a = ap.parse_args(argv)
    tol = "1e-3..1e-9/1" if a.quick else "1e-2..1e-12/1"
    reps = 1 if a.quick else a.repeats
    for key in a.models.split(","):
        title, res = sweep(key, tol, reps, log=lambda s: print("   " + s, file=sys.stderr, flush=True))
        print(table(title, res)[0], "\n", flush=True)


if __name__ == "__main__":
    main()
