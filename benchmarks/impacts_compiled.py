"""Contact stepping in the compiled loop (issue 16) against the Python contact stepper and free flight.

1. The bouncing ball (h = 1 m, e = 0.8, rtol 1e-10, atol 1e-12, 2 output points) run until halfway
   between its 20th and 21st impact: `simulate_with_contacts` with the free flights in the
   compiled loop (default) and all in Python (`compiled=False`), against the same ball's free
   flight without contacts in the ODE simulator's compiled loop (`simulate(..., method="dop853")`,
   a horizon of the same length).  A parabola takes only a handful of dop853 steps, so "equal
   step counts" is per step: wall time / accepted steps, and the ratio of those.
   The free flight with the contact present but never reached (floor 1 km below) is listed too.
2. Every shipped contact scene: wall time compiled / Python and the largest difference of the
   event times and of the states on the output grid.

Times are the best of --repeats warm runs (the first run compiles and is not counted).  Run:

    PYTHONPATH=src python benchmarks/impacts_compiled.py
"""
from __future__ import annotations

import argparse
import os
import sys
import time

import numpy as np

ROOT = os.path.join(os.path.dirname(__file__), "..")
sys.path.insert(0, os.path.join(ROOT, "tests"))

H0, E, G, RTOL, ATOL = 1.0, 0.8, 9.81, 1e-10, 1e-12
SCENES = [("bouncing_ball.mech", "Bounce"), ("bouncing_ball.mech", "BounceElastic"), ("pendulum_wall.mech", "Knock"),
          ("newtons_cradle.mech", "Cradle3"), ("newtons_cradle.mech", "Cradle5"),
          ("newtons_cradle.mech", "Cradle5Simultaneous"), ("falling_rod.mech", "Drop"), ("falling_rod.mech", "Catch"),
          ("particle_on_sphere.mech", "SlideOff")]


def best(call, repeats):
    call()                       # warm: derivation, compilation, caches
    t, out = np.inf, None
    for _ in range(repeats):
        t0 = time.perf_counter()
        out = call()
        t = min(t, time.perf_counter() - t0)
    return t, out


def ball_table(bounces: int, repeats: int) -> list[str]:
    from imp_models import ball, ball_closed_form
    from mechdsl.impacts import simulate_with_contacts
    from mechdsl.simulate import simulate

    times, _ = ball_closed_form(H0, E, G, bounces + 1)
    t_end = 0.5 * (times[bounces - 1] + times[bounces])
    eom, floor = ball(H0, E, G)
    far = ball(H0, E, G)[1]
    import dataclasses

    from mechdsl.model import ir

    far = dataclasses.replace(far, fields=tuple((k, ir.Const(-1000.0)) if k == "offset" else (k, v)
                                                for k, v in far.fields))
    kw = dict(points=2, rtol=RTOL, atol=ATOL)
    rows = []
    runs = [("contacts, compiled loop (default)", lambda: simulate_with_contacts(eom, [floor], t_end, **kw)),
            ("contacts, Python (compiled=False)",
             lambda: simulate_with_contacts(eom, [floor], t_end, compiled=False, **kw)),
            ("free flight, contact never reached, compiled loop",
             lambda: simulate_with_contacts(eom, [far], t_end, **kw)),
            ("free flight without contacts, ODE simulator dop853",
             lambda: simulate(eom, t_end, method="dop853", **kw))]
    res = {}
    c_time = {}
    for name, call in runs:
        t, r = best(call, repeats)
        if "compiled loop" in name:
            c_time[name] = (segment_time(call, repeats), int(r.stats["steps"]))
        steps = int(r.stats["steps"])
        nimp = sum(1 for e in (r.events or []) if e["kind"] == "impact")
        res[name] = (t, steps)
        rows.append((name, nimp, steps, t * 1e3, t / steps * 1e6))
    free_us = rows[-1][4]
    out = [f"Bouncing ball, {bounces} bounces (t_end = {t_end:.4f} s), rtol {RTOL:g}, atol {ATOL:g}, 2 points; "
           f"best of {repeats} warm runs", "",
           "| run | impacts | steps | ms | us per step | per step / free flight's |", "|---|---|---|---|---|---|"]
    for name, nimp, steps, ms, us in rows:
        out.append(f"| {name} | {nimp} | {steps} | {ms:.2f} | {us:.1f} | {us / free_us:.2f} |")
    tc, tp = res[runs[0][0]][0], res[runs[1][0]][0]
    tn, tf = res[runs[2][0]][0], res[runs[3][0]][0]
    out += ["", f"compiled / Python contact stepping: {tc / tp:.2f} ({tp / tc:.1f}x faster). "
            f"Goal (issue 16): within 2x of the free flight at equal step counts. Per step "
            f"{rows[0][4] / free_us:.2f}x, but the free flight's {res[runs[3][0]][1]} steps are mostly its fixed "
            f"cost, which flatters this ratio; whole calls: {tc / tf:.1f}x the ODE simulator's free flight, "
            f"{tc / tn:.1f}x the same contact run whose contact is never reached; "
            f"(contact run - never reached) / impacts = {(tc - tn) / max(rows[0][1], 1) * 1e3:.2f} ms an impact "
            "(Python's decoding of the impact records, its impact law when it handles one, the run's setup)."]
    (cc, sc), (cn, sn) = c_time[runs[0][0]], c_time[runs[2][0]]
    out += ["", "The compiled calls alone (time inside `CompiledFlight.segment`, best of the same runs): "
            f"contact run {cc * 1e6:.0f} us for {sc} steps and {rows[0][1]} impacts ({cc / sc * 1e6:.2f} us a step), "
            f"free flight with the contact never reached {cn * 1e6:.0f} us for {sn} steps "
            f"({cn / sn * 1e6:.2f} us a step): per step {cc / sc / (cn / sn):.2f}x."]
    return out


