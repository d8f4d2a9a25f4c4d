"""Linear models and modes against closed forms; the sympy route against the CasADi route."""
import json
import math

import numpy as np
import pytest
import sympy as sp

import ana_models as am
from mechdsl.analysis.equilibrium import equilibria
from mechdsl.analysis.linearize import linearize
from mechdsl.diagnostics import UsageError


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
def test_double_pendulum_frequencies():
    m, l, g = 0.7, 1.3, 9.81
    lin = linearize(am.double_pendulum(m, l, g))
    assert lin.kind == "equilibrium" and np.allclose(lin.q, 0)
    md = lin.modes()
    w2 = np.array([(g / l) * (2 - math.sqrt(2)), (g / l) * (2 + math.sqrt(2))])
    assert md.frequencies == pytest.approx(np.sqrt(w2), rel=1e-12)
    assert md.hz == pytest.approx(np.sqrt(w2) / (2 * math.pi), rel=1e-12)
    assert np.all(md.damping_ratios == 0) and md.kinds == ("oscillatory", "oscillatory")
    # shapes: th2/th1 = +sqrt(2) (in phase, slow) and -sqrt(2) (out of phase, fast)
    assert md.shapes[0, 0] / md.shapes[1, 0] == pytest.approx(1 / math.sqrt(2), rel=1e-10)
    assert md.shapes[0, 1] / md.shapes[1, 1] == pytest.approx(-1 / math.sqrt(2), rel=1e-10)
    assert np.allclose(lin.C, 0) and lin.A.shape == (4, 4)
    # the eigenvalues of A are +-i w
    assert np.sort(np.abs(md.eigenvalues.imag)) == pytest.approx(np.repeat(np.sqrt(w2), 2), rel=1e-10)


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
def test_double_pendulum_symbolic_is_exact_and_agrees():
    eom = am.double_pendulum()
    lin = linearize(eom)
    s = lin.symbolic()
    m, l, g = sp.symbols("m l g", real=True)
    assert sp.simplify(s.M - sp.Matrix([[2 * m * l ** 2, m * l ** 2], [m * l ** 2, m * l ** 2]])) == sp.zeros(2, 2)
    assert sp.simplify(s.K - sp.Matrix([[2 * m * g * l, 0], [0, m * g * l]])) == sp.zeros(2, 2)
    Ms, Cs, Ks = s.numeric(lin.p)
    assert np.allclose(Ms, lin.M, atol=1e-12) and np.allclose(Ks, lin.K, atol=1e-12) and np.allclose(Cs, lin.C)


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
def test_symbolic_and_numeric_agree_off_equilibrium():
    eom = am.double_pendulum(q0=(1.0, -0.4), qd0=(0.3, 1.2))
    lin = linearize(eom, at="t=0.37")
    assert lin.kind == "state" and lin.notes
    s = lin.symbolic(exact=False)
    for a, b in zip(s.numeric(lin.p), (lin.M, lin.C, lin.K)):
        assert np.allclose(a, b, rtol=1e-10, atol=1e-10)
    assert np.max(np.abs(lin.C)) > 0.1               # Coriolis terms at a moving state


def test_state_at_time_T_matches_closed_form():
    # small-amplitude linear oscillator: x(T) = x0 cos(w T)
    m, k = 2.0, 18.0
    eom = am.two_masses(m=m, k=k, F=0.0)
    lin = linearize(eom, at={"x1": 0.0, "x2": 1.2})
    assert lin.kind == "state"
    import casadi as ca
    from mechdsl import eom as E
    q, qd, t, p = ca.SX.sym("q", 1), ca.SX.sym("qd", 1), ca.SX.sym("t"), ca.SX.sym("p", 2)
    osc = E.from_lagrangian("Osc", ["x"], ["m", "k"], [m, k], q, qd, t, p, 0.5 * p[0] * qd[0] ** 2,
                            0.5 * p[1] * q[0] ** 2, q0=[0.2])
    T = 1.234
    lin = linearize(osc, at=f"t={T}")
    w = math.sqrt(k / m)
    assert lin.q[0] == pytest.approx(0.2 * math.cos(w * T), abs=1e-9)
    assert lin.qd[0] == pytest.approx(-0.2 * w * math.sin(w * T), abs=1e-8)


@pytest.mark.parametrize("w", [5.0, 6.5])
def test_hoop_small_oscillations(w):
    R, g = 0.8, 9.81
    eom = am.hoop(R=R, g=g, w=w)
    eqs = equilibria(eom)
    th0 = math.acos(g / (w ** 2 * R))
    off = [e for e in eqs if abs(e["theta"] - th0) < 1e-8][0]
    lin = linearize(eom, at=off)
    assert lin.modes().frequencies == pytest.approx([w * math.sin(th0)], rel=1e-10)
    bottom = [e for e in eqs if abs(e["theta"]) < 1e-8][0]
    lb = linearize(eom, at=bottom)
    md = lb.modes()
    assert md.kinds == ("divergent",) and md.damping_ratios[0] == pytest.approx(-1, rel=1e-12)
    assert md.frequencies[0] == pytest.approx(math.sqrt(w ** 2 - g / R), rel=1e-10)
    assert np.max(md.eigenvalues.real) == pytest.approx(math.sqrt(w ** 2 - g / R), rel=1e-10)


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
def test_hoop_slow_spin_bottom_frequency_and_symbolic():
    R, g, w = 1.0, 9.81, 2.0
    eom = am.hoop(R=R, g=g, w=w, q0=0.1)
    lin = linearize(eom)
    assert lin.modes().frequencies == pytest.approx([math.sqrt(g / R - w ** 2)], rel=1e-10)
    s = lin.symbolic()
    m, RR, gg, ww = sp.symbols("m R g w", real=True)
    assert sp.simplify(s.K[0, 0] - (m * gg * RR - m * RR ** 2 * ww ** 2)) == 0


