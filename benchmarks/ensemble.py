"""Ensembles (issue 24 item 5): a sweep of the double pendulum's release angles against a
hand-written ``Function.map`` of a CasADi integrator and against ``mujoco.rollout``, at
matched accuracy, one thread each, side by side in one run.

    python benchmarks/ensemble.py [--runs 400] [--t-end 10] [--rtol 1e-8] [--repeat 3]

The runs: models/double_pendulum.mech from (j1.phi, j2.phi) on a grid over [-a, a]^2 (--spread
a, default 1.5 rad), at rest, --t-end seconds, 101 output points.  The error of a run is the
largest |angle - reference| at the end time, the reference the same sweep at rtol 1e-12
(dop853); the table gives the median over the runs.  Rows:

  sweep             mechdsl's default sweep (``m.sweep(starts=...)``: method auto, vectorized
                    scheduler; the stepping loop's ensemble call), per-run post steps included
  hand map          the prepared erk integrator of one run (CasADi's, the virtual machine)
                    ``map``-ped over the runs by hand and called once (no post steps): at the
                    sweep's rtol, and at the loosest rtol of a decade grid whose error is at
                    most the sweep's (matched accuracy)
  mujoco.rollout    the same two rods in MJCF, RK4, the time step halved until the median
                    error is at most the sweep's (matched accuracy); one MjData (one thread)

CPU time (time.process_time), the minimum of --repeat, per run; ratios of the same run.
"""
from __future__ import annotations

import argparse
import platform
import time
from pathlib import Path

import numpy as np

import mechdsl
from mechdsl.simulation import formulate
from mechdsl.simulation.prepared import prepare
from mechdsl.sweep.runs import scheme_parameter

MODEL = Path(__file__).resolve().parents[1] / "models" / "double_pendulum.mech"

MJCF = """<mujoco model="double_pendulum">
  <option timestep="{dt}" integrator="RK4" gravity="0 -9.81 0"/>
  <worldbody>
    <body name="rod1">
      <joint name="j1" type="hinge" axis="0 0 1"/>
      <inertial pos="0 -0.5 0" mass="1" diaginertia="{I} 1e-12 {I}"/>
      <body name="rod2" pos="0 -1 0">
        <joint name="j2" type="hinge" axis="0 0 1"/>
        <inertial pos="0 -0.5 0" mass="1" diaginertia="{I} 1e-12 {I}"/>
      </body>
    </body>
  </worldbody>
</mujoco>"""


def starts(runs: int, spread: float) -> dict:
    k = max(1, int(round(np.sqrt(runs))))
    return {"j1.phi": np.linspace(-spread, spread, k), "j2.phi": np.linspace(-spread, spread, k)}


def start_matrix(st: dict) -> np.ndarray:
    a, b = np.meshgrid(st["j1.phi"], st["j2.phi"], indexing="ij")
    return np.column_stack([a.ravel(), b.ravel()])


def cpu_min(fn, repeat: int):
    best, out = float("inf"), None
    for _ in range(repeat):
        t0 = time.process_time()
        out = fn()
        best = min(best, time.process_time() - t0)
    return best, out


def sweep_final(m, st, t_end, rtol, **kw):
    ds = m.sweep(starts=st, t_end=t_end, rtol=rtol, points=101, progress=False, workers=1, **kw)
    assert int(ds.attrs["n_failed"]) == 0, ds.attrs["summary"]
    return np.column_stack([ds["j1.phi"].values[:, -1], ds["j2.phi"].values[:, -1]]), ds


def hand_map(m, Q0, t_end, rtol):
    """The erk integrator a single run of rtol uses, mapped over the runs by hand: (call, final angles)."""
    s = m.settings(t_end=t_end, rtol=rtol, method="erk", points=101)
    prep = prepare(formulate(m.eom, s))
    n = len(Q0)
    F = prep.integrator().map(n)
    X0 = np.vstack([Q0.T, np.zeros((2, n))])
    P = np.tile(scheme_parameter(m.parameter_values)[:, None], (1, n))

    def call():
        return np.asarray(F(x0=X0, p=P)["xf"], float)

    def final(xf):
        return xf.reshape(4, n, 101)[:2, :, -1].T
    return call, final


