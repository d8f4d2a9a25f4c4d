"""Degrees of freedom, redundant constraints (Bricard) and singular configurations."""
import warnings

import casadi as ca
import numpy as np
import pytest

from dae_models import (andrews_eom, bricard_eom, parallelogram_eom, parallelogram_singular_time,
                        pendulum_eom)
from mechdsl.dae import FORMULATIONS, dof_report, simulate_dae
from mechdsl.eom import from_lagrangian


def _counts(rep):
    return (rep.coordinates, rep.constraints, rep.rank, rep.dof, rep.redundant)


def test_counts_of_simple_models():
    assert _counts(dof_report(pendulum_eom())) == (2, 1, 1, 1, 0)
    assert _counts(dof_report(andrews_eom())) == (7, 6, 6, 1, 0)


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
def test_duplicated_constraint_is_redundant():
    q = ca.SX.sym("q", 2)
    qd = ca.SX.sym("qd", 2)
    t = ca.SX.sym("t")
    p = ca.SX.sym("p", 0)
    rod = 0.5 * (q[0] ** 2 + q[1] ** 2 - 1)
    e = from_lagrangian("Twice", ("x", "y"), (), [], q, qd, t, p, 0.5 * ca.dot(qd, qd), 9.81 * q[1],
                        g=ca.vertcat(rod, 1000 * rod), q0=[1, 0], constraint_names=["rod", "rod_mm"])
    rep = dof_report(e)
    assert _counts(rep) == (2, 2, 1, 1, 1)
    assert rep.redundant_names == ("rod_mm",)
    r = simulate_dae(e, 1.0, rtol=1e-10, atol=1e-10, points=5, reactions=True)
    assert r.success and r.metadata["active_constraints"] == ["rod"]
    assert np.all(r["lambda[rod_mm]"] == 0.0)
    ref = simulate_dae(pendulum_eom(gravity=9.81, v0=(0, 0)), 1.0, rtol=1e-10, atol=1e-10, points=5)
    assert np.max(np.abs(r.q - ref.q)) < 1e-7       # same equations; projection points differ


def test_bricard_has_one_dof_and_one_redundant_constraint():
    rep = dof_report(bricard_eom())
    assert _counts(rep) == (5, 5, 4, 1, 1)
    assert rep.predicted_dof == 0
    assert rep.redundant_names == dof_report(bricard_eom()).redundant_names   # deterministic
    assert len(rep.redundant_names) == 1


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
def test_bricard_simulates_on_all_constraints_with_constant_energy():
    r = simulate_dae(bricard_eom(), 2.0, rtol=1e-10, atol=1e-10, points=41, reactions=True)
    assert r.success, r.message
    assert any("redundant" in n for n in r.metadata["notes"])
    dropped = r.metadata["dof"]["redundant_names"][0]
    assert np.all(r[f"lambda[{dropped}]"] == 0.0)
    # every constraint, the dropped one included, holds; a 1-dof conservative system whose
    # energy and constraints hold follows the true motion
    assert np.max(r["constraint_drift"]) <= 1e-9 and np.max(r["velocity_drift"]) <= 1e-9
    E = r["energy"]
    assert np.max(np.abs(E - E[0])) < 1e-8 * max(1.0, abs(E[0]))
    assert np.ptp(r.q[:, 0]) > 0.1            # it does move


@pytest.mark.slow_cases('partitioning')  # CPU budget: the cheaper tests of this file stay in the default run
@pytest.mark.parametrize("formulation", [f for f in FORMULATIONS if f != "augmented"])   # augmented crosses:
def test_parallelogram_stops_at_the_singular_configuration(formulation):                  # test_dae_singular.py
    t_star = parallelogram_singular_time()
    with warnings.catch_warnings(record=True):
        warnings.simplefilter("always")
        r = simulate_dae(parallelogram_eom(), 2.0, formulation=formulation, rtol=1e-9, atol=1e-9, points=21)
    assert not r.success
    assert r.failure.cause == "singular configuration"
    assert abs(r.failure.time - t_star) < 1e-3
    assert r.t[-1] <= r.failure.time + 1e-12           # nothing recorded past it
    # what was recorded is the parallelogram motion (th1 = th3, th2 = 0), not garbage
    assert np.max(np.abs(r.q[:, 0] - r.q[:, 2])) < 1e-6 and np.max(np.abs(r.q[:, 1])) < 1e-6
    # every output time before the singular one was recorded, then the singular state itself
    assert np.allclose(r.t[:-1], np.arange(0, t_star, 0.1)) and r.t[-1] == r.failure.time


def test_parallelogram_default_detects_precisely():
    r = simulate_dae(parallelogram_eom(), 2.0, rtol=1e-10, atol=1e-10, points=21)
    assert abs(r.failure.time - parallelogram_singular_time()) < 1e-5
    assert any(ev["kind"] == "singular" for ev in r.events)
