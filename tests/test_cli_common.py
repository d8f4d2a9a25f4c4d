"""One `--set` grammar and one "which scene" line for every command (commands/_common.py)."""
from __future__ import annotations

import pytest

from conftest import MODELS
from mechdsl.cli import main

PENDULUM = str(MODELS / "pendulum.mech")          # has scenes: the first one applies by default
COMMANDS = [["equations"], ["equilibrium"], ["linearize"], ["simulate", "--t-end", "0.5", "--points", "3"]]


@pytest.mark.parametrize("cmd", COMMANDS, ids=lambda c: c[0])
def test_set_before_the_file_does_not_swallow_it(cmd, capsys):
    assert main([*cmd, "--set", "L=2", PENDULUM]) == 0, capsys.readouterr().err


@pytest.mark.parametrize("cmd", COMMANDS, ids=lambda c: c[0])
def test_both_set_forms_mean_the_same(cmd, capsys):
    assert main([*cmd, PENDULUM, "--set", "L=2", "--set", "m=3"]) == 0
    a = capsys.readouterr().out
    assert main([*cmd, PENDULUM, "--set", "L=2,m=3"]) == 0
    b = capsys.readouterr().out
    strip = [ln for ln in a.splitlines() if "s)" not in ln and "statistics" not in ln]   # timings differ
    assert strip == [ln for ln in b.splitlines() if "s)" not in ln and "statistics" not in ln]


@pytest.mark.parametrize("cmd", COMMANDS, ids=lambda c: c[0])
def test_every_command_says_which_scene_it_used(cmd, capsys):
    assert main([*cmd, PENDULUM]) == 0
    out = capsys.readouterr().out
    assert "scene Swing of model Pendulum (the file's first scene" in out
    assert main([*cmd, PENDULUM, "--scene", "Swing"]) == 0
    out = capsys.readouterr().out
    assert "scene Swing of model Pendulum" in out and "first scene" not in out
    assert main([*cmd, PENDULUM, "--model", "Pendulum"]) == 0
    assert "model Pendulum (no scene)" in capsys.readouterr().out


def test_set_changes_the_analysis(capsys):
    """L = 2 halves the pendulum's w^2 = g/L (closed form), in every form of --set."""
    assert main(["linearize", "--set", "L=2,g=9.81", PENDULUM, "--model", "Pendulum"]) == 0
    out = capsys.readouterr().out
    assert f"{(9.81 / 2) ** 0.5:.6g}" in out


@pytest.mark.parametrize("bad", ["L", "=2", "L=abc", "L=9**9**9", "L=inf", "nosuch=1"])
def test_bad_set_is_a_usage_error(bad, capsys):
    assert main(["equilibrium", PENDULUM, "--set", bad]) == 2
    err = capsys.readouterr().err
    assert "mech: error:" in err and "Traceback" not in err


def test_guess_steers_linearize_grammar(capsys):
    """--guess takes one NAME=VALUE[,...] per option (it must not swallow FILE either)."""
    assert main(["linearize", "--guess", "theta=3", PENDULUM, "--model", "Pendulum"]) == 0
    capsys.readouterr()


NO_REST = """model Slope
  parameter Real m(unit = "kg") = 1;
  parameter Real V0(unit = "J") = 1;
  parameter Real a(unit = "m") = 1;
  coordinate Real x(start = 0, unit = "m");
equation
  kinetic = 1/2*m*der(x)^2;
  potential = V0*exp(-x/a);
end Slope;
"""


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
def test_a_later_phase_error_is_located_at_the_model(tmp_path, capsys):
    """E903 (no equilibrium: V0 exp(-x/a) has no rest state) carries no position of its own:
    the command locates it at the model it worked on, so the error reads file:line:col."""
    f = tmp_path / "slope.mech"
    f.write_text(NO_REST)
    assert main(["linearize", str(f)]) == 1
    err = capsys.readouterr().err
    assert f"{f}:1:1: error[E903]" in err and "model Slope" in err
