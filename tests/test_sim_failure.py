"""Failed runs keep their results up to the failure and say when and why."""
from __future__ import annotations

import json

import numpy as np
import pytest

from mechdsl.diagnostics import MechError
from mechdsl.simulate import simulate
from sim_models import blowup, chain, singular_bead, stiff_oscillator


@pytest.mark.parametrize("method", ["erk", "cvodes-bdf", "cvodes-adams", "rosenbrock", "scipy-dop853", "scipy-lsoda"])
@pytest.mark.parametrize("two", [False, True], ids=["1dof", "2dof-qr"])
def test_singular_mass_matrix_is_reported_with_time(method, two):
    # exact motion sin(s) = t: the mass matrix cos(s)^2 becomes singular at t = 1
    r = simulate(singular_bead(extra_oscillator=two), 3.0, method=method, points=30)
    assert not r.success
    assert r.failure.cause == "singular mass matrix", r.failure
    assert abs(r.failure.time - 1.0) < 0.02
    assert "coordinates involved: s" in r.failure.detail
    assert 0.9 < r.t[-1] <= 1.0 and len(r.t) == r.q.shape[0] == len(r["energy"])
    assert np.isfinite(r.q).all() and np.isfinite(r.qd).all()
    # the kept part is right: sin(s) = t
    np.testing.assert_allclose(np.sin(r["s"]), r.t, atol=1e-6)


@pytest.mark.slow_cases('erk', 'rk')  # CPU budget: the cheaper tests of this file stay in the default run
@pytest.mark.parametrize("method", ["erk", "cvodes-bdf", "scipy-rk45", "rk"])
def test_blow_up_is_reported_and_partial_results_are_exact(method):
    r = simulate(blowup(), 3.0, method=method, points=31)
    assert not r.success
    assert r.failure.cause == "solution blows up", r.failure
    assert abs(r.failure.time - np.sqrt(2)) < 1e-3
    assert r.t[-1] == pytest.approx(1.4)
    exact = 1 / (1 - r.t / np.sqrt(2))
    # default rtol 1e-8; the last point (u = 99, 0.014 before the pole) is ill-conditioned
    np.testing.assert_allclose(r["u"][:-1], exact[:-1], rtol=1e-5)
    np.testing.assert_allclose(r["u"][-1], exact[-1], rtol=1e-4)


def test_too_many_steps():
    r = simulate(stiff_oscillator(), 1.0, method="cvodes-adams", points=11, max_steps=30)
    assert not r.success
    assert r.failure.cause == "too many steps"
    assert "max_steps" in r.failure.detail
    assert r.t[-1] < 1.0


def test_unstable_fixed_step_is_told_apart_from_the_model():
    r = simulate(stiff_oscillator(), 1.0, method="rk", dt=0.01, points=11)
    assert not r.success
    assert r.failure.cause == "fixed step too large", r.failure
    assert "dt" in r.failure.detail


def test_failed_run_writes_partial_csv_and_json(tmp_path):
    r = simulate(singular_bead(), 3.0, method="erk", points=30)
    out = tmp_path / "bead.csv"
    r.to_csv(out)
    rows = out.read_text().strip().splitlines()
    assert len(rows) == 1 + len(r.t)
    meta = json.loads((tmp_path / "bead.json").read_text())
    assert meta["success"] is False
    assert meta["failure"]["cause"] == "singular mass matrix"
    assert abs(meta["failure"]["time"] - 1.0) < 0.02


def test_non_finite_start_is_a_usage_error_not_a_traceback():
    from mechdsl.diagnostics import UsageError

    with pytest.raises(UsageError, match="not finite"):
        simulate(chain(2), 1.0, x0={"theta1": float("nan")})


def test_non_finite_right_hand_side_at_the_start():
    import casadi as ca

    from mechdsl import eom as E

    q, qd, t, p = ca.SX.sym("q", 1), ca.SX.sym("qd", 1), ca.SX.sym("t"), ca.SX.sym("p", 0)
    # V = -sqrt(q): the force sqrt'(q) is infinite at q = 0, where the run starts
    e = E.from_lagrangian("Root", ["q"], [], [], q, qd, t, p, 0.5 * qd[0] ** 2, -ca.sqrt(q[0]))
    # at the start the start check refuses it (mechdsl.eom.preflight): a coded error, no run
    with pytest.raises(MechError) as ex:
        simulate(e, 1.0, points=11)
    assert ex.value.first.code == "E744" and "q" in ex.value.first.message
    # started at q = 1 towards 0 at speed 20 it reaches q = 0, past which sqrt(q) is nan, at
    # t = int_0^1 dq / sqrt(2 (199 + sqrt(q))) (energy 1/2 v^2 - sqrt(q) = 199): the run stops there
    from scipy.integrate import quad

    t_zero = quad(lambda s: 1.0 / np.sqrt(2.0 * (199.0 + np.sqrt(s))), 0.0, 1.0)[0]
    r = simulate(e, 1.0, points=11, x0=[1.0, -20.0])
    assert not r.success and r.failure.time == pytest.approx(t_zero, rel=1e-3)
    assert r.failure.cause in ("non-finite right-hand side", "non-finite state", "integrator failure"), r.failure
    assert len(r.t) == 1 and r.q[0, 0] == 1.0


def test_model_without_coordinates_evaluates_outputs():
    import casadi as ca

    from mechdsl import eom as E

    q, qd, t, p = ca.SX.sym("q", 0), ca.SX.sym("qd", 0), ca.SX.sym("t"), ca.SX.sym("p", 1)
    e = E.from_lagrangian("Clock", [], ["w"], [2.0], q, qd, t, p, ca.SX(0), ca.SX(0), outputs={"s": ca.sin(p[0] * t)})
    r = simulate(e, 1.0, points=5)
    assert r.success and r.metadata["method"] == "none"
    np.testing.assert_allclose(r["s"], np.sin(2 * r.t), atol=1e-15)
