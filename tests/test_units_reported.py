"""Values are held in SI, so every place that labels them says the SI unit: a coordinate
declared in "deg" is reported in rad, "cm" in m (the CSV's sidecar, --json, tables, the model)."""
import json
import math

import pytest

import mechdsl
from mechdsl.cli import main
from mechdsl.model.units import parse_unit, si_unit

MODEL = """model P
  parameter Real m(unit = "g") = 1000;
  parameter Real L(unit = "m") = 1;
  parameter Real g(unit = "m/s2") = 9.81;
  parameter Real k(unit = "N/m") = 100;
  coordinate Real theta(start = 30, speed = 0, unit = "deg");
  coordinate Real x(start = 0.1, speed = 0, unit = "cm");
  output Real v(unit = "km/h") = der(x);
equation
  kinetic = 1/2*m*L^2*der(theta)^2 + 1/2*m*der(x)^2;
  potential = -m*g*L*cos(theta) + 1/2*k*x^2;
end P;
"""


@pytest.mark.parametrize("unit, si", [
    ("deg", "rad"), ("deg/s", "rad/s"), ("deg/s2", "rad/s2"), ("cm", "m"), ("mm2", "m2"), ("g", "kg"),
    ("g.cm2", "kg.m2"), ("km/h", "m/s"), ("cm/min", "m/s"), ("kN.m", "N.m"), ("rpm", "rad/s"),
    ("turn", "rad"), ("ft", "m"),
    # SI already: as written
    ("rad", "rad"), ("kg", "kg"), ("N.m/rad", "N.m/rad"), ("m/s2", "m/s2"), ("", ""), (None, ""),
])
def test_si_unit(unit, si):
    assert si_unit(unit) == si
    if unit:   # the same dimension, factor 1
        f, d = parse_unit(si)
        assert f == pytest.approx(1.0, rel=1e-12) and d == parse_unit(unit)[1]


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
def test_a_model_declared_in_deg_and_cm_reports_rad_and_m(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "p.mech").write_text(MODEL)
    m = mechdsl.load("p.mech")
    # the model keeps the declared units (fit and sensitivities convert to them); what shows SI
    # values says the SI unit
    assert {c.name: c.unit for c in m.model.coordinates} == {"theta": "deg", "x": "cm"}
    assert m.model.parameters[0].value == pytest.approx(1.0) and m.model.parameters[0].unit == "g"
    from mechdsl.output.display import _model_parts

    params = _model_parts(m)[3]
    # the model's own table shows each value in its declared unit, with that unit (issue 23)
    assert params[0][:3] == ["m", pytest.approx(1000.0), "g"]
    from mechdsl.export.variables import unit_definition

    assert unit_definition(si_unit("deg"))[1] == 1.0
    assert main(["simulate", "p.mech", "--t-end", "0.1", "--points", "3", "-o", "p.csv"]) == 0
    side = json.loads((tmp_path / "p.json").read_text())
    assert side["units"]["theta"] == "rad" and side["units"]["x"] == "m"
    assert side["units"]["der(theta)"] == "rad/s" and side["units"]["v"] == "m/s"
    row = (tmp_path / "p.csv").read_text().splitlines()[1].split(",")
    first = dict(zip(side["columns"], map(float, row)))
    assert first["theta"] == pytest.approx(math.pi / 6, rel=1e-12)      # 30 deg in rad
    assert first["x"] == pytest.approx(1e-3, rel=1e-12)                 # 0.1 cm in m
    capsys.readouterr()
    assert main(["equilibrium", "p.mech"]) == 0
    out = capsys.readouterr().out
    assert "theta [rad]" in out and "x [m]" in out and "[deg]" not in out and "[cm]" not in out


