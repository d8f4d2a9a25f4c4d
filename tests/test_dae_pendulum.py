"""Cartesian pendulum (unit point mass, rod of length 1 as a distance constraint).

Cash: J. Cash's MEBDFDAE driver pendul3.f (../shared/references, copied in tests/references/pendulum_index3.json);
its lam is our multiplier since g = (x^2 + y^2 - 1)/2 gives x'' = -x lambda.
A01: IFToMM benchmark A01 against the exact elliptic-function solution.
"""
import json

import warnings

import numpy as np
import pytest

from dae_models import REFERENCES, pendulum_eom, pendulum_exact
from mechdsl.dae import FORMULATIONS, simulate_dae

CASH = json.loads((REFERENCES / "pendulum_index3.json").read_text())["reference_t1"]


def test_cash_scene_matches_reference_at_t1():
    r = simulate_dae(pendulum_eom(gravity=1.0, v0=(0.0, 1.0)), 1.0, rtol=1e-10, atol=1e-10, points=11,
                     reactions=True)
    assert r.success
    assert abs(r["x"][-1] - float(CASH["x"])) < 1e-8
    assert abs(r["y"][-1] - float(CASH["y"])) < 1e-8
    assert abs(r["der(x)"][-1] - float(CASH["u"])) < 1e-8
    assert abs(r["der(y)"][-1] - float(CASH["v"])) < 1e-8
    assert abs(r["lambda[rod]"][-1] - float(CASH["lam"])) < 1e-8


@pytest.mark.slow_cases('partitioning')  # CPU budget: the cheaper tests of this file stay in the default run
@pytest.mark.parametrize("formulation", FORMULATIONS)
def test_cash_scene_every_formulation(formulation):
    with warnings.catch_warnings(record=True):      # plain Baumgarte may exceed the drift bound
        warnings.simplefilter("always")
        r = simulate_dae(pendulum_eom(gravity=1.0, v0=(0.0, 1.0)), 1.0, formulation=formulation,
                         rtol=1e-10, atol=1e-10, points=11)
    assert r.success
    assert np.hypot(r["x"][-1] - float(CASH["x"]), r["y"][-1] - float(CASH["y"])) < 1e-7


def _a01(t_end, points):
    tol = 1e-12
    # checked against the exact solution: the runs carry no error estimate
    r = simulate_dae(pendulum_eom(gravity=9.81, v0=(0.0, 0.0)), t_end, rtol=tol, atol=tol, points=points,
                     error_estimate="off")
    assert r.success, r.message
    x, y = pendulum_exact(r.t)
    err = np.hypot(r["x"] - x, r["y"] - y)
    bound = max(10 * tol, 1e-10)
    return r, err, bound


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
def test_a01_200s():
    r, err, bound = _a01(200.0, 201)
    assert np.max(err) < 1e-3
    assert np.max(r["constraint_drift"]) <= bound and np.max(r["velocity_drift"]) <= bound
    assert r.stats["drift_ok"]


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
def test_a01_energy_is_conserved():
    r, err, bound = _a01(50.0, 501)
    E = 0.5 * (r["der(x)"] ** 2 + r["der(y)"] ** 2) + 9.81 * r["y"]
    assert np.max(np.abs(E - E[0])) < 1e-7
