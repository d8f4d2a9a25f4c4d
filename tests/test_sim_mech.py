"""simulate() and `mech simulate` on models written in .mech (through mechdsl.load/loads)."""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

import mechdsl
from mechdsl.cli import main
from test_sim_accuracy import T_REF, hermite_crossings
import mechdsl.examples

MODELS = mechdsl.examples.folder()


def test_pendulum_scene_period_from_mech_text():
    m = mechdsl.load(MODELS / "pendulum.mech", scene="Swing")
    r = m.simulate(points=10001)            # scene: stop_time 10, tolerance 1e-10, outputs x, y, E
    assert r.success and r.t[-1] == pytest.approx(10.0, rel=1e-14)
    assert list(r.signals)[:3] == ["x", "y", "E"]
    tc = hermite_crossings(r.t, r["theta"], r["der(theta)"])
    assert len(tc) >= 4
    assert np.abs(np.diff(tc) / T_REF - 1).max() < 1e-9
    assert np.abs(r["E"] - r["energy"]).max() < 1e-12


@pytest.mark.parametrize("method", ["erk", "cvodes-bdf", "scipy-dop853"])
def test_component_and_equation_layer_pendulums_agree(method):
    a = mechdsl.load(MODELS / "pendulum.mech", model="Pendulum").simulate(3.0, method=method, points=31)
    b = mechdsl.load(MODELS / "pendulum.mech", model="PendulumLagrange").simulate(3.0, method=method, points=31)
    np.testing.assert_allclose(a.q, b.q, atol=1e-7)


def test_compiled_recursive_route_matches_vm(tmp_path, monkeypatch):
    monkeypatch.setenv("MECHDSL_CACHE", str(tmp_path))
    m = mechdsl.load(MODELS / "double_pendulum.mech")
    vm = m.simulate(2.0, method="erk", points=21)
    c = m.simulate(2.0, method="erk", points=21, compiled=True)
    if c.metadata["options"]["compiled"]:
        np.testing.assert_allclose(c.q, vm.q, rtol=1e-12, atol=1e-12)
    else:
        assert any("no C compiler" in w for w in c.metadata["warnings"])


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
def test_cli_on_shipped_model_with_scene_and_sets(tmp_path, capsys):
    out = tmp_path / "swing.csv"
    code = main(["simulate", str(MODELS / "pendulum.mech"), "--scene", "Swing", "--t-end", "1", "--points", "11",
                 "--set", "L=2", "--set", "theta.start=0.5", "-o", str(out), "--plot", str(tmp_path / "s.svg")])
    text = capsys.readouterr().out
    assert code == 0, text
    header = out.read_text().splitlines()[0].split(",")
    assert header[:3] == ["time", "theta", "der(theta)"] and header[3:6] == ["x", "y", "E"]
    first = [float(v) for v in out.read_text().splitlines()[1].split(",")]
    assert first[1] == 0.5 and first[3] == pytest.approx(2 * np.sin(0.5))
    meta = json.loads((tmp_path / "swing.json").read_text())
    assert meta["metadata"]["options"]["rtol"] == 1e-10 and meta["metadata"]["scene"] == "Swing"
    assert (tmp_path / "s.svg").read_text().startswith("<?xml")


def test_loads_text_model_and_failure_report():
    text = """
    model Bead "T = 1/2 (cos(s) s')^2: the mass matrix vanishes at s = pi/2"
      coordinate Real s(start = 0, speed = 1);
    equation
      kinetic = 1/2*(cos(s)*der(s))^2;
      potential = 0;
    end Bead;
    """
    r = mechdsl.loads(text).simulate(3.0, points=30)
    assert not r.success and r.failure.cause == "singular mass matrix"
    assert abs(r.failure.time - 1.0) < 0.02


def test_parameter_variants_share_functions_and_give_their_own_numbers():
    from mechdsl.eom.codegen import casadi_functions

    m = mechdsl.load(MODELS / "pendulum.mech", model="PendulumLagrange")
    m2 = m.with_params(L=2.0)
    assert casadi_functions(m.eom) is casadi_functions(m2.eom)
    assert m.casadi()["ode"] is m2.casadi()["ode"]
    r1 = m.simulate(1.0, points=3, method="erk", rtol=1e-10, atol=1e-12)
    r2 = m2.simulate(1.0, points=3, method="erk", rtol=1e-10, atol=1e-12)
    # the same swing on a 4 times longer pendulum takes twice the time (sqrt(L/g) scaling)
    r4 = m.with_params(L=4.0).simulate(2.0, points=3, method="erk", rtol=1e-10, atol=1e-12)
    assert abs(r4["theta"][-1] - r1["theta"][-1]) < 1e-8 and r2["theta"][-1] != r1["theta"][-1]
