"""5 s of the N-link chain at rtol 1e-8: mechdsl's default run against scipy DOP853 + Pinocchio's ABA.

    PYTHONPATH=src python benchmarks/nlink_run.py [--sizes 2,5,10,20,30,50,100,200] [--repeats 3] [--no-pin]

For each N (models/nlink_pendulum.mech, q1 = pi/2, the rest 0, at rest) it prints one row:

- mechdsl: ``Model.simulate(t_end=5, rtol=1e-8)``, every other option default (atol 1e-10,
  501 output points, method auto, compiled automatic), warm: one run first (it derives, and
  compiles when ``auto`` decides to; the library is cached on disk), then the CPU time
  (``time.process_time``, all threads) of a whole run, minimum over --repeats runs; the
  method auto chose, its steps and right-hand side evaluations; the first run's wall time;
- scipy: ``solve_ivp(method="DOP853")`` with the same rtol, atol and output grid on the
  right-hand side x' = (v, pin.aba(q, v, 0)) (Pinocchio, C++ called from Python), same CPU
  timing; without pin (``pip install pin``) the right-hand side is mechdsl's own ``ode``
  Function through a buffer call and the column says so;
- ratio = mechdsl / scipy (goal: at most 0.5), and the largest difference of the final joint
  angles between the two runs (both at rtol 1e-8 on a chaotic chain: agreement to about
  1e-6..1e-4 is what the tolerance allows).
"""
from __future__ import annotations

import argparse
import re
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "src"))
sys.path.insert(0, str(ROOT / "benchmarks"))

import mechdsl  # noqa: E402

TEXT = (ROOT / "models" / "nlink_pendulum.mech").read_text()
T_END, RTOL, ATOL, POINTS = 5.0, 1e-8, 1e-10, 501


def model(N):
    return mechdsl.loads(re.sub(r"parameter Integer N = \d+", f"parameter Integer N = {N}", TEXT))


def cpu(fn, repeats):
    best, out = float("inf"), None
    for _ in range(repeats):
        t = time.process_time()
        out = fn()
        best = min(best, time.process_time() - t)
    return best, out


def pin_rhs(N):
    import pinocchio as pin

    from nlink import pin_model

    pm, data = pin_model(N)
    tau = np.zeros(N)

    def f(t, x):
        return np.concatenate([x[N:], pin.aba(pm, data, x[:N], x[N:], tau)])
    return f


def own_rhs(m):
    from mechdsl.eom.codegen import FastFunction, casadi_functions

    fast = FastFunction(casadi_functions(m.eom, names=("ode",))["ode"]).bind(u=np.zeros(0), p=m.parameter_vector())
    return lambda t, x: fast(t, x)


def row(N, repeats, use_pin):
    from scipy.integrate import solve_ivp

    m = model(N)
    t0 = time.perf_counter()
    r = m.simulate(t_end=T_END, rtol=RTOL)
    first = time.perf_counter() - t0
    t_mech, r = cpu(lambda: m.simulate(t_end=T_END, rtol=RTOL), repeats)
    x0 = np.r_[r.q[0], r.qd[0]]
    rhs, kind = (pin_rhs(N), "pin.aba") if use_pin else (own_rhs(m), "mechdsl ode (VM)")
    grid = np.linspace(0, T_END, POINTS)
    t_sp, s = cpu(lambda: solve_ivp(rhs, (0, T_END), x0, method="DOP853", rtol=RTOL, atol=ATOL, t_eval=grid),
                  repeats)
    diff = float(np.abs(r.q[-1] - s.y[:N, -1]).max())
    return {"N": N, "method": r.metadata["method"], "compiled": r.metadata["options"]["compiled"],
            "mech_ms": 1e3 * t_mech, "first_s": first, "steps": r.stats.get("steps"), "evals": r.stats.get("rhs_evals"),
            "scipy_ms": 1e3 * t_sp, "scipy_steps": None, "scipy_evals": s.nfev, "ratio": t_mech / t_sp,
            "diff": diff, "kind": kind}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--sizes", default="2,5,10,20,30,50,100,200")
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--no-pin", action="store_true")
    a = ap.parse_args(argv)
    use_pin = not a.no_pin
    if use_pin:
        try:
            import pinocchio  # noqa: F401
        except ImportError:
            print("# pinocchio not installed (pip install pin): scipy runs on mechdsl's own ode instead",
                  file=sys.stderr)
            use_pin = False
    print(f"5 s of the N-link chain, rtol {RTOL:g}, atol {ATOL:g}, {POINTS} points; CPU ms (min of {a.repeats}, warm)")
    print()
    print("|   N | mechdsl method | compiled | mechdsl CPU [ms] | first run [s] | evals | scipy DOP853 + RHS | scipy CPU [ms] | evals | ratio | final diff |")
    print("|----:|---|---|---:|---:|---:|---|---:|---:|---:|---:|")
    for N in [int(x) for x in a.sizes.split(",")]:
        d = row(N, a.repeats, use_pin)
        print(f"| {d['N']:3d} | {d['method']} | {'yes' if d['compiled'] else 'no'} | {d['mech_ms']:.1f} | "
              f"{d['first_s']:.2f} | {d['evals']} | {d['kind']} | {d['scipy_ms']:.1f} | {d['scipy_evals']} | "
              f"{d['ratio']:.2f} | {d['diff']:.1e} |", flush=True)


if __name__ == "__main__":
    main()
