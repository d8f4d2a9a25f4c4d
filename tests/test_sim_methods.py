"""Every method runs, agrees with a reference, and conserves energy to a tolerance-scaled bound."""
from __future__ import annotations

import numpy as np
import pytest

from mechdsl.eom.codegen import find_compiler

from mechdsl.diagnostics import UsageError
from mechdsl.simulation.registry import ode_methods
from mechdsl.simulate import simulate
from sim_models import chain, pendulum, stiff_oscillator

METHODS = ode_methods()
ALL = ["auto", *METHODS]


@pytest.fixture(scope="module")
def reference():
    e = chain(2)
    r = simulate(e, 2.0, method="scipy-dop853", rtol=1e-13, atol=1e-13, points=21)
    return e, r


@pytest.mark.slow_cases('collocation', 'scipy-radau')  # CPU budget: the cheaper tests of this file stay in the default run
@pytest.mark.parametrize("method", ALL)
def test_every_method_runs_accurately_and_conserves_energy(method, reference):
    e, ref = reference
    rtol = 1e-8
    r = simulate(e, 2.0, method=method, rtol=rtol, atol=rtol * 1e-2, points=21)
    assert r.success, r.message
    assert r.t.shape == (21,) and r.q.shape == (21, 2) and r.qd.shape == (21, 2)
    # auto picks from its own rules (choose.choose_method, crk.auto_choice): one of these
    assert r.metadata["method"] == method if method != "auto" else r.metadata["method"] in ("erk", "cvodes-bdf",
                                                                                            "dopri5", "dop853")
    assert r.metadata["method"] in METHODS and r.metadata["method_reason"]
    for key in ("steps", "wall_time"):
        assert key in r.stats
    assert r.stats["steps"] > 0
    # state error against an independent high-accuracy run (scipy DOP853 at 1e-13)
    err = np.abs(np.c_[r.q, r.qd] - np.c_[ref.q, ref.qd]).max()
    assert err < 2e3 * rtol, err
    # energy: a conservative model; drift bounded by a multiple of the tolerance
    assert r.metadata["conservative"] is True
    assert r.stats["energy_drift_relative"] < 300 * rtol


@pytest.mark.parametrize("method", ["erk", "cvodes-bdf", "scipy-dop853", "rk"])
def test_energy_drift_scales_with_tolerance(method):
    e = pendulum()
    loose = simulate(e, 5.0, method=method, rtol=1e-4, atol=1e-6, points=11)
    tight = simulate(e, 5.0, method=method, rtol=1e-9, atol=1e-11, points=11)
    assert tight.stats["energy_drift_relative"] < 1e-2 * loose.stats["energy_drift_relative"]
    assert tight.stats["energy_drift_relative"] < 300 * 1e-9


def test_auto_explains_its_choice():
    r = simulate(chain(2), 1.0)
    assert r.metadata["method"] == ("erk" if find_compiler() is None else "dop853")
    assert "not stiff" in r.metadata["method_reason"]
    assert r.metadata["auto"]["stiffness_ratio"] < 1e3
    s = simulate(stiff_oscillator(), 1.0)
    assert s.metadata["method"] == "cvodes-bdf"
    assert s.metadata["method_reason"].startswith("stiff")
    assert s.metadata["auto"]["stiffness_ratio"] > 1e3


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
def test_stiff_model_bdf_needs_far_fewer_steps_than_explicit():
    e = stiff_oscillator()
    bdf = simulate(e, 2.0, method="cvodes-bdf", rtol=1e-6, atol=1e-8, points=11)
    erk = simulate(e, 2.0, method="erk", rtol=1e-6, atol=1e-8, points=11)
    assert bdf.success and erk.success
    assert bdf.stats["steps"] * 20 < erk.stats["steps"]
    assert np.abs(bdf.q - erk.q).max() < 1e-4


