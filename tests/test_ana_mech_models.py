"""The analyses from .mech text and the shipped models, against closed forms; the CLI.

These go through the whole front end and the mechanics stage (derive)."""
import json
import math

import numpy as np
import pytest

import mechdsl
from mechdsl.cli import main
from ana_models import simulate_symplectic

from conftest import MODELS

POINT_MASS_DP = """
model DPComponents "two equal point masses on equal massless rods"
  parameter Real m(unit = "kg") = 0.7;
  parameter Real l(unit = "m") = 1.3;
  parameter Real g(unit = "m/s2") = 9.81;
  Gravity gravity(g = {0, -g, 0});
  PointMass b1(m = m);
  PointMass b2(m = m);
  Point top1(body = b1, r = {0, l, 0});
  Point top2(body = b2, r = {0, l, 0});
  Revolute j1(parent = world, child = top1, axis = {0, 0, 1}, phi(start = 0.1));
  Revolute j2(parent = b1, child = top2, axis = {0, 0, 1}, phi(start = 0.1));
end DPComponents;

model DPEquations "the same, as T and V in absolute angles"
  parameter Real m(unit = "kg") = 0.7;
  parameter Real l(unit = "m") = 1.3;
  parameter Real g(unit = "m/s2") = 9.81;
  coordinate Real a(start = 0.1, unit = "rad");
  coordinate Real b(start = 0.2, unit = "rad");
equation
  kinetic = 1/2*m*l^2*(2*der(a)^2 + der(b)^2 + 2*der(a)*der(b)*cos(a - b));
  potential = -m*g*l*(2*cos(a) + cos(b));
end DPEquations;
"""


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
@pytest.mark.parametrize("model", ["DPComponents", "DPEquations"])
def test_point_mass_double_pendulum_from_text(model):
    m = mechdsl.loads(POINT_MASS_DP, model=model)
    lin = m.linearize()
    g, l = 9.81, 1.3
    expected = np.sqrt([(g / l) * (2 - math.sqrt(2)), (g / l) * (2 + math.sqrt(2))])
    assert lin.modes().frequencies == pytest.approx(expected, rel=1e-10)
    eqs = m.equilibria()
    assert len(eqs) == 4 and sum(e.stable is True for e in eqs) == 1


def test_equation_layer_symbolic_route_is_ir_and_agrees():
    m = mechdsl.loads(POINT_MASS_DP, model="DPEquations")
    lin = m.linearize(at="t=0.8")
    s = lin.symbolic(exact=False)
    assert s.route == "ir"
    for a, b in zip(s.numeric(lin.p), (lin.M, lin.C, lin.K)):
        assert np.allclose(a, b, rtol=1e-10, atol=1e-10)


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
def test_shipped_double_pendulum_uniform_rods():
    m = mechdsl.load(MODELS / "double_pendulum.mech", model="DoublePendulum")
    g, l = 9.81, 1.0
    # two uniform rods: (l/g) w^2 = 3 -/+ 6/sqrt(7)
    expected = np.sqrt([(g / l) * (3 - 6 / math.sqrt(7)), (g / l) * (3 + 6 / math.sqrt(7))])
    assert m.linearize().modes().frequencies == pytest.approx(expected, rel=1e-10)


@pytest.mark.parametrize("model", ["BeadOnHoop", "BeadOnHoopLagrange"])
def test_bead_on_hoop(model):
    m = mechdsl.load(MODELS / "bead_on_hoop.mech", model=model)
    p = m.parameters
    R, g, w = p["R"], p["g"], p["omega"]
    assert w ** 2 * R > g
    th0 = math.acos(g / (w ** 2 * R))
    eqs = m.equilibria()
    stable = [e for e in eqs if e.stable]
    assert sorted(abs(e["theta"]) for e in stable) == pytest.approx([th0, th0], rel=1e-10)
    assert all(e.kind == "relative" for e in eqs)
    bottom = [e for e in eqs if abs(e["theta"]) < 1e-9][0]
    assert bottom.stable is False
    lin = m.linearize(at=stable[0])
    assert lin.modes().frequencies == pytest.approx([w * math.sin(th0)], rel=1e-10)
    fis = m.first_integrals()
    assert [f.name for f in fis] == ["jacobi"]


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
def test_two_masses_spring_model():
    m = mechdsl.load(MODELS / "two_masses_spring.mech")
    p = m.parameters
    eqs = m.equilibria(guesses={"x1": 0.0, "x2": 1.0})
    e = [e for e in eqs if e["x2"] > e["x1"]][0]
    assert e.kind == "accelerated-reference"
    assert e.acceleration == pytest.approx([p["F"] / (2 * p["m"])] * 2, rel=1e-10)
    assert e["x2"] - e["x1"] - p["l0"] == pytest.approx(p["F"] / (2 * p["k"]), rel=1e-9)