def segment_time(call, repeats):
    """The least total time a run spends in compiled contact calls (CompiledFlight.segment)."""
    from mechdsl.impacts import compiled

    orig = compiled.CompiledFlight.segment
    spent = [0.0]

    def timed(self, *a, **kw):
        t0 = time.perf_counter()
        try:
            return orig(self, *a, **kw)
        finally:
            spent[0] += time.perf_counter() - t0

    compiled.CompiledFlight.segment = timed
    try:
        best_t = np.inf
        for _ in range(repeats):
            spent[0] = 0.0
            call()
            best_t = min(best_t, spent[0])
    finally:
        compiled.CompiledFlight.segment = orig
    return best_t


def scenes_table(repeats: int) -> list[str]:
    import mechdsl
    from mechdsl.impacts import simulate_with_contacts

    out = ["", "Shipped contact scenes (scene settings): compiled loop against Python contact stepping", "",
           "| scene | events | compiled segments / Python segments | ms compiled | ms Python | ratio | "
           "max event-time difference | max state difference |", "|---|---|---|---|---|---|---|---|"]
    for file, scene in SCENES:
        m = mechdsl.load(os.path.join(ROOT, "models", file), scene=scene)
        s = m.scene_settings
        opts = {k: s[k] for k in ("rest_speed", "impact_order", "points", "rtol", "atol", "method") if k in s}
        tc, c = best(lambda: simulate_with_contacts(m.eom, None, s["stop_time"], **opts), repeats)
        tp, p = best(lambda: simulate_with_contacts(m.eom, None, s["stop_time"], compiled=False, **opts), repeats)
        dt = max((abs(a["time"] - b["time"]) for a, b in zip(c.events, p.events)), default=0.0)
        dx = float(np.max(np.abs(np.hstack([c.q, c.qd]) - np.hstack([p.q, p.qd]))))
        same = len(c.events) == len(p.events)
        out.append(f"| {file[:-5]} {scene} | {len(c.events)}{'' if same else f' (Python {len(p.events)})'} | "
                   f"{c.stats.get('compiled_segments', 0)} / {c.stats.get('python_segments', 0)} | {tc * 1e3:.1f} | "
                   f"{tp * 1e3:.1f} | {tc / tp:.2f} | {dt:.1e} | {dx:.1e} |")
    return out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", default="20", help="numbers of bounces (comma separated)")
    ap.add_argument("--repeats", type=int, default=5)
    a = ap.parse_args(argv)
    lines = []
    for b in a.sizes.split(","):
        lines += ball_table(int(b), a.repeats) + [""]
    lines += scenes_table(max(1, a.repeats // 2))
    print("\n".join(lines))


if __name__ == "__main__":
    main()
