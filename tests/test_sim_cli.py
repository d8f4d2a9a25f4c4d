"""`mech simulate` against a stand-in for the lead's mechdsl.api (load -> Model with .eom).

The stand-in implements only the interface the command relies on: load(path, model, scene)
returning an object with .eom, .scene_settings, .parameter_values and .with_params(**kw).
"""
from __future__ import annotations

import json
import sys
import types

import numpy as np
import pytest

from mechdsl.cli import main
from sim_models import blowup, pendulum


class FakeModel:
    def __init__(self, eom, settings=None, values=None):
        self.eom = eom
        self.scene_settings = dict(settings or {})
        self.parameter_values = np.array(eom.param_values if values is None else values, float)

    def with_params(self, **kw):
        v = self.parameter_values.copy()
        for k, x in kw.items():
            v[self.eom.params.index(k)] = x
        return FakeModel(self.eom, self.scene_settings, v)


@pytest.fixture
def fake_api(monkeypatch):
    calls = []
    registry = {"pendulum.mech": lambda scene: FakeModel(
        pendulum(), {"stop_time": 2.0, "points": 11, "outputs": ("x",)} if scene == "Swing" else {}),
        "blowup.mech": lambda scene: FakeModel(blowup())}
    mod = types.ModuleType("mechdsl.api")

    def load(path, model=None, scene=None):
        calls.append((path, model, scene))
        return registry[str(path).split("/")[-1]](scene)

    mod.load = load
    monkeypatch.setitem(sys.modules, "mechdsl.api", mod)
    return calls


def test_simulate_writes_csv_json_plot_and_summary(tmp_path, fake_api, capsys):
    out, png = tmp_path / "p.csv", tmp_path / "p.png"
    code = main(["simulate", "pendulum.mech", "--t-end", "1", "--points", "6", "-o", str(out),
                 "--plot", str(png), "--set", "L=2", "--set", "theta.start=pi/4", "--no-progress"])
    text = capsys.readouterr().out
    assert code == 0
    assert "method: erk (not stiff" in text and "energy drift" in text and f"wrote {out}" in text
    lines = out.read_text().splitlines()
    assert lines[0].startswith("time,theta,der(theta),x,y,kinetic_energy") and len(lines) == 7
    first = [float(v) for v in lines[1].split(",")]
    assert first[1] == pytest.approx(np.pi / 4) and first[3] == pytest.approx(2 * np.sin(np.pi / 4))
    meta = json.loads((tmp_path / "p.json").read_text())["metadata"]
    assert meta["options"]["parameters"]["L"] == 2.0 and meta["source"] == "pendulum.mech"
    assert png.read_bytes().startswith(b"\x89PNG")


def test_scene_settings_are_used(tmp_path, fake_api, capsys):
    out = tmp_path / "s.csv"
    assert main(["simulate", "pendulum.mech", "--scene", "Swing", "-o", str(out)]) == 0
    assert fake_api[-1] == ("pendulum.mech", None, "Swing")
    lines = out.read_text().splitlines()
    assert len(lines) == 12 and lines[0].split(",")[3] == "x" and "y" not in lines[0].split(",")
    assert float(lines[-1].split(",")[0]) == pytest.approx(2.0, rel=1e-14)


def test_failure_exits_1_and_keeps_partial_results(tmp_path, fake_api, capsys):
    out = tmp_path / "b.csv"
    code = main(["simulate", "blowup.mech", "--t-end", "3", "--points", "31", "-o", str(out)])
    text = capsys.readouterr().out
    assert code == 1
    assert "FAILED at t = 1.414" in text and "solution blows up" in text
    assert len(out.read_text().splitlines()) == 1 + 15
    assert json.loads((tmp_path / "b.json").read_text())["failure"]["cause"] == "solution blows up"


def test_usage_errors_exit_2_without_traceback(tmp_path, fake_api, capsys):
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
    from mechdsl.commands.simulate import eval_number, parse_sets

    assert eval_number("pi/4") == pytest.approx(np.pi / 4)
    assert eval_number("2^3") == 8 and eval_number("-deg(180)") == pytest.approx(-np.pi)
    assert parse_sets(["m=2", "a.b.start=1", "q.speed=-1"]) == ({"m": 2.0}, {"a.b": 1.0, "der(q)": -1.0})
    from mechdsl.diagnostics import UsageError

    for bad in ("__import__('os')", "1+", "x"):
        with pytest.raises(UsageError):
            eval_number(bad)