def test_cart_pole_model_uniform_rod():
    m = mechdsl.load(MODELS / "cart_pole.mech")
    p = m.parameters
    M, mp, l, g = p["M"], p["m"], p["l"], p["g"]
    lin = m.linearize()
    lam2 = (mp * g * l / 2) / (mp * l ** 2 / 3 - (mp * l / 2) ** 2 / (M + mp))
    assert np.max(np.linalg.eigvals(lin.A).real) == pytest.approx(math.sqrt(lam2), rel=1e-10)
    assert lin.inputs == ("F",)                         # the declared input
    assert lin.B[2:, 0] == pytest.approx(np.linalg.solve(lin.M, [1.0, 0.0]))


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
def test_heavy_top_model_momenta():
    m = mechdsl.load(MODELS / "heavy_top.mech", scene="Spin")
    p = m.parameters
    A, I3 = p["I1"] + p["m"] * p["l"] ** 2, p["I3"]
    fis = {f.name: f for f in m.first_integrals()}
    assert set(fis) == {"p_tip.phi", "p_tip.psi", "energy"}
    s = m.scene_settings
    r = simulate_symplectic(m.eom, s["stop_time"], method=s["method"], dt=s["dt"], points=s["points"])
    assert r.success
    th, phid, psid = r.q[:, 1], r.qd[:, 0], r.qd[:, 2]
    ppsi = I3 * (psid + phid * np.cos(th))
    pphi = A * phid * np.sin(th) ** 2 + ppsi * np.cos(th)
    assert r["p_tip.psi"] == pytest.approx(ppsi, rel=1e-9)
    assert r["p_tip.phi"] == pytest.approx(pphi, rel=1e-9)
    assert np.ptp(ppsi) < 1e-9 * abs(ppsi[0]) and np.ptp(pphi) < 1e-9 * abs(pphi[0])
    assert np.ptp(th) > 1e-3                           # it nutates


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
def test_kepler_model_scene():
    m = mechdsl.load(MODELS / "kepler.mech", scene="Orbits")
    fis = {f.name for f in m.first_integrals()}
    assert {"p_(fs.x+fp.x)", "p_(fs.y+fp.y)", "p_(fs.z+fp.z)", "energy",
            "L_(fs.x:fs.y+fp.x:fp.y)", "L_(fs.x:fs.z+fp.x:fp.z)", "L_(fs.y:fs.z+fp.y:fp.z)"} == fis
    s = m.scene_settings
    T = s["stop_time"] / 10
    sv = simulate_symplectic(m.eom, T, method="stormer-verlet", dt=s["dt"])
    rk = simulate_symplectic(m.eom, T, method="rk4", dt=4 * s["dt"])
    e_sv = np.abs(sv["energy"] - sv["energy"][0])
    e_rk = np.abs(rk["energy"] - rk["energy"][0])
    assert e_sv.max() <= 1.05 * e_sv[sv.t <= T / 5].max()
    assert e_rk[-1] >= 3 * e_rk[rk.t <= T / 5].max()
    assert np.ptp(sv["p_(fs.x+fp.x)"]) < 1e-14


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
def test_cli_equilibrium_and_linearize(tmp_path, capsys):
    out = tmp_path / "eq.json"
    assert main(["equilibrium", str(MODELS / "bead_on_hoop.mech"), "--model", "BeadOnHoopLagrange",
                 "-o", str(out)]) == 0
    text = capsys.readouterr().out
    assert "4 equilibria" in text and "stable" in text and "unstable" in text
    data = json.loads(out.read_text())
    assert data["count"] == 4
    j, c, pl = tmp_path / "lin.json", tmp_path / "modes.csv", tmp_path / "modes.png"
    assert main(["linearize", str(MODELS / "cart_pole.mech"), "-o", str(j), "--csv", str(c),
                 "--plot", str(pl), "--symbolic"]) == 0
    text = capsys.readouterr().out
    assert "divergent" in text and "K (stiffness)" in text and "symbolic" in text
    assert json.loads(j.read_text())["inputs"] == ["F"]
    assert c.read_text().startswith("mode,kind")
    assert pl.stat().st_size > 1000
    assert main(["linearize", str(MODELS / "pendulum.mech"), "--model", "PendulumLagrange", "--at",
                 "theta=0.3,der(theta)=0.1"]) == 0
    assert "about the state" in capsys.readouterr().out


def test_cli_usage_errors(capsys):
    assert main(["equilibrium", str(MODELS / "cart_pole.mech"), "--guess", "phi=1"]) == 2
    assert "unknown coordinate" in capsys.readouterr().err
    assert main(["linearize", str(MODELS / "cart_pole.mech"), "--at", "somewhere"]) == 2
    assert main(["equilibrium", str(MODELS / "cart_pole.mech"), "--guess", "theta=pi/"]) == 2
    assert main(["equilibrium", str(MODELS / "cart_pole.mech"), "-o", str(MODELS / "cart_pole.mech")]) == 2
