"""The output grid does not change a constrained run's numbers (issue 12, failure 6).

Before, the monitoring grid was the output grid refined to at least 61 points, and every
chunk of it restarted the integrator and projected, so asking for more points gave other
numbers: on the Cartesian pendulum (A01: g = 9.81, released at rest horizontally, 10 s,
default tolerances) 11 and 1001 output points differed by 1.2e-7 (projection + erk),
3.0e-5 (projection + BDF), 1.6e-5 (Adams), 2.6e-7 (baumgarte), 1.6e-6 (ggl) at the common
times.  Now the monitoring grid (checks, projections, segment ends) is fixed by the run's
span, and output times in between are extra output times of the same integrator calls.
CasADi's erk and IDAS take the same steps whatever their output times (round-off equality);
CVODES does not quite (within the tolerance).
"""
import warnings

import numpy as np
import pytest

from dae_models import andrews_eom, pendulum_eom
from mechdsl.dae import simulate_dae


def _pair(eom, t_end, coarse, fine, **kw):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")       # baumgarte / ggl may report drift above the bound
        # the subject is the grid, not the error estimate: the runs carry none
        a = simulate_dae(eom, t_end, points=coarse, error_estimate="off", **kw)
        b = simulate_dae(eom, t_end, points=fine, error_estimate="off", **kw)
    assert a.success and b.success
    step = (fine - 1) // (coarse - 1)
    np.testing.assert_allclose(b.t[::step], a.t, rtol=0, atol=1e-13 * t_end)
    return a, b, step


# CPU budget: the cheaper tests of this file stay in the default run
@pytest.mark.slow_cases('projection-adams-1e-08', 'projection-auto-1e-13', 'projection-bdf-1e-09')
@pytest.mark.parametrize("formulation, method, tol", [
    ("projection", "auto", 1e-13),       # main: 1.2e-7
    ("baumgarte", "auto", 1e-13),        # main: 2.6e-7
    ("ggl", "auto", 1e-13),              # main: 1.6e-6
    ("projection", "bdf", 1e-9),         # main: 3.0e-5 (CVODES: within the tolerance, not round-off)
    ("projection", "adams", 1e-8),       # main: 1.6e-5
])
def test_pendulum_results_do_not_depend_on_the_output_grid(formulation, method, tol):
    # 201 points: already more output times than the monitoring grid's (the 1001 cost 5x the CPU)
    a, b, step = _pair(pendulum_eom(gravity=9.81, v0=(0.0, 0.0)), 10.0, 11, 201,
                       formulation=formulation, method=method)
    assert np.max(np.abs(b.q[::step] - a.q)) <= tol
    assert np.max(np.abs(b.qd[::step] - a.qd)) <= 10 * tol


def test_andrews_results_do_not_depend_on_the_output_grid():
    a, b, step = _pair(andrews_eom(), 0.03, 4, 601, rtol=1e-7, atol=1e-7)
    assert np.max(np.abs(b.q[::step] - a.q)) <= 1e-12 * np.max(np.abs(a.q))


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
def test_outputs_between_checks_keep_the_drift_bound():
    """Output states between projections are recorded within the drift bound (projected for
    the record when needed), without changing the integration."""
    r = simulate_dae(pendulum_eom(gravity=9.81, v0=(0.0, 0.0)), 10.0, points=1001, error_estimate="off")
    assert r.stats["drift_ok"]
    assert np.max(r["constraint_drift"]) <= r.stats["drift_bound"]
    assert np.max(r["velocity_drift"]) <= r.stats["drift_bound"]


@pytest.mark.slow
def test_partitioning_results_do_not_depend_on_the_output_grid():
    """Output times inside a sub-segment are integrated on the side from its start (main: the
    sub-segments were cut at every output time)."""
    a, b, step = _pair(pendulum_eom(gravity=9.81, v0=(0.0, 0.0)), 10.0, 11, 201, formulation="partitioning")
    assert np.max(np.abs(b.q[::step] - a.q)) <= 1e-13
    assert np.max(np.abs(b.qd[::step] - a.qd)) <= 1e-12
