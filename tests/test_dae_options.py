"""Options, rheonomic constraints, drift reporting, determinism, usage errors."""
import warnings

import numpy as np
import pytest

from dae_models import (andrews_eom, pendulum_eom, rheonomic_pendulum_eom, rheonomic_pendulum_reference)
from mechdsl.dae import FORMULATIONS, simulate_dae
from mechdsl.diagnostics import UsageError


@pytest.mark.slow_cases('partitioning')  # CPU budget: the cheaper tests of this file stay in the default run
@pytest.mark.parametrize("formulation", FORMULATIONS)
def test_rheonomic_constraint_matches_minimal_coordinates(formulation):
    """Rod of prescribed length L(t) = 1 + 0.2 sin 2t: g_t and g_tt enter by AD."""
    t_out = np.linspace(0, 4, 41)
    x_ref, y_ref = rheonomic_pendulum_reference(t_out)
    with warnings.catch_warnings(record=True):
        warnings.simplefilter("always")
        r = simulate_dae(rheonomic_pendulum_eom(), 4.0, formulation=formulation, rtol=1e-10, atol=1e-10,
                         points=41)
    assert r.success, r.message
    # the start speed was free: consistent initialization gave it the radial speed dL/dt(0)
    assert np.hypot(*r.qd[0]) == pytest.approx(0.4, abs=1e-12)
    assert np.max(np.hypot(r["x"] - x_ref, r["y"] - y_ref)) < 1e-6


def test_drift_over_the_bound_is_reported():
    """In the result (metadata warnings, which every command prints) and as a MechWarning (issue
    23), no other Python warning."""
    import warnings

    from mechdsl import MechWarning

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        r = simulate_dae(pendulum_eom(gravity=9.81, v0=(0, 0)), 10.0, formulation="baumgarte",
                         method="cvodes-bdf", rtol=1e-10, atol=1e-10, points=11)
    assert r.stats["drift_ok"] is False
    assert any("drift exceeded" in w for w in r.metadata["warnings"])
    assert caught and all(w.category is MechWarning for w in caught)
    assert sum("drift exceeded" in str(w.message) for w in caught) == 1
    assert "drift exceeded" in r.metadata["drift_warning"]
    assert r.stats["drift_bound"] == pytest.approx(1e-9, rel=1e-12)
    assert r.stats["max_velocity_drift"] > r.stats["drift_bound"]


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
def test_default_keeps_drift_within_bound_for_loose_tolerances():
    for tol in (1e-4, 1e-6, 1e-8):
        r = simulate_dae(pendulum_eom(gravity=9.81, v0=(0, 0)), 20.0, rtol=tol, atol=tol, points=51)
        assert r.stats["drift_ok"], (tol, r.stats)
        assert np.max(r["constraint_drift"]) <= max(10 * tol, 1e-10)


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
def test_deterministic():
    a = simulate_dae(andrews_eom(), 0.01, rtol=1e-8, atol=1e-8, points=5, reactions=True)
    b = simulate_dae(andrews_eom(), 0.01, rtol=1e-8, atol=1e-8, points=5, reactions=True)
    assert np.array_equal(a.q, b.q) and np.array_equal(a.qd, b.qd)
    assert all(np.array_equal(a.signals[k], b.signals[k]) for k in a.signals)


def test_metadata_and_stats():
    r = simulate_dae(pendulum_eom(), 1.0, points=5)
    md = r.metadata
    assert md["formulation"] == "projection" and md["method"].startswith("CasADi erk")
    assert "not stiff" in md["method_reason"] and "Runge-Kutta" in md["method_reason"]
    assert md["dof"]["dof"] == 1 and md["constraints"] == ["rod"]
    for k in ("nsteps", "max_constraint_drift", "max_velocity_drift", "drift_bound", "wall_time", "projections"):
        assert k in r.stats
    r.to_csv_text()          # the Result serializes
    r.to_json_text()


def test_parameters_override():
    r1 = simulate_dae(pendulum_eom(), 1.0, points=3, p={"g": 2.0})
    r2 = simulate_dae(pendulum_eom(gravity=2.0), 1.0, points=3)
    assert np.allclose(r1.q, r2.q)


@pytest.mark.parametrize("kw, match", [
    ({"formulation": "index3"}, "unknown formulation"),
    ({"method": "rk4"}, "ignores the constraints"),         # the fixed-step back end's rule, as for Model.simulate
    ({"formulation": "ggl", "method": "adams"}, "does not apply"),
    ({"bogus": 1}, "unknown simulation setting"),          # the one settings check (issue 22)
    ({"points": 1}, "integer >= 2"),
    ({"rtol": -1}, "tolerances must lie in"),
    ({"p": {"nope": 1}}, "not a parameter"),
])
def test_usage_errors(kw, match):
    with pytest.raises(UsageError, match=match):
        simulate_dae(pendulum_eom(), 1.0, **kw)


def test_stop_time_must_follow_start():
    with pytest.raises(UsageError):
        simulate_dae(pendulum_eom(), 0.0)