@pytest.mark.parametrize("uniform", [False, True])
def test_cart_pole_upright_unstable_eigenvalue(uniform):
    M, m, l, g = 1.0, 0.1, 1.0, 9.81
    lin = linearize(am.cart_pole(M, m, l, g, uniform=uniform), inputs=["F"])
    assert np.allclose(lin.q, 0)
    if uniform:
        lam2 = (m * g * l / 2) / (m * l ** 2 / 3 - (m * l / 2) ** 2 / (M + m))
    else:
        lam2 = g * (M + m) / (M * l)
    lam = np.linalg.eigvals(lin.A)
    assert np.max(lam.real) == pytest.approx(math.sqrt(lam2), rel=1e-10)
    md = lin.modes()
    assert md.kinds == ("rigid", "divergent")
    assert md.frequencies == pytest.approx([0, math.sqrt(lam2)], rel=1e-10, abs=1e-12)
    # B: a unit force on the cart accelerates (x, theta) by M^-1 e_x
    assert lin.B[2:, 0] == pytest.approx(np.linalg.solve(lin.M, [1.0, 0.0]))
    assert lin.B[:2, 0] == pytest.approx([0, 0])
    assert lin.equilibrium.stable is False


def test_damping_ratio_and_generalized_force_input():
    m, k, c = 2.0, 50.0, 3.0
    lin = linearize(am.two_masses(m=m, k=k, F=0.0, c=c), inputs=["force(x1)", "F"])
    md = lin.modes()
    # relative mode of two masses: reduced mass m/2, stiffness k, damping c
    wn = math.sqrt(k / (m / 2))
    zeta = c / (2 * math.sqrt(k * m / 2))
    osc = [j for j, kd in enumerate(md.kinds) if kd == "oscillatory"]
    assert len(osc) == 1
    assert md.frequencies[osc[0]] == pytest.approx(wn, rel=1e-10)
    assert md.damping_ratios[osc[0]] == pytest.approx(zeta, rel=1e-10)
    assert np.allclose(lin.D, lin.C) and np.allclose(lin.G, 0)
    assert lin.inputs == ("force(x1)", "F")
    assert lin.Bq == pytest.approx(np.array([[1.0, 0.0], [0.0, 1.0]]))


def test_gyroscopic_matrix_in_C():
    W = 2.0
    lin = linearize(am.rotating_saddle(W=W), at="equilibrium")
    assert lin.G == pytest.approx(np.array([[0, -2 * W], [2 * W, 0]]))
    assert np.allclose(lin.D, 0)
    md = lin.modes()
    assert md.frequencies == pytest.approx([math.sqrt(3), math.sqrt(5)], rel=1e-9)
    assert np.allclose(md.damping_ratios, 0, atol=1e-9)


def test_geometric_stiffness_of_loaded_pendulum():
    m, L, g, F = 1.0, 0.8, 9.81, 4.0
    lin = linearize(am.pendulum(m=m, L=L, g=g, F=F, q0=0.3))
    assert lin.q[0] == pytest.approx(math.atan2(F, m * g), rel=1e-10)
    assert lin.K[0, 0] == pytest.approx(L * math.hypot(m * g, F), rel=1e-10)


def test_accelerated_reference_linearization():
    lin = linearize(am.two_masses(m=2.0, k=50.0, F=3.0))
    assert lin.kind == "accelerated-reference"
    assert lin.acceleration == pytest.approx([0.75, 0.75])
    assert lin.modes().frequencies == pytest.approx([0.0, math.sqrt(50.0)], abs=1e-12, rel=1e-10)


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
def test_outputs_json_csv_plot(tmp_path):
    lin = linearize(am.double_pendulum())
    md = lin.modes()
    jp, cp, pp = tmp_path / "m.json", tmp_path / "m.csv", tmp_path / "m.png"
    md.write_json(jp)
    md.write_csv(cp)
    md.plot(pp, title="double pendulum")
    data = json.loads(jp.read_text())
    assert [mo["frequency_rad_s"] for mo in data["modes"]] == pytest.approx(list(md.frequencies))
    rows = cp.read_text().splitlines()
    assert rows[0].startswith("mode,kind,frequency_rad_s") and len(rows) == 3
    assert pp.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["m.csv", "m.json", "m.png"]   # no temporaries left
    full = json.loads(lin.to_json())
    assert full["kind"] == "equilibrium" and len(full["A"]) == 4


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
def test_bad_requests():
    eom = am.double_pendulum()
    with pytest.raises(UsageError):
        linearize(eom, at="somewhere")
    with pytest.raises(UsageError):
        linearize(eom, inputs=["nope"])
    with pytest.raises(UsageError):
        linearize(eom, at={"th9": 1.0})
