"""A dumbbell (two masses, massless rigid rod) in DAE form against its minimal-coordinate form.

The minimal form is an ODE integrated here with scipy (DOP853) from the same T and V; the
DAE form goes through every formulation of the package."""
import functools
import warnings

import casadi as ca
import numpy as np
import pytest
from scipy.integrate import solve_ivp

from dae_models import dumbbell_dae, dumbbell_minimal
from mechdsl.dae import FORMULATIONS, simulate_dae

T_END = 3.0
POINTS = 31


@functools.lru_cache(maxsize=1)          # one reference for every formulation
def _minimal_reference():
    e = dumbbell_minimal()
    f = ca.Function("f", [e.q, e.qd, e.p], [ca.solve(e.M, e.bias), ca.vertcat(*e.outputs.values())])
    rhs = lambda t, y: np.concatenate([y[3:], np.array(f(y[:3], y[3:], e.param_values)[0]).ravel()])  # noqa: E731
    q0, qd0 = e.start()
    t = np.linspace(0, T_END, POINTS)
    sol = solve_ivp(rhs, (0, T_END), np.concatenate([q0, qd0]), method="DOP853", rtol=1e-13, atol=1e-13, t_eval=t)
    x2y2 = np.array([np.array(f(y[:3], y[3:], e.param_values)[1]).ravel() for y in sol.y.T])
    return sol.y[:3].T, x2y2


# CPU budget: the cheaper tests of this file stay in the default run
@pytest.mark.slow_cases('ggl', 'partitioning', 'projection')
@pytest.mark.parametrize("formulation", FORMULATIONS)
def test_dae_dumbbell_agrees_with_minimal_coordinates(formulation):
    q_min, x2y2 = _minimal_reference()
    with warnings.catch_warnings(record=True):
        warnings.simplefilter("always")
        r = simulate_dae(dumbbell_dae(), T_END, formulation=formulation, rtol=1e-10, atol=1e-10, points=POINTS,
                         error_estimate="off")          # against the minimal-coordinate reference
    assert r.success, r.message
    err1 = np.max(np.abs(r.q[:, :2] - q_min[:, :2]))
    err2 = np.max(np.abs(r.q[:, 2:] - x2y2))
    assert err1 < 1e-6 and err2 < 1e-6, (err1, err2)
    assert np.max(np.abs(np.hypot(r["x2"] - r["x1"], r["y2"] - r["y1"]) - 1.5)) < 1e-9
