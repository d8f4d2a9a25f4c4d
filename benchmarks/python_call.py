"""One call of a 7-joint arm's dynamics from Python: mechdsl against Pinocchio's ``aba`` (issue 24, item 6).

    PYTHONPATH=src python benchmarks/python_call.py [--calls K]

Franka's Panda from example-robot-data (the bench/test extras install it with ``pin``):
Pinocchio's ``pin.aba(model, data, q, v, tau)`` on the URDF as Pinocchio reads it (9 joints:
7 arm joints and 2 fingers) and on the model with the fingers locked (7 joints), against
mechdsl's ``ode(t, x)`` of the same URDF imported with ``mech import`` (8 coordinates: the
arm's 7 and one finger, the other follows it by its mimic tag) and of models/arm7.mech (7):

- ``fast_function``: ``Model.fast_function()`` (compiled C through preallocated buffers:
  the path docs/control.md documents for a user's own loop);
- ``fast_function VM``: the same with ``compiled=False`` (CasADi's virtual machine);
- ``plain call``: ``m.casadi()["ode"](t, x, u, p)``, numpy in and out (what a user writes first).

Microseconds per call: CPU time (time.process_time) of K calls in a Python loop at a fixed
state, minimum of 5 such loops, all interleaved.  Goal: fast_function at most 2x ``pin.aba``.
"""
from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "src"))


def per_call(fn, calls):
    for _ in range(min(calls, 1000)):
        fn()
    best = float("inf")
    for _ in range(5):
        c = time.process_time()
        for _ in range(calls):
            fn()
        best = min(best, (time.process_time() - c) / calls)
    return 1e6 * best


def urdf_path() -> Path:
    import importlib.metadata as md

    return Path(md.distribution("example-robot-data").locate_file(
        "cmeel.prefix/share/example-robot-data/robots")) / "panda_description" / "urdf" / "panda.urdf"


def rows(calls):
    import pinocchio as pin

    import mechdsl

    urdf = urdf_path()
    full = pin.buildModelFromUrdf(str(urdf))
    fingers = [full.getJointId(n) for n in ("panda_finger_joint1", "panda_finger_joint2")]
    arm = pin.buildReducedModel(full, fingers, pin.neutral(full))
    rng = np.random.default_rng(1)
    cases = []
    for label, model in (("pin.aba, Panda, 9 joints", full), ("pin.aba, Panda, fingers locked (7 joints)", arm)):
        data = model.createData()
        q = pin.neutral(model) + 0.1 * rng.standard_normal(model.nq)
        v, tau = 0.1 * rng.standard_normal(model.nv), np.zeros(model.nv)
        cases.append((label, lambda model=model, data=data, q=q, v=v, tau=tau: pin.aba(model, data, q, v, tau)))
    out = Path(tempfile.mkdtemp()) / "panda.mech"
    subprocess.run([sys.executable, "-m", "mechdsl", "import", str(urdf), "-o", str(out), "--force"], check=True,
                   capture_output=True, env={**os.environ, "PYTHONPATH": str(ROOT / "src")})
    for label, path in (("Panda (mech import, 8 coordinates)", out), ("models/arm7.mech (7 joints)", ROOT / "models" / "arm7.mech")):
        m = mechdsl.load(str(path))
        x = 0.1 * rng.standard_normal(2 * m.eom.n)
        fast, vm = m.fast_function(), m.fast_function(compiled=False)
        plain, pv, u = m.casadi()["ode"], m.parameter_vector(), np.zeros(len(m.eom.inputs))
        cases += [(f"mechdsl fast_function, {label}", lambda f=fast, x=x: f(0.0, x)),
                  (f"mechdsl fast_function VM, {label}", lambda f=vm, x=x: f(0.0, x)),
                  (f"mechdsl plain call, {label}", lambda f=plain, x=x, pv=pv, u=u: f(0.0, x, u, pv))]
    times = {label: per_call(fn, calls if "plain" not in label else max(calls // 20, 100)) for label, fn in cases}
    ref = times["pin.aba, Panda, fingers locked (7 joints)"]
    yield (f"`benchmarks/python_call.py`: us per call from a Python loop (CPU, minimum of 5 loops of {calls} calls); "
           "x aba = relative to pin.aba on the 7-joint Panda")
    yield ""
    yield "| call | us | x aba (7 joints) |"
    yield "|---|---:|---:|"
    for label, _ in cases:
        yield f"| {label} | {times[label]:.2f} | {times[label] / ref:.2f} |"


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--calls", type=int, default=20000)
    a = ap.parse_args(argv)
    for line in rows(a.calls):
        print(line, flush=True)


if __name__ == "__main__":
    main()
