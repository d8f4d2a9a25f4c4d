"""Andrews' squeezing mechanism from a fresh process, build included (issue 16).

    python benchmarks/andrews_fresh.py mech OUT.csv      # mech simulate: projection + erk, rtol = atol = 1e-7
    python benchmarks/andrews_fresh.py dop853 OUT.csv    # scipy DOP853 on the index-1 ODE, rtol = atol = 1e-8
    python benchmarks/andrews_fresh.py check OUT.csv     # digits of the positions at t = 0.03

Each of the first two is one whole process (imports, parsing or the model cache, derivation,
integration, writing the final state): time them from outside, side by side, e.g.

    farm-bench -n 7 -- python benchmarks/andrews_fresh.py mech /tmp/a.csv \\
        --vs 'python benchmarks/andrews_fresh.py dop853 /tmp/b.csv'

The tolerances are those at which each reaches 7 correct digits in docs/performance.md's
chart (projection+erk at 1e-7; index1-ode+scipy-dop853 at 1e-8); ``check`` prints the relative
error against the IVP Test Set's reference and exits 1 when it is above 1e-7.  The model
cache (docs/simulate.md) serves both from the second run on; MECHDSL_CACHE=<empty folder>
gives the cold-cache figure.
"""
from __future__ import annotations

import json
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
MODEL = ROOT / "models" / "andrews.mech"
REFERENCE = ROOT / "tests" / "references" / "andrews_squeezer.json"


def run_mech(out: str) -> int:
    from mechdsl.cli import main

    return main(["simulate", str(MODEL), "--formulation", "projection", "--method", "erk", "--rtol", "1e-7",
                 "--atol", "1e-7", "--points", "2", "--no-progress", "-o", out, "--force"])


def run_dop853(out: str) -> int:
    import numpy as np

    import mechdsl
    from mechdsl.bench.index1 import simulate_index1

    m = mechdsl.load(MODEL, model="Andrews")
    r = simulate_index1(m.eom, 0.03, method="scipy-dop853", rtol=1e-8, atol=1e-8, points=2)
    if not r.success:
        print(f"DOP853 failed: {r.message}", file=sys.stderr)
        return 1
    header = ",".join(["time", *m.coordinates])
    np.savetxt(out, np.r_[r.t[-1], r.q[-1]][None, :], delimiter=",", header=header, comments="", fmt="%.17g")
    return 0


def check(out: str) -> int:
    import numpy as np

    ref = np.array(json.loads(REFERENCE.read_text())["reference_t0.03"][:7])
    rows = [ln for ln in Path(out).read_text().splitlines() if ln and not ln.startswith("#")]
    names = rows[0].split(",")
    last = np.array([float(v) for v in rows[-1].split(",")])
    q = last[1:8] if names[0] == "time" else last[:7]
    err = float(np.max(np.abs(q - ref) / np.abs(ref)))
    print(f"{out}: t = {last[0]:g}, max relative error of the 7 positions {err:.2e} "
          f"({'7 digits' if err <= 1e-7 else 'NOT 7 digits'})")
    return 0 if err <= 1e-7 else 1


if __name__ == "__main__":
    if len(sys.argv) != 3 or sys.argv[1] not in ("mech", "dop853", "check"):
        print(__doc__, file=sys.stderr)
        sys.exit(2)
    mode, path = sys.argv[1], sys.argv[2]
    sys.exit({"mech": run_mech, "dop853": run_dop853, "check": check}[mode](path))
