"""Contact scenes across tolerances (issue 24, item 4): cost and events monotone in the tolerance.

    PYTHONPATH=src python benchmarks/contacts_tolerance.py [--repeats K] [--quick]

For the shipped contact scenes, a run at rtol = atol = each tolerance (scene settings
otherwise, method auto): CPU time (time.process_time of the whole ``simulate`` call, minimum
of K runs after a warm-up), the number of events, and the energy ledger: the kinetic energy
the events' table says the impacts took against what the run lost (E(0) - E(end)).  Before
resting contact was recognized at the run's tolerance the falling rod at 1e-6 took 4606 events
and 16-140 s, and at 1e-4 the table's losses exceeded the energy available.  Beside the default
run (which carries the error estimate), the same run with ``error_estimate="off"`` (its base
cost) and the estimate the default run reports (its ratio to the tolerance class; "none" when it
has none): before the companion followed the run's own impacts, runs with more than 20 events
had no estimate and the loose runs paid a companion the tight ones did not.
"""
from __future__ import annotations

import argparse
import math
import sys
import time
import warnings
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "src"))

import mechdsl  # noqa: E402

SCENES = [("falling_rod.mech", "Drop"), ("bouncing_ball.mech", "Bounce"), ("newtons_cradle.mech", "Cradle5"),
          ("pendulum_wall.mech", "Knock")]


GOAL = 1.2          # issue 24 item 4 (as item 1): a row costs at most this times the cheapest tighter row


ROUND = 0.25        # s: a scene whose runs are shorter gets proportionally more rounds


def measure(runs, repeats):
    """CPU seconds (time.process_time: every thread of the process) of each of ``runs`` (callables),
    the minimum of at least ``repeats`` rounds after a warm-up (more for short runs: ``repeats``
    times ROUND over the median warm-up, so a 9 ms scene is not judged on eight samples of a
    loaded machine); the rounds go through all runs in turn, so a burst of load on the shared
    machine falls on one round of every run, not on every round of one.  Returns the minima, the
    runs' results and the number of rounds."""
    outs, warm = [], []
    for fn in runs:
        c = time.process_time()
        outs.append(fn())
        warm.append(time.process_time() - c)
    typical = sorted(warm)[len(warm) // 2]        # the median: the first run also builds the model's code
    rounds = repeats * max(1, math.ceil(ROUND / max(typical, 1e-3)))
    best = [float("inf")] * len(runs)
    for _ in range(rounds):
        for i, fn in enumerate(runs):
            c = time.process_time()
            fn()
            best[i] = min(best[i], time.process_time() - c)
    return best, outs, rounds


def criterion(tolerances, costs, events):
    """Per row, its cost over the cheapest cost among the tighter rows (None for the tightest), the
    largest of those ratios, and whether the events never decrease as the tolerance tightens."""
    order = sorted(range(len(tolerances)), key=lambda i: -tolerances[i])      # loose -> tight
    ratios = [None] * len(tolerances)
    for pos, i in enumerate(order):
        tighter = [costs[j] for j in order[pos + 1:]]
        if tighter:
            ratios[i] = costs[i] / min(tighter)
    ev = [events[i] for i in order]
    monotone = all(a <= b for a, b in zip(ev, ev[1:]))
    return ratios, max((r for r in ratios if r is not None), default=0.0), monotone


def table(tolerances, repeats) -> str:
    lines = [f"`benchmarks/contacts_tolerance.py`: CPU ms = minimum of at least {repeats} rounds after a warm-up "
             f"(each round runs every tolerance of a scene in turn; {repeats} x {ROUND:g} s / the median warm-up run "
             "when more), of the default run (with its error estimate) and of the run "
             "with error_estimate = off; / tighter = the row's CPU over the cheapest CPU among the tighter rows "
             f"(goal: at most {GOAL}); estimate = the default run's error estimate (ratio to its tolerance class); "
             "loss = the events' kinetic energy changes summed; lost = E(0) - E(end) of the run",
             "", "| scene | tolerance | CPU ms | / tighter | CPU ms, estimate off | / tighter | events | "
             "estimate (ratio) | loss J | lost J | E(0) J |",
             "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|"]
    verdicts = []
    for path, scene in SCENES:
        m = mechdsl.load(str(ROOT / "models" / path), scene=scene)

        def run(tol, **kw):
            def go():
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore", mechdsl.MechWarning)
                    return m.simulate(rtol=tol, atol=tol, **kw)
            return go

        runs = [run(tol) for tol in tolerances] + [run(tol, error_estimate="off") for tol in tolerances]
        best, outs, rounds = measure(runs, repeats)
        k = len(tolerances)
        res, cost, cost_off = outs[:k], best[:k], best[k:]
        events = [len(r.events) for r in res]
        ratio, worst, monotone = criterion(tolerances, cost, events)
        ratio_off, worst_off, _ = criterion(tolerances, cost_off, events)
        name = f"{path.split('.')[0]} {scene}"
        for tol, c, c_off, q, q_off, r in zip(tolerances, cost, cost_off, ratio, ratio_off, res):
            E = r["energy"]
            loss = -sum(e["energy_change"] for e in r.events)
            acc = r.metadata.get("accuracy", {})
            est = ("none" if acc.get("error_estimate") is None
                   else f"{acc['error_estimate']:.2g} ({acc['error_estimate_ratio']:.2g})")
            ok = "" if r.success else f" (failed at t = {r.failure.time:.4g}: {r.failure.cause})"
            fq = "-" if q is None else f"{q:.2f}"
            fq_off = "-" if q_off is None else f"{q_off:.2f}"
            lines.append(f"| {name} | {tol:.0e} | {1e3 * c:.1f}{ok} | {fq} | {1e3 * c_off:.1f} | {fq_off} | "
                         f"{len(r.events)} | {est} | {loss:.4f} | {E[0] - E[-1]:.4f} | {E[0]:.4f} |")
        met = worst <= GOAL and monotone
        verdicts.append(f"goal (issue 24 item 4) {name}: largest CPU / cheapest tighter row {worst:.2f} "
                        f"(estimate off {worst_off:.2f}; goal <= {GOAL}), events "
                        f"{'monotone' if monotone else 'NOT monotone'} in the tolerance "
                        f"({', '.join(str(e) for e in events)}): {'met' if met else 'NOT met'} (minimum of {rounds} rounds)")
    return "\n".join(lines + [""] + verdicts)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--quick", action="store_true")
    a = ap.parse_args(argv)
    tols = [1e-4, 1e-8] if a.quick else [1e-3, 1e-4, 1e-5, 1e-6, 1e-7, 1e-8, 1e-10]
    print(table(tols, 1 if a.quick else a.repeats))


if __name__ == "__main__":
    main()