def test_unknown_method_and_options_are_usage_errors():
    e = pendulum()
    with pytest.raises(UsageError, match="did you mean 'cvodes-bdf'"):
        simulate(e, 1.0, method="cvodes-bfd")
    with pytest.raises(UsageError, match="unknown simulation setting 'max_stpe'; did you mean 'max_step'"):
        simulate(e, 1.0, max_stpe=3)
    # a setting of another back end (the contact loop's max_step) is noted, never dropped silently
    assert "settings without effect on an ODE problem: max_step = 3" in simulate(e, 0.1, max_step=3).metadata["notes"]
    with pytest.raises(UsageError, match="end time"):
        simulate(e, 0.0)
    with pytest.raises(UsageError, match="points"):
        simulate(e, 1.0, points=1)
    with pytest.raises(UsageError, match="x0 has 3 entries"):
        simulate(e, 1.0, x0=[1, 2, 3])
    with pytest.raises(UsageError, match="not a coordinate"):
        simulate(e, 1.0, x0={"theta2": 1.0})
    with pytest.raises(UsageError, match="not an output"):
        simulate(e, 1.0, outputs=["z"])
    with pytest.raises(UsageError, match="not a parameter"):
        simulate(e, 1.0, p={"mass": 2})
    r = simulate(e, 1.0, method="erk", dt=0.1, points=3)
    assert any("dt = 0.1 ignored" in n for n in r.metadata["notes"])


def test_overrides_of_start_values_and_parameters():
    e = pendulum()
    r = simulate(e, 1.0, x0={"theta": 0.1, "der(theta)": 0.2}, p={"L": 2.0}, points=3)
    assert r.q[0, 0] == 0.1 and r.qd[0, 0] == 0.2
    assert r.metadata["options"]["parameters"]["L"] == 2.0
    assert abs(r["x"][0] - 2.0 * np.sin(0.1)) < 1e-15


def test_outputs_selection_and_signals():
    e = pendulum()
    r = simulate(e, 1.0, outputs=["y"], points=5)
    assert list(r.signals) == ["y", "kinetic_energy", "potential_energy", "energy"]
    np.testing.assert_allclose(r["y"], -np.cos(r["theta"]), atol=1e-15)
    np.testing.assert_allclose(r["energy"], r["kinetic_energy"] + r["potential_energy"], atol=1e-12)


def test_progress_callback_sees_time_advance():
    seen = []
    simulate(chain(2), 2.0, method="erk", progress=lambda t, t1: seen.append((t, t1)))
    simulate(chain(2), 2.0, method="scipy-rk45", progress=lambda t, t1: seen.append((t, t1)))
    assert seen and seen[-1] == (2.0, 2.0)
    assert all(t1 == 2.0 and 0 <= t <= 2.0 for t, t1 in seen)


def test_dispatch_to_dae_and_symplectic_helpers(monkeypatch):
    """The problem's kind picks the back end: fixed-step methods the canonical integrator,
    constrained models the DAE driver (each called with the settings of the run)."""
    import mechdsl.simulation.backends.dae as dae
    import mechdsl.simulation.backends.fixed_step as symp
    from mechdsl.output.result import Result

    def fake(tag, calls):
        def run(eom, s, *args, **kw):
            calls.append((eom, s))
            return Result(t=np.array([0.0, s.t_end]), q=np.zeros((2, eom.n)), qd=np.zeros((2, eom.n)),
                          coordinates=tuple(eom.coords), metadata={"method": tag})
        return run

    e = pendulum()
    calls = []
    monkeypatch.setattr(symp, "fixed_step_run", fake("stormer-verlet", calls))
    r = simulate(e, 3.0, method="stormer-verlet", dt=0.01)
    assert r.metadata["run"]["problem"] == "canonical"
    s = calls[0][1]           # the back end reads the validated settings: dt in the fixed_step group
    assert s.t_end == 3.0 and s.method == "stormer-verlet" and s.fixed_step.dt == 0.01

    import casadi as ca

    c = pendulum()
    c = c.replace(g=ca.SX(c.q[0] ** 2 - 1), constraint_names=("g1",))  # any constraint routes to the DAE helper
    monkeypatch.setattr("mechdsl.simulation.template.check_start", lambda *a, **k: None)   # (q0 is not on g = 0)
    dcalls = []

    class FakeRun:
        def __init__(self, eom, s, progress=None, compiled=False):
            self.run = lambda: fake("bdf", dcalls)(eom, s)

    monkeypatch.setattr(dae, "SegmentRun", FakeRun)
    r = simulate(c, 2.0, rtol=1e-7)
    assert r.metadata["run"]["problem"] == "dae" and dcalls[0][1].t_end == 2.0 and dcalls[0][1].rtol == 1e-7
