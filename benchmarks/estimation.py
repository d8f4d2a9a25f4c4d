"""The measured goals of issue 28 (sensitivities and fitting), CPU times side by side in one
process, the minimum of repeats of warm calls (a study's second call: the run's Function and
its derivative Functions are reused, simulation/trajectory.cached_trajectory); the first
call, which builds them, is shown too.  "One
simulation" is ``simulate`` of the same run in CasADi's virtual machine (``compiled=False``:
the integrator the derivatives are CasADi's sensitivities of); the table also shows the
ratio to the default ``simulate`` (which may choose a compiled stepping loop):

  adjoint   d/dp of a scalar objective (the integral of the energy over the run, and the last
            mass's position at t_end) with respect to 100 parameters (a chain of 50 masses and
            springs: m1..m50, k1..k50), against one simulation of the same run:   goal <= 5x
  forward   forward sensitivities of every recorded signal on 1,000 points with respect to 5
            parameters of the double pendulum (m1, m2, l1, l2, g), against one simulation
            with the same points and tolerances:                                 goal <= 3x
  fit       a fit of those 5 parameters to 1,000 samples over 2 s of tracked positions (x1,
            y1, x2, y2 with noise 3 mm), started 10-30% off:                      goal < 5 s CPU

    PYTHONPATH=src python benchmarks/estimation.py [--repeats 3]
"""
from __future__ import annotations

import argparse
import time

import numpy as np

import mechdsl

DOUBLE = """
model DoublePendulum2 "two uniform rods hinged in series, each with its own length and mass"
  parameter Real m1(unit = "kg", min = 0) = 1;
  parameter Real m2(unit = "kg", min = 0) = 0.5;
  parameter Real l1(unit = "m", min = 0) = 1;
  parameter Real l2(unit = "m", min = 0) = 0.7;
  parameter Real g(unit = "m/s2", min = 0) = 9.81;
  Gravity gravity(g = {0, -g, 0});
  Rod rod1(m = m1, L = l1, axis = {0, -1, 0});
  Rod rod2(m = m2, L = l2, axis = {0, -1, 0});
  Revolute j1(parent = world, child = rod1.a, axis = {0, 0, 1}, phi(start = 1.2, speed = 0));
  Revolute j2(parent = rod1.b, child = rod2.a, axis = {0, 0, 1}, phi(start = -0.5, speed = 0));
  output Real x1(unit = "m") = rod1.b.x;
  output Real y1(unit = "m") = rod1.b.y;
  output Real x2(unit = "m") = rod2.b.x;
  output Real y2(unit = "m") = rod2.b.y;
end DoublePendulum2;
"""


def chain(n: int) -> str:
    """n masses in a line joined by springs, the first to a wall: 2n parameters."""
    lines = [f'model Chain{n} "{n} masses and {n} springs in a line"']
    for i in range(1, n + 1):
        lines.append(f'  parameter Real m{i}(unit = "kg") = {1 + 0.01 * i:g};')
        lines.append(f'  parameter Real k{i}(unit = "N/m") = {100 - i:g};')
    for i in range(1, n + 1):
        lines.append(f'  coordinate Real x{i}(start = {0.1 if i == 1 else 0:g}, speed = 0, unit = "m");')
    lines.append("equation")
    lines.append("  kinetic = " + " + ".join(f"1/2*m{i}*der(x{i})^2" for i in range(1, n + 1)) + ";")
    pot = ["1/2*k1*x1^2"] + [f"1/2*k{i}*(x{i} - x{i - 1})^2" for i in range(2, n + 1)]
    lines.append("  potential = " + " + ".join(pot) + ";")
    lines.append(f"end Chain{n};")
    return "\n".join(lines) + "\n"


def best(f, repeats):
    times = []
    for _ in range(repeats):
        t0 = time.process_time()
        out = f()
        times.append(time.process_time() - t0)
    return min(times), out


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--repeats", type=int, default=3)
    args = ap.parse_args()
    R = args.repeats
    print(f"{'goal':44} {'simulate s':>11} {'this s':>9} {'ratio':>7} {'goal':>7} {'vs default':>11} "
          f"{'first call s':>13}")

    def row(label, t_vm, t_default, t, goal, first):
        print(f"{label:44} {t_vm:11.3f} {t:9.3f} {t / t_vm:7.2f} {goal:>7} {t / t_default:11.2f} {first:13.3f}")

    def once(f):
        t0 = time.process_time()
        f()
        return time.process_time() - t0

    m = mechdsl.loads(chain(50))
    names = [f"{c}{i}" for i in range(1, 51) for c in "mk"]
    kw = dict(rtol=1e-8, atol=1e-10)
    m.simulate(2.0, points=101, **kw)
    m.simulate(2.0, points=101, compiled=False, **kw)
    t_default, _ = best(lambda: m.simulate(2.0, points=101, **kw), R)
    t_vm, _ = best(lambda: m.simulate(2.0, points=101, compiled=False, **kw), R)
    for label, extra in (("adjoint: integral(energy), 100 parameters", dict(integral=["energy"])),
                         ("adjoint: x50 at t_end, 100 parameters", dict(outputs=["x50"], times=[2.0]))):
        first = once(lambda: m.sensitivities(2.0, params=names, method="adjoint", points=101, **extra, **kw))
        t, S = best(lambda: m.sensitivities(2.0, params=names, method="adjoint", points=101, **extra, **kw), R)
        assert len(S.names) == 100
        row(label, t_vm, t_default, t, "<= 5", first)

    d = mechdsl.loads(DOUBLE)
    five = ["m1", "m2", "l1", "l2", "g"]
    d.simulate(2.0, points=1000, **kw)
    d.simulate(2.0, points=1000, compiled=False, **kw)
    t_default, truth = best(lambda: d.simulate(2.0, points=1000, **kw), R)
    t_vm, _ = best(lambda: d.simulate(2.0, points=1000, compiled=False, **kw), R)
    first = once(lambda: d.sensitivities(2.0, params=five, points=1000, **kw))
    t, S = best(lambda: d.sensitivities(2.0, params=five, points=1000, **kw), R)
    row("forward: 1,000 points, 5 parameters", t_vm, t_default, t, "<= 3", first)

    rng = np.random.default_rng(1)
    data = {"time": truth.t, **{c: truth[c] + 0.003 * rng.standard_normal(truth.t.size)
                                for c in ("x1", "y1", "x2", "y2")}}
    start = d._with_real({"m1": 1.3, "m2": 0.4, "l1": 0.9, "l2": 0.8, "g": 9.0})
    t, f = best(lambda: start.fit(data, params=five, **kw), R)
    ok = all(abs(f.estimates[n] - v) < 4 * f.standard_errors[n] for n, v in (("l1", 1.0), ("l2", 0.7), ("g", 9.81)))
    assert ok and [c.determinable for c in f.unidentifiable] == ["m1/m2"], f.table()
    print(f"{'fit: 5 parameters, 1,000 samples x 4 signals':44} {'':>11} {t:9.3f} {'':>7} {'< 5 s':>7}")
    print(f"  the fit: {f.iterations} iterations, {f.evaluations} runs ({f.jacobians} with sensitivities); "
          f"l1 = {f.estimates['l1']:.5f} +- {f.standard_errors['l1']:.1g} m, g = {f.estimates['g']:.4f} +- "
          f"{f.standard_errors['g']:.1g} m/s2, m1/m2 = {f.unidentifiable[0].value:.4f} +- "
          f"{f.unidentifiable[0].standard_error:.1g} (only the ratio)")


if __name__ == "__main__":
    main()
