"""`mech simulate` end to end on real model files (written to a temporary folder)."""
from __future__ import annotations

import json

import numpy as np
import pytest

from mechdsl.cli import main

PENDULUM = """model Pendulum
  parameter Real m(unit = "kg") = 1;
  parameter Real L(unit = "m") = 1;
  parameter Real g(unit = "m/s2") = 9.81;
  coordinate Real theta(start = 0.5, unit = "rad");
  output Real x = L*sin(theta);
  output Real y = -L*cos(theta);
equation
  kinetic = 1/2*m*L^2*der(theta)^2;
  potential = -m*g*L*cos(theta);
end Pendulum;

scene Swing
  model Pendulum;
  stop_time = 2;
  points = 11;
  outputs = {x};
end Swing;
"""

# T = m u'^2/2, V = -k u^4/4: u'' = u^3.  From u = 1, u' = 1/sqrt(2): u = 1/(1 - t/sqrt(2)),
# infinite at t = sqrt(2).
BLOWUP = """model Blowup
  parameter Real m(unit = "kg") = 1;
  parameter Real k(unit = "N/m3") = 1;
  coordinate Real u(start = 1, speed = 1/sqrt(2), unit = "m");
equation
  kinetic = 1/2*m*der(u)^2;
  potential = -k*u^4/4;
end Blowup;
"""


@pytest.fixture
def files(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "pendulum.mech").write_text(PENDULUM)
    (tmp_path / "blowup.mech").write_text(BLOWUP)
    return tmp_path


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
def test_simulate_writes_csv_json_plot_and_summary(tmp_path, files, capsys):
    out, png = tmp_path / "p.csv", tmp_path / "p.png"
    code = main(["simulate", "pendulum.mech", "--model", "Pendulum", "--t-end", "1", "--points", "6", "-o", str(out),
                 "--plot", str(png), "--set", "L=2", "--set", "theta.start=pi/4", "--no-progress"])
    text = capsys.readouterr().out
    assert code == 0
    assert "method: dop853 (not stiff" in text and "energy drift" in text and f"wrote {out}" in text
    lines = out.read_text().splitlines()
    assert lines[0].startswith("time,theta,der(theta),x,y,kinetic_energy") and len(lines) == 7
    first = [float(v) for v in lines[1].split(",")]
    assert first[1] == pytest.approx(np.pi / 4) and first[3] == pytest.approx(2 * np.sin(np.pi / 4))
    meta = json.loads((tmp_path / "p.json").read_text())["metadata"]
    assert meta["options"]["parameters"]["L"] == 2.0 and meta["source"] == "pendulum.mech"
    assert png.read_bytes().startswith(b"\x89PNG")


def test_scene_settings_are_used(tmp_path, files, capsys):
    out = tmp_path / "s.csv"
    assert main(["simulate", "pendulum.mech", "--scene", "Swing", "-o", str(out)]) == 0
    assert "scene Swing of model Pendulum" in capsys.readouterr().out
    lines = out.read_text().splitlines()
    assert len(lines) == 12 and lines[0].split(",")[3] == "x" and "y" not in lines[0].split(",")
    assert float(lines[-1].split(",")[0]) == pytest.approx(2.0, rel=1e-14)


def test_failure_exits_1_and_keeps_partial_results(tmp_path, files, capsys):
    out = tmp_path / "b.csv"
    code = main(["simulate", "blowup.mech", "--t-end", "3", "--points", "31", "-o", str(out)])
    text = capsys.readouterr().out
    assert code == 1
    assert "FAILED at t = 1.414" in text and "solution blows up" in text
    assert len(out.read_text().splitlines()) == 1 + 15
    assert json.loads((tmp_path / "b.json").read_text())["failure"]["cause"] == "solution blows up"


def test_usage_errors_exit_2_without_traceback(tmp_path, files, capsys):
    assert main(["simulate", "pendulum.mech", "--set", "theta"]) == 2
    assert "NAME=VALUE" in capsys.readouterr().err
    assert main(["simulate", "pendulum.mech", "--set", "thetaa.start=1"]) == 2
    assert "did you mean 'theta'" in capsys.readouterr().err
    assert main(["simulate", "pendulum.mech", "--set", "m=abc"]) == 2
    assert main(["simulate", "pendulum.mech", "--method", "rk5"]) == 2
    assert "unknown method" in capsys.readouterr().err
    out = tmp_path / "x.csv"
    out.write_text("mine")
    assert main(["simulate", "pendulum.mech", "-o", str(out)]) == 2
    assert "--force" in capsys.readouterr().err and out.read_text() == "mine"
    assert main(["simulate", "pendulum.mech", "--t-end", "1", "-o", str(out), "--force"]) == 0


def test_value_expressions():
    from mechdsl.commands._common import assignments, number, split_starts
    from mechdsl.diagnostics import UsageError

    assert number("pi/4") == pytest.approx(np.pi / 4)
    assert number("2^3") == pytest.approx(8) and number("-deg(180)") == pytest.approx(-np.pi)
    assert split_starts(assignments(["m=2", "a.b.start=1,q.speed=-1"])) == \
        ({"m": 2.0}, {"a.b": 1.0, "der(q)": -1.0})
    assert assignments(["x=atan(1),y=sqrt(4)"]) == pytest.approx({"x": np.pi / 4, "y": 2.0})
    for bad in ("__import__('os')", "1+", "x", "9**9**9", "inf", "1e400", "0/0", "(-1)^0.5", "1" * 300):
        with pytest.raises(UsageError):
            number(bad)
