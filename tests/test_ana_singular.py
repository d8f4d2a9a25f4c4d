"""No LinAlgError escapes an analysis: a singular mass matrix is a coded diagnostic (E910)
naming the coordinate without inertia; gimbal lock with speeds is E911 (issue 11)."""
from __future__ import annotations

import os

import casadi as ca
import numpy as np
import pytest

from mechdsl import eom as E
from mechdsl.analysis.equilibrium import equilibria
from mechdsl.analysis.linearize import linearize
from mechdsl.cli import main
from mechdsl.diagnostics import MechError
import mechdsl.examples

MODELS = str(mechdsl.examples.folder())


def massless():
    """x has a mass, y none, but a spring acts on y: M is singular where a force acts."""
    q, qd, t, p = ca.SX.sym("q", 2), ca.SX.sym("qd", 2), ca.SX.sym("t"), ca.SX.sym("p", 1)
    T = 0.5 * qd[0] ** 2
    V = 0.5 * p[0] * (q[0] ** 2 + (q[1] - q[0]) ** 2)
    return E.from_lagrangian("Massless", ["x", "y"], ["k"], [4.0], q, qd, t, p, T, V, q0=[0.1, 0.2], qd0=[0, 0])


def test_equilibrium_with_a_singular_mass_matrix_is_undetermined():
    eqs = equilibria(massless())                  # before: LinAlgError
    assert len(eqs) == 1
    assert eqs[0].q == pytest.approx([0.0, 0.0], abs=1e-12)
    assert eqs[0].stable is None and "mass matrix is singular" in eqs[0].reason


@pytest.mark.parametrize("at", ["equilibrium", {"x": 0.1, "y": 0.3}])
def test_linearization_with_a_singular_mass_matrix_is_E910(at):
    with pytest.raises(MechError) as ex:
        linearize(massless(), at=at)
    d = ex.value.diagnostics[0]
    assert d.code == "E910" and "no inertia along y" in d.message


def test_gimbal_lock_with_speeds_is_E911(capsys):
    rc = main(["linearize", os.path.join(MODELS, "heavy_top.mech"), "--at", "tip.theta=0,der(tip.phi)=1"])
    assert rc == 1
    assert "error[E911]" in capsys.readouterr().err


def test_gimbal_lock_at_rest_is_linearized_in_a_quaternion_chart():
    from mechdsl.api import load

    e = load(os.path.join(MODELS, "heavy_top.mech")).eom
    lin = linearize(e, at={"tip.theta": 0.0})
    assert lin.kind == "equilibrium"
    assert lin.reduced_coords == ("tip.rx", "tip.ry", "tip.rz")
    assert any("gimbal lock" in n for n in lin.notes)
    mgl, A = 9.81 * 0.5, 0.12 + 0.25
    assert sorted(ev.real for ev in lin.eigenvalues)[-1] == pytest.approx(np.sqrt(mgl / A), rel=1e-9)


def test_gimbal_lock_with_an_angle_used_elsewhere_is_E908(tmp_path, capsys):
    """A potential on psi is no function of the rotation: the chart cannot be switched."""
    src = open(os.path.join(MODELS, "heavy_top.mech")).read()
    src = src.replace("end HeavyTop;", "equation\n  potential = 0.01*tip.psi^2;\nend HeavyTop;")
    f = tmp_path / "top_psi.mech"
    f.write_text(src)
    assert main(["equilibrium", str(f), "--model", "HeavyTop"]) == 1
    err = capsys.readouterr().err
    assert "error[E908]" in err and "tip.psi" in err
