"""`mech linearize --guess` steers which equilibrium is used; "no equilibrium" says why (issue 11)."""
from __future__ import annotations

import math
import os

import pytest

from mechdsl.analysis.linearize import linearize
from mechdsl.cli import main

from ana_models import pendulum

MODELS = os.path.join(os.path.dirname(__file__), "..", "models")


def test_guess_steers_the_linearization():
    """Pendulum started at 0.5: without a guess the hanging position (w = sqrt(g/L)); with the
    guess theta = 3 the inverted one (divergent, rate sqrt(g/L))."""
    e = pendulum(q0=0.5)
    down = linearize(e)
    assert down.q[0] == pytest.approx(0.0, abs=1e-9)
    up = linearize(e, guesses={"theta": 3.0})
    assert abs(up.q[0]) == pytest.approx(math.pi, abs=1e-9)
    assert max(ev.real for ev in up.eigenvalues) == pytest.approx(math.sqrt(9.81), rel=1e-9)
    assert any("nearest to the guess" in n for n in up.notes)


def test_cli_guess_steers(capsys):
    path = os.path.join(MODELS, "pendulum.mech")
    assert main(["linearize", path, "--model", "Pendulum", "--guess", "theta=3"]) == 0
    out = capsys.readouterr().out
    assert "stability: unstable" in out


def test_kepler_says_why_there_is_no_equilibrium(capsys):
    rc = main(["linearize", os.path.join(MODELS, "kepler.mech")])
    err = capsys.readouterr().err
    assert rc == 1
    assert "error[E903]" in err
    assert "no static equilibrium" in err and "central attraction" in err
    assert "--at t=0" in err and "relative equilibrium" in err