def test_linear_model_and_equilibria_say_their_units(capsys):
    """The cart-pole mixes m and rad: M, C, K have no single unit (said once), the modes' eigenvalues
    are in 1/s; the pendulum (all rad) has M in kg.m2, K and the Hessian of V in N.m/rad, and its
    K is m g L = 9.81 N.m/rad (the model's m = 1 kg, L = 1 m)."""
    from mechdsl.examples import path

    assert main(["linearize", str(path("cart_pole"))]) == 0
    out = capsys.readouterr().out
    assert "x = 0 m, theta = 0 rad" in out and "eigenvalue (1/s)" in out
    assert "the coordinates' units differ" in out and "K (stiffness):" in out
    assert "linearization has eigenvalue 3.97388 1/s with positive real part" in out
    assert main(["linearize", str(path("pendulum")), "--model", "Pendulum"]) == 0
    out = capsys.readouterr().out
    assert "M (mass) [kg.m2]:" in out and "C (damping + gyroscopic) [N.m.s/rad]:" in out
    k_line = out.split("K (stiffness) [N.m/rad]:")[1].splitlines()[2].split()
    assert k_line[0] == "theta" and float(k_line[1]) == pytest.approx(9.81, rel=1e-9)
    assert main(["equilibrium", str(path("pendulum")), "--model", "Pendulum"]) == 0
    out = capsys.readouterr().out
    assert "Hessian eigenvalues [N.m/rad]" in out and "(eigenvalues [9.81] N.m/rad)" in out


@pytest.mark.parametrize("units, expected", [
    (["rad", "deg"], {"M": "kg.m2", "C": "N.m.s/rad", "K": "N.m/rad"}),
    (["m", "cm"], {"M": "kg", "C": "N.s/m", "K": "N/m"}),
    (["m", "rad"], {}), (["m", ""], {}), ([], {}),
])
def test_matrix_units(units, expected):
    from mechdsl.model.units import matrix_units

    assert matrix_units(units) == expected


def test_accelerated_reference_motion_says_its_unit(capsys):
    """The dropped ball: no rest state, a uniformly accelerated reference motion at -g in m/s2."""
    from mechdsl.examples import path

    assert main(["equilibrium", str(path("bouncing_ball"))]) == 0
    out = capsys.readouterr().out
    assert "with acceleration a = drop.s: -9.81 m/s2" in out


def test_a_fixed_step_run_says_its_step_not_tolerances(tmp_path, monkeypatch, capsys):
    """Stormer-Verlet takes no rtol/atol: the summary says the step it took, in s."""
    from mechdsl.examples import path

    monkeypatch.chdir(tmp_path)
    assert main(["simulate", str(path("pendulum")), "--method", "stormer-verlet", "--dt", "0.01",
                 "--t-end", "0.5"]) == 0
    ran = [ln for ln in capsys.readouterr().out.splitlines() if ln.startswith("ran: ")]
    assert len(ran) == 1 and ran[0].endswith("step dt 0.01 s") and "rtol" not in ran[0]


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
def test_json_of_equilibrium_and_linearize_carries_units(tmp_path, capsys):
    """--json and -o OUT.json: each coordinate's unit, and the unit of the Hessian / M, C, K."""
    from cli_json import validate
    from mechdsl.examples import path

    pend = str(path("pendulum"))
    assert main(["equilibrium", pend, "--model", "Pendulum", "--json", "-o", str(tmp_path / "e.json")]) == 0
    doc = json.loads(capsys.readouterr().out)
    validate(doc)
    assert doc["result"]["units"] == {"theta": "rad"} and doc["result"]["hessian_unit"] == "N.m/rad"
    assert json.loads((tmp_path / "e.json").read_text())["units"] == {"theta": "rad"}
    assert main(["linearize", str(path("cart_pole")), "--json", "-o", str(tmp_path / "l.json")]) == 0
    doc = json.loads(capsys.readouterr().out)
    validate(doc)
    assert doc["result"]["units"] == {"x": "m", "theta": "rad"} and doc["result"]["matrix_units"] == {}
    saved = json.loads((tmp_path / "l.json").read_text())
    assert saved["units"] == {"x": "m", "theta": "rad"}
