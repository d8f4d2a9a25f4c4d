"""``mech compile --emit problem`` of every shipped model against committed golden text
(tests/golden/<model>.problem.txt).  Regenerate after an intended change with
``MECHDSL_UPDATE_GOLDEN=1 python -m pytest tests/test_golden_problem.py -m 'slow or not slow'``
and read the diff: it shows what a run of each model would solve."""
from __future__ import annotations

import os
from pathlib import Path

import pytest

from mechdsl.cli import main

ROOT = Path(__file__).resolve().parent.parent
GOLDEN = ROOT / "tests" / "golden"
MODELS = sorted(p.name for p in (ROOT / "models").glob("*.mech"))
FAST = ("double_pendulum.mech", "pendulum_cartesian.mech", "bouncing_ball.mech", "heavy_top.mech")


def _check(name, capsys):
    assert main(["compile", str(ROOT / "models" / name), "--emit", "problem"]) == 0
    text = capsys.readouterr().out
    path = GOLDEN / (name[:-5] + ".problem.txt")
    if os.environ.get("MECHDSL_UPDATE_GOLDEN"):
        path.write_text(text)
    assert path.is_file(), f"no golden file {path.name}: run with MECHDSL_UPDATE_GOLDEN=1"
    assert text == path.read_text()


@pytest.mark.parametrize("name", FAST)
def test_problem_dump_matches_golden(name, capsys):
    _check(name, capsys)


@pytest.mark.slow
@pytest.mark.parametrize("name", [m for m in MODELS if m not in FAST])
def test_problem_dump_matches_golden_every_model(name, capsys):
    _check(name, capsys)


def test_kinds_of_the_shipped_models():
    kinds = {name: (GOLDEN / (name[:-5] + ".problem.txt")).read_text().splitlines()[1].split()[1]
             for name in FAST}
    assert kinds == {"double_pendulum.mech": "ode", "pendulum_cartesian.mech": "dae",
                     "bouncing_ball.mech": "hybrid", "heavy_top.mech": "canonical"}
