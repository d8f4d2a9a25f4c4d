"""`mech linearize --guess` steers which equilibrium is used; "no equilibrium" says why (issue 11)."""
from __future__ import annotations

import math
import os

import pytest

from mechdsl.analysis.linearize import linearize
from mechdsl.cli import main

from ana_models import pendulum
import mechdsl.examples

MODELS = str(mechdsl.examples.folder())


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


def test_a_force_that_decays_without_vanishing_has_no_equilibrium():
    """V = V0 exp(-x): the force V0 exp(-x) never vanishes; every search runs off to large x."""
    import casadi as ca

    from mechdsl import eom as E
    from mechdsl.diagnostics import MechError

    q, qd, t, p = ca.SX.sym("q", 1), ca.SX.sym("qd", 1), ca.SX.sym("t"), ca.SX.sym("p", 1)
    e = E.from_lagrangian("Decay", ["x"], ["V0"], [2.0], q, qd, t, p, 0.5 * qd[0] ** 2,
                          p[0] * ca.exp(-q[0]), q0=[0.5], qd0=[0.0])
    with pytest.raises(MechError) as ex:
        linearize(e)
    d = ex.value.diagnostics[0]
    assert d.code == "E903"
    assert "ran off" in d.message and "no static equilibrium" in d.message
    assert "--at t=0" in d.help


@pytest.mark.slow
def test_kepler_says_why_there_is_no_equilibrium(capsys):
    rc = main(["linearize", os.path.join(MODELS, "kepler.mech")])
    err = capsys.readouterr().err
    assert rc == 1
    assert "error[E903]" in err
    assert "no static equilibrium" in err and "central attraction" in err
    assert "--at t=0" in err and "relative equilibrium" in err
