"""mech check / mech compile on the shipped models: clean, deterministic, never a traceback."""
import os
import subprocess
import sys

import pytest

from mechdsl.cli import main

from conftest import MODELS, model_files


@pytest.mark.slow_cases('nfourbar.mech')  # CPU budget: the cheaper tests of this file stay in the default run
@pytest.mark.parametrize("path", model_files(), ids=lambda p: p.name)
def test_check_passes(path, capsys):
    assert main(["check", str(path)]) == 0
    out = capsys.readouterr().out
    assert "ok" in out and "->" in out


def test_check_reports_formulation(capsys):
    assert main(["check", str(MODELS / "double_pendulum.mech")]) == 0
    out = capsys.readouterr().out
    assert "DoublePendulum: 2 bodies, 2 joints, 2 coordinates, tree -> ODE in minimal coordinates" in out
    assert main(["check", str(MODELS / "pendulum_cartesian.mech")]) == 0
    out = capsys.readouterr().out
    assert "1 explicit constraint, 1 constraint equation -> DAE with multipliers" in out     # (one, not "equations")


@pytest.mark.slow_cases('nfourbar.mech-model')  # CPU budget: the cheaper tests of this file stay in the default run
@pytest.mark.parametrize("emit", ["ast", "model", "source"])
@pytest.mark.parametrize("path", model_files(), ids=lambda p: p.name)
def test_emit_is_deterministic(path, emit, capsys):
    assert main(["compile", str(path), "--emit", emit]) == 0
    first = capsys.readouterr().out
    assert main(["compile", str(path), "--emit", emit]) == 0
    assert capsys.readouterr().out == first


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
@pytest.mark.parametrize("emit, shows", [("model", "q[3]"), ("eom", "M[q[3],q[1]] = ")])
def test_emit_is_identical_across_processes(emit, shows):
    """Two processes with different hash seeds (set iteration order) print the same bytes."""
    path = str(MODELS / "nlink_pendulum.mech")
    outs = [subprocess.run([sys.executable, "-m", "mechdsl", "compile", path, "--emit", emit],
                           capture_output=True, text=True, check=True,
                           env={**os.environ, "PYTHONHASHSEED": seed}).stdout for seed in ("1", "4711")]
    assert outs[0] == outs[1] and shows in outs[0]


def test_usage_errors_exit_2(capsys):
    assert main(["check"]) == 2
    assert main(["no-such-command"]) == 2
    assert main([]) == 2


def test_model_error_exit_1(tmp_path, capsys):
    f = tmp_path / "bad.mech"
    f.write_text("model A\n  parameter Real x = y;\nend A;\n")
    assert main(["check", str(f)]) == 1
    err = capsys.readouterr().err
    assert f"{f}:2:22: error[E201]: undefined name 'y'" in err
    assert "^" in err
