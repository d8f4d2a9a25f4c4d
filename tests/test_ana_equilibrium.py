"""Equilibria and their stability against closed forms (hand-built EOMs, CasADi SX)."""
import math

import numpy as np
import pytest

import ana_models as am
from mechdsl.analysis.equilibrium import equilibria
from mechdsl.diagnostics import UsageError


def by_values(eqs, **vals):
    for e in eqs:
        if all(abs(math.remainder(e[k] - v, 2 * math.pi)) < 1e-7 for k, v in vals.items()):
            return e
    raise AssertionError(f"no equilibrium at {vals}: {[e.values for e in eqs]}")


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
def test_double_pendulum_four_equilibria_and_hessians():
    m, l, g = 1.3, 0.7, 9.81
    eqs = equilibria(am.double_pendulum(m, l, g))
    assert len(eqs) == 4
    assert all(e.kind == "static" for e in eqs)
    down = by_values(eqs, th1=0, th2=0)
    assert down.stable is True
    # V = -m g l (2 cos th1 + cos th2): Hessian diag(2 m g l, m g l) at the bottom
    assert np.allclose(down.hessian_eigenvalues, [m * g * l, 2 * m * g * l], rtol=1e-10)
    for vals in ({"th1": 0, "th2": math.pi}, {"th1": math.pi, "th2": 0}, {"th1": math.pi, "th2": math.pi}):
        e = by_values(eqs, **vals)
        assert e.stable is False and e.hessian_eigenvalues[0] < 0
    # angles are reported in (-pi, pi]
    assert all(-math.pi < v <= math.pi for e in eqs for v in e.q)


@pytest.mark.parametrize("w", [5.0, 7.0])
def test_hoop_fast_spin_off_axis_equilibrium(w):
    R, g = 0.8, 9.81
    assert w ** 2 * R > g
    eqs = equilibria(am.hoop(R=R, g=g, w=w))
    th0 = math.acos(g / (w ** 2 * R))
    assert all(e.kind == "relative" for e in eqs)
    assert sorted(round(e["theta"], 8) for e in eqs) == sorted(round(v, 8) for v in (-th0, 0.0, th0, math.pi))
    off = by_values(eqs, theta=th0)
    assert off.stable is True
    # Hessian of V - T0 = -m g R cos th - m R^2 w^2 sin^2 th / 2 at th0: m R^2 w^2 sin^2 th0
    assert off.hessian_eigenvalues[0] == pytest.approx(R ** 2 * w ** 2 * math.sin(th0) ** 2, rel=1e-9)
    bottom = by_values(eqs, theta=0.0)
    assert bottom.stable is False           # the bottom becomes unstable
    assert bottom.hessian_eigenvalues[0] == pytest.approx(g * R - R ** 2 * w ** 2, rel=1e-9)
    assert "V - T0" in off.reason


def test_hoop_slow_spin_bottom_stable():
    R, g, w = 1.0, 9.81, 2.0
    eqs = equilibria(am.hoop(R=R, g=g, w=w))
    assert sorted(round(e["theta"], 8) for e in eqs) == [0.0, round(math.pi, 8)]
    assert by_values(eqs, theta=0).stable is True
    assert by_values(eqs, theta=math.pi).stable is False


def test_two_masses_accelerated_reference():
    m, k, l0, F = 2.0, 50.0, 1.0, 3.0
    eqs = equilibria(am.two_masses(m, k, l0, F), guesses={"x1": 0.0, "x2": 1.0})
    assert len(eqs) == 1
    e = eqs[0]
    assert e.kind == "accelerated-reference"
    assert e.acceleration == pytest.approx([F / (2 * m), F / (2 * m)], rel=1e-10)
    assert e["x2"] - e["x1"] - l0 == pytest.approx(F / (2 * k), rel=1e-9)
    assert e.stable is True
    assert e.hessian_eigenvalues == pytest.approx([2 * k], rel=1e-10)   # relative coordinate only
    assert e.symmetry_directions.shape == (2, 1)
    # the reference passes through the start configuration's centre of mass
    assert (e["x1"] + e["x2"]) / 2 == pytest.approx(l0 / 2, abs=1e-12)


def test_two_masses_without_force_is_a_static_family():
    eqs = equilibria(am.two_masses(F=0.0))
    assert len(eqs) == 1 and eqs[0].kind == "static"
    assert np.allclose(eqs[0].acceleration, 0)
    assert eqs[0]["x2"] - eqs[0]["x1"] == pytest.approx(1.0)


def test_damped_loaded_pendulum_equilibrium():
    m, L, g, F = 1.0, 0.8, 9.81, 4.0
    eqs = equilibria(am.pendulum(m=m, L=L, g=g, c=0.3, F=F))
    th = math.atan2(F, m * g)
    e = by_values(eqs, theta=th)
    assert e.stable is True
    # geometric stiffness of the loaded equilibrium: L sqrt((m g)^2 + F^2)
    assert e.hessian_eigenvalues[0] == pytest.approx(L * math.hypot(m * g, F), rel=1e-9)
    assert by_values(eqs, theta=th + math.pi).stable is False


def test_gyroscopic_stabilization_is_undetermined():
    # V_eff Hessian diag(k - m W^2, -k - m W^2) = (-3, -5): both negative, gyroscopic terms
    eqs = equilibria(am.rotating_saddle(m=1.0, k=1.0, W=2.0))
    assert len(eqs) == 1
    e = eqs[0]
    assert e.hessian_eigenvalues == pytest.approx([-5.0, -3.0])
    assert e.stable is None and "gyroscopic" in e.reason
    # lambda^4 + 8 lambda^2 + 15 = 0: purely imaginary
    assert np.max(np.abs(e.linear_eigenvalues.real)) < 1e-9
    assert sorted(np.round(np.abs(e.linear_eigenvalues.imag) ** 2, 9)) == [3, 3, 5, 5]


def test_one_negative_eigenvalue_with_gyroscopic_terms_is_unstable():
    eqs = equilibria(am.rotating_saddle(m=1.0, k=1.0, W=0.5))   # diag(0.75, -1.25)
    assert eqs[0].stable is False


def test_zero_hessian_is_undetermined():
    eqs = equilibria(am.quartic())
    assert len(eqs) == 1 and eqs[0]["x"] == pytest.approx(0, abs=1e-4)
    assert eqs[0].stable is None and "zero eigenvalue" in eqs[0].reason


def test_time_dependent_forcing_is_not_decided():
    eqs = equilibria(am.pendulum(A=0.5, w=2.0), t=0.0)     # forcing vanishes at t = 0
    assert eqs and all(e.stable is None for e in eqs)
    assert "time" in eqs[0].notes[0]


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
def test_user_guesses_and_errors():
    eom = am.double_pendulum()
    eqs = equilibria(eom, guesses=[{"th1": 3.0}, np.array([0.1, 3.0])])
    assert len(eqs) == 4
    with pytest.raises(UsageError, match="th3"):
        equilibria(eom, guesses={"th3": 1.0})
    with pytest.raises(UsageError):
        equilibria(eom, guesses=[np.zeros(3)])


def test_parameter_override_and_determinism():
    eom = am.hoop(w=5.0)
    a = equilibria(eom, p={"w": 2.0})
    assert len(a) == 2
    b = equilibria(eom)
    c = equilibria(eom)
    assert len(b) == 4 and [e.q.tolist() for e in b] == [e.q.tolist() for e in c]
    d = b[0].to_dict()
    assert d["stability"] in ("stable", "unstable", "undetermined") and "values" in d
