"""Hamilton's equations: the CasADi form against the Lagrangian equations, the sympy text
against closed forms."""
import casadi as ca
import numpy as np
import pytest
import sympy as sp

import ana_models as am
from mechdsl.analysis.hamilton import format_hamiltonian, hamiltonian
from mechdsl.analysis.integrals import first_integrals
from mechdsl.diagnostics import MechError


@pytest.mark.parametrize("make", [am.double_pendulum, am.hoop, am.heavy_top, am.rotating_saddle,
                                  lambda: am.pendulum(c=0.4, F=1.0, A=0.3, w=2.0)])
def test_canonical_equations_match_lagrange(make):
    eom = make()
    h = hamiltonian(eom)
    pv = eom.param_values
    n = eom.n
    mom = ca.Function("mom", [eom.q, eom.qd, eom.t, eom.p], [h.momenta])
    # d/dt (dL/dqd) along the Lagrangian motion: dp/dq qd + dp/dqd qdd + dp/dt
    qdd = ca.solve(eom.M, eom.bias)
    pdot_l = ca.jtimes(h.momenta, eom.q, eom.qd) + ca.jtimes(h.momenta, eom.qd, qdd) + ca.jacobian(h.momenta, eom.t)
    fl = ca.Function("pl", [eom.q, eom.qd, eom.t, eom.p], [pdot_l])
    rhs = h.function("rhs")
    rng = np.random.default_rng(7)
    for _ in range(4):
        q, qd, t = rng.uniform(-1.2, 1.2, n) + 0.2, rng.uniform(-1, 1, n), rng.uniform(0, 2)
        p = np.array(mom(q, qd, t, pv)).ravel()
        qdot, pdot = (np.array(v).ravel() for v in rhs(q, p, t, pv))
        assert qdot == pytest.approx(qd, rel=1e-10, abs=1e-10)
        assert pdot == pytest.approx(np.array(fl(q, qd, t, pv)).ravel(), rel=1e-9, abs=1e-9)


def test_hamiltonian_equals_jacobi_integral():
    for eom in (am.hoop(), am.heavy_top(), am.double_pendulum()):
        h = hamiltonian(eom)
        fi = [f for f in first_integrals(eom) if f.kind in ("jacobi", "energy")][0]
        fj = ca.Function("j", [eom.q, eom.qd, eom.t, eom.p], [fi.sx])
        mom = h.function("momenta")
        rng = np.random.default_rng(3)
        for _ in range(3):
            q, qd = rng.uniform(-1, 1, eom.n) + 0.3, rng.uniform(-1, 1, eom.n)
            p = mom(q, qd, 0.0, eom.param_values)
            assert float(h.function("H")(q, p, 0.0, eom.param_values)) == pytest.approx(
                float(fj(q, qd, 0.0, eom.param_values)), rel=1e-10)


def test_separability():
    assert hamiltonian(am.kepler()).separable
    assert hamiltonian(am.two_masses()).separable
    assert not hamiltonian(am.double_pendulum()).separable
    assert not hamiltonian(am.pendulum(c=0.3)).separable
    assert not hamiltonian(am.rotating_saddle()).separable


def test_singular_mass_matrix_at_start_is_reported():
    with pytest.raises(MechError, match="singular"):
        hamiltonian(am.heavy_top(q0=(0.0, 0.0, 0.0)))


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
def test_format_hamiltonian_hoop_text_and_latex():
    txt = format_hamiltonian(am.hoop())
    assert "p_theta = der(theta)*m*R^2" in txt.replace("m*R^2*der(theta)", "der(theta)*m*R^2")
    line = [ln for ln in txt.splitlines() if ln.strip().startswith("H =")][0]
    H = sp.sympify(line.split("=", 1)[1].replace("^", "**"))
    m, R, g, w, th, p = sp.symbols("m R g w theta p_theta")
    closed = p ** 2 / (2 * m * R ** 2) - m * g * R * sp.cos(th) - m * R ** 2 * w ** 2 * sp.sin(th) ** 2 / 2
    assert sp.simplify(H - closed) == 0
    assert "Jacobi integral" in txt
    tex = format_hamiltonian(am.hoop(), latex=True)
    assert r"\begin{aligned}" in tex and r"\dot{\theta}" in tex


def test_format_hamiltonian_from_equation_layer_ir():
    import mechdsl

    text = """
model Osc
  parameter Real m = 2;
  parameter Real k = 3;
  parameter Real c = 0.5;
  coordinate Real x(start = 1);
equation
  kinetic = 1/2*m*der(x)^2;
  potential = 1/2*k*x^2;
  dissipation = 1/2*c*der(x)^2;
end Osc;
"""
    model = mechdsl.loads(text).model
    txt = format_hamiltonian(model)
    assert "p_x = m*der(x)" in txt.replace("der(x)*m", "m*der(x)")
    lines = {ln.split("=")[0].strip(): ln.split("=", 1)[1].strip() for ln in txt.splitlines() if " = " in ln}
    x, px, m, k, c = sp.symbols("x p_x m k c")
    assert sp.simplify(sp.sympify(lines["H"].replace("^", "**")) - (px ** 2 / (2 * m) + k * x ** 2 / 2)) == 0
    assert sp.simplify(sp.sympify(lines["der(p_x)"].replace("^", "**")) - (-k * x - c * px / m)) == 0
    assert "energy T + V" in txt
