"""Helpers of the FMI export tests: run an exported FMU with fmpy and compare its states with
``mech simulate`` (tests/test_export_fmu.py, tests/test_export_matrix.py)."""
from __future__ import annotations

import numpy as np

# states agree when |fmu - mech| <= STATE_TOL * max(1, |mech|) at every output time
STATE_TOL = 1e-6
# tolerances of the runs compared: mech simulate and the FMU's own stepper at 1e-11; fmpy's
# CVode (BDF, atol = rtol * nominal) needs 1e-12 for the speeds of the constrained models
REF_RTOL, REF_ATOL = 1e-11, 1e-12
CS_TOL, ME_TOL = 1e-11, 1e-12


def state_names(model) -> list[str]:
    return list(model.coordinates) + [f"der({c})" for c in model.coordinates]


def reference(model, t_end: float, dt: float, **kw) -> np.ndarray:
    """mech simulate's states on the grid 0, dt, ..., t_end (method auto: the explicit
    Runge-Kutta pair, whatever the scene's method), (points, 2n)."""
    points = int(round(t_end / dt)) + 1
    r = model.simulate(t_end, points=points, rtol=REF_RTOL, atol=REF_ATOL, method="auto", **kw)
    assert r.success, r.failure
    return np.c_[r.q, r.qd]


def run_fmu(path, model, fmi_type: str, t_end: float, dt: float, tol: float | None = None, **kw):
    """fmpy's run of the FMU at the relative tolerance ``tol`` (default CS_TOL or ME_TOL): (states
    (points, 2n), the result array)."""
    import fmpy

    names = state_names(model)
    tol = tol or (CS_TOL if fmi_type == "CoSimulation" else ME_TOL)
    out = list(kw.pop("output", [])) + names
    res = fmpy.simulate_fmu(str(path), fmi_type=fmi_type, stop_time=t_end, output_interval=dt,
                            relative_tolerance=tol, output=out, record_events=False, **kw)
    # one row per output time (the last one recorded there: after an event at that time)
    grid = np.linspace(0.0, t_end, int(round(t_end / dt)) + 1)
    t = np.asarray(res["time"], float)
    rows = [int(np.flatnonzero(np.abs(t - tg) <= 1e-9 * max(1.0, t_end))[-1]) for tg in grid
            if np.any(np.abs(t - tg) <= 1e-9 * max(1.0, t_end))]
    return np.array([[res[n][i] for n in names] for i in rows]), res[rows]


def assert_agree(X, ref, what: str = "") -> float:
    """The largest scaled difference; fails above STATE_TOL."""
    assert X.shape == ref.shape, f"{what}: {X.shape} rows and columns against {ref.shape}"
    scaled = np.abs(X - ref) / np.maximum(1.0, np.abs(ref))
    worst = float(np.max(scaled))
    assert worst <= STATE_TOL, f"{what}: FMU and mech simulate differ by {worst:.3g} (scaled) at row " \
                               f"{int(np.argmax(np.max(scaled, axis=1)))}"
    return worst
