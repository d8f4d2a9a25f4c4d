"""Consistent initialization: fixed start values held, free ones solved, changes reported."""
import numpy as np
import pytest

from dae_models import andrews_eom, bricard_eom, crank_rocker_eom, pendulum_eom
from mechdsl.dae import check_report, initialize, simulate_dae
from mechdsl.diagnostics import MechError


def test_consistent_start_changes_nothing():
    rep = initialize(andrews_eom())
    assert rep.changes == []
    assert rep.position_residual < 1e-15


def test_free_position_and_speed_are_solved_and_reported():
    e = pendulum_eom(x0=(0.6, -0.5), v0=(0.3, 0.0))
    e = e.replace(fixed_q=(True, False), fixed_qd=(True, False))       # x held, y free
    rep = initialize(e)
    assert rep.q[0] == 0.6 and rep.q[1] == pytest.approx(-0.8, abs=1e-14)
    # velocity tangent to the circle: x vx + y vy = 0 -> vy = -x vx / y
    assert rep.qd[1] == pytest.approx(-0.6 * 0.3 / -0.8, abs=1e-14)
    kinds = {(c.name, c.kind): c for c in rep.changes}
    assert set(kinds) == {("y", "start"), ("y", "speed")}
    assert kinds[("y", "start")].change == pytest.approx(-0.3, abs=1e-14)
    assert "y: -0.5 -> -0.8" in str(kinds[("y", "start")])


def test_initialization_is_in_result_metadata():
    e = pendulum_eom(x0=(0.6, -0.5), v0=(0.0, 0.0))
    e = e.replace(fixed_q=(True, False))
    r = simulate_dae(e, 0.1, points=3)
    ch = r.metadata["initialization"]["changes"]
    assert [c["name"] for c in ch] == ["y"] and ch[0]["after"] == pytest.approx(-0.8)
    assert r.q[0, 1] == pytest.approx(-0.8)


def test_all_fixed_and_inconsistent_is_a_diagnostic_naming_the_constraint():
    e = pendulum_eom(x0=(0.6, -0.5))
    with pytest.raises(MechError) as info:
        initialize(e)
    d = info.value.first
    assert d.code == "E821" and "'rod'" in d.message and "fixed" in d.help


def test_unreachable_start_names_the_constraint():
    e = pendulum_eom(x0=(2.0, 0.0))          # x = 2 beyond the rod length, y free
    e = e.replace(fixed_q=(True, False))
    with pytest.raises(MechError) as info:
        initialize(e)
    assert info.value.first.code == "E821" and "'rod'" in info.value.first.message


def test_inconsistent_fixed_speeds_are_a_diagnostic():
    e = pendulum_eom(x0=(1.0, 0.0), v0=(1.0, 0.0))    # radial velocity, both fixed
    with pytest.raises(MechError) as info:
        initialize(e)
    assert info.value.first.code == "E822" and "'rod'" in info.value.first.message


def test_loop_closure_from_approximate_start():
    e = crank_rocker_eom()           # th2, th3 start values are rough guesses
    rep = initialize(e)
    names = [c.name for c in rep.changes if c.kind == "start"]
    assert names == ["th2", "th3"]
    assert rep.position_residual < 1e-13 and rep.velocity_residual < 1e-12


def test_redundant_constraints_initialize():
    rep = initialize(bricard_eom())      # 5 constraints of rank 4; only J1 speed fixed
    assert rep.velocity_residual < 1e-13
    assert rep.qd[0] == pytest.approx(1.0, abs=1e-13)


def test_check_report_lines():
    lines = check_report(bricard_eom())
    text = "\n".join(lines)
    assert "degrees of freedom: 1" in text and "redundant constraints: 1" in text
    bad = pendulum_eom(x0=(0.6, -0.5))
    assert any(line.startswith("error[E821]") for line in check_report(bad))