def mujoco_rollout(Q0, t_end, dt):
    import mujoco
    from mujoco import rollout

    model = mujoco.MjModel.from_xml_string(MJCF.format(dt=dt, I=1.0 / 12.0))
    data = mujoco.MjData(model)
    spec = mujoco.mjtState.mjSTATE_FULLPHYSICS
    size = mujoco.mj_stateSize(model, spec)
    init = np.zeros((len(Q0), size))
    for i, q in enumerate(Q0):
        mujoco.mj_resetData(model, data)
        data.qpos[:] = q
        mujoco.mj_getState(model, data, init[i], spec)
    nstep = int(round(t_end / dt))

    def call():
        state, _ = rollout.rollout(model, data, init, nstep=nstep)
        return state[:, -1, 1:3]        # FULLPHYSICS: time, qpos, ...
    return call


def median_err(Q, ref) -> float:
    return float(np.median(np.abs(Q - ref).max(axis=1)))


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--runs", type=int, default=400)
    ap.add_argument("--spread", type=float, default=1.5)
    ap.add_argument("--t-end", type=float, default=10.0)
    ap.add_argument("--rtol", type=float, default=1e-8)
    ap.add_argument("--repeat", type=int, default=3)
    a = ap.parse_args()
    m = mechdsl.load(str(MODEL), model="DoublePendulum")
    st = starts(a.runs, a.spread)
    Q0 = start_matrix(st)
    n = len(Q0)
    ref, _ = sweep_final(m, st, a.t_end, 1e-12, method="dop853")
    print(f"double pendulum ensemble: {n} runs from (j1.phi, j2.phi) in [-{a.spread}, {a.spread}]^2 at rest, "
          f"{a.t_end} s, 101 points; error = median over runs of max |angle - reference| at the end "
          f"(reference: dop853 at rtol 1e-12); CPU ms per run, min of {a.repeat}, one thread")
    print(f"machine: {platform.platform()}, load average {' '.join(f'{x:.2f}' for x in __import__('os').getloadavg())}")
    rows = []
    sweep_final(m, st, a.t_end, a.rtol)     # warm: compile / load the loop
    t_sw, (Q_sw, ds) = cpu_min(lambda: sweep_final(m, st, a.t_end, a.rtol), a.repeat)
    e_sw = median_err(Q_sw, ref)
    rows.append((f"sweep (default: {ds.attrs['method']}, {ds.attrs['scheduler']})", f"rtol {a.rtol:g}", t_sw / n, e_sw))
    call, final = hand_map(m, Q0, a.t_end, a.rtol)
    call()
    t_h, xf = cpu_min(call, a.repeat)
    e_h = median_err(final(xf), ref)
    rows.append(("hand map (erk, CasADi VM), same rtol", f"rtol {a.rtol:g}", t_h / n, e_h))
    matched = None
    for k in range(0, 6):          # the loosest rtol, a decade at a time, whose error is within the sweep's
        r = a.rtol / 10 ** k
        call, final = hand_map(m, Q0, a.t_end, r)
        call()
        t, xf = cpu_min(call, a.repeat)
        e = median_err(final(xf), ref)
        if e <= e_sw:
            matched = ("hand map (erk, CasADi VM), matched accuracy", f"rtol {r:g}", t / n, e)
            break
    rows.append(matched or ("hand map (erk, CasADi VM), matched accuracy", "not reached by rtol 1e-5 x", np.nan,
                            np.nan))
    mj = None
    try:
        import mujoco  # noqa: F401
        dt = 0.01
        for _ in range(16):
            call = mujoco_rollout(Q0, a.t_end, dt)
            call()
            t, Q = cpu_min(call, a.repeat)
            e = median_err(Q, ref)
            if e <= e_sw:
                mj = ("mujoco.rollout (RK4), matched accuracy", f"dt {dt:.3g} s", t / n, e)
                break
            dt /= 2
        rows.append(mj or ("mujoco.rollout (RK4), matched accuracy", f"not reached by dt {dt:.3g}", np.nan, np.nan))
    except ImportError:
        rows.append(("mujoco.rollout", "mujoco not installed", np.nan, np.nan))
    print()
    print("| run | setting | CPU ms per run | median final error | sweep / this |")
    print("|---|---|---:|---:|---:|")
    for name, setting, t, e in rows:
        ratio = (t_sw / n) / t if t == t else float("nan")
        print(f"| {name} | {setting} | {t * 1e3:.3f} | {e:.1e} | {ratio:.2f} |")
    print()
    h_same = rows[1][2]
    print(f"goal (issue 24): sweep at most 0.5x the hand map: {t_sw / n / h_same:.2f}x the same-rtol map"
          + (f", {t_sw / n / matched[2]:.2f}x the matched-accuracy map" if matched else ""))
    if mj:
        print(f"goal (issue 24): at least 4x better than mujoco.rollout at matched accuracy: "
              f"{mj[2] / (t_sw / n):.1f}x")


if __name__ == "__main__":
    main()
