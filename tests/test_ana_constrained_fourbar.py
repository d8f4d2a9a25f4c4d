"""Four-bar linkage (models/four_bar.mech, a crank-rocker under gravity): static equilibria of
the constrained model against a brute-force search of the potential energy along the
one-dof configuration curve, computed here independently (absolute link angles, the loop
solved by scipy for every crank angle, continuation from the model's assembly branch)."""
import math

import numpy as np
import pytest
from scipy.optimize import brentq, fsolve

import mechdsl
from mechdsl.dae import initialize
from conftest import MODELS

A, B, C, D, MASS, G = 0.2, 0.6, 0.5, 0.6, 1.0, 9.81


def loop(th, guess):
    """(phi, psi): absolute coupler and rocker angles closing the loop for crank angle th."""
    def f(x):
        phi, psi = x
        return [A * math.cos(th) + B * math.cos(phi) - D - C * math.cos(psi),
                A * math.sin(th) + B * math.sin(phi) - C * math.sin(psi)]

    x = fsolve(f, guess, xtol=1e-13)
    assert max(abs(v) for v in f(x)) < 1e-12
    return x


def potential(th, phi, psi):
    # uniform rods: centres at the middle of each link
    y = A / 2 * math.sin(th) + (A * math.sin(th) + B / 2 * math.sin(phi)) + C / 2 * math.sin(psi)
    return MASS * G * y


def sweep(th0, phi0, psi0, steps=720):
    """V along the configuration curve, one crank turn from th0, continuation in small steps."""
    ths = th0 + 2 * math.pi * np.arange(steps + 1) / steps
    guess = np.array([phi0, psi0])
    rows = []
    for th in ths:
        guess = loop(th, guess)
        rows.append((th, *guess, potential(th, *guess)))
    return np.array(rows)


def slopes(th, phi, psi):
    """(dphi/dth, dpsi/dth) along the curve: the loop equations differentiated."""
    J = np.array([[-B * math.sin(phi), C * math.sin(psi)], [B * math.cos(phi), -C * math.cos(psi)]])
    return np.linalg.solve(J, [A * math.sin(th), -A * math.cos(th)])


def dV(th, start):
    """dV/dth along the curve (chain rule through the loop)."""
    phi, psi = loop(th, start)
    dphi, dpsi = slopes(th, phi, psi)
    return MASS * G * (1.5 * A * math.cos(th) + B / 2 * math.cos(phi) * dphi + C / 2 * math.cos(psi) * dpsi)


def critical_points(rows):
    """Local minima and maxima of V along the curve: sign changes of dV/dth on the sweep,
    refined by brentq."""
    out = []
    for i in range(len(rows) - 1):
        (t1, p1, s1, _), (t2, *_rest) = rows[i], rows[i + 1]
        d1, d2 = dV(t1, (p1, s1)), dV(t2, (p1, s1))
        if d1 < 0 <= d2 or d1 > 0 >= d2:
            th = brentq(lambda x: dV(x, (p1, s1)), t1, t2, xtol=1e-15, rtol=1e-15)
            out.append(("min" if d1 < 0 else "max", th, *loop(th, (p1, s1))))
    return out


def wrap(x):
    return math.remainder(x, 2 * math.pi)


@pytest.fixture(scope="module")
def model():
    return mechdsl.load(MODELS / "four_bar.mech", model="FourBar")


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
def test_four_bar_equilibria_match_brute_force(model):
    eqs = model.equilibria()
    q0 = initialize(model.eom).q                  # the model's assembly branch
    th0, phi0, psi0 = q0[0], q0[0] + q0[1], q0[2]
    ref = critical_points(sweep(th0, phi0, psi0))
    assert sorted(k for k, *_ in ref) == ["max", "min"]       # one minimum, one maximum of V per turn
    assert len(eqs) == len(ref)
    for kind, th, phi, psi in ref:
        e = min(eqs, key=lambda e: abs(wrap(e.q[0] - th)))
        assert abs(wrap(e.q[0] - th)) < 1e-6
        assert abs(wrap(e.q[0] + e.q[1] - phi)) < 1e-6      # elbow.phi is the relative coupler angle
        assert abs(wrap(e.q[2] - psi)) < 1e-6
        assert e.stable is (kind == "min")
        assert e.kind == "static"
        # constraint forces: the redundant out-of-plane conditions carry none
        assert e.lambdas["close.fz"] == e.lambdas["close.tx"] == e.lambdas["close.ty"] == 0.0


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
def test_four_bar_reduced_model_is_the_one_dof_motion(model):
    """The reduced linear model against the one-dof motion along the brute-force curve:
    dq = Z dz with Z tangent to the curve; K_r = V''(th) (dth/dz)^2 at an equilibrium (the
    geometric stiffness of the constraint forces included), M_r = m(th) (dth/dz)^2 with m(th)
    the mass of the motion along the curve; the frequency does not depend on the basis."""
    q0 = initialize(model.eom).q
    ref = critical_points(sweep(q0[0], q0[0] + q0[1], q0[2]))
    h = 1e-5
    for kind, th, phi, psi in ref:
        lin = model.linearize(at={"crank_pivot.phi": th})
        assert lin.kind == "equilibrium" and len(lin.reduced_coords) == 1
        z = lin.reduced_coords[0]
        Z = lin.basis[:, 0]
        assert Z[model.eom.coords.index(z)] == pytest.approx(1.0, abs=1e-12)  # dz is the change of that coordinate
        d2V = (dV(th + h, (phi, psi)) - dV(th - h, (phi, psi))) / (2 * h)
        dphi, dpsi = slopes(th, phi, psi)
        tangent = np.array([1.0, dphi - 1.0, dpsi])            # (crank, elbow = phi - th, rocker)
        assert np.allclose(Z, Z[0] * tangent, rtol=1e-10, atol=1e-12)
        crank = MASS * A ** 2 / 3
        vc = np.array([-A * math.sin(th) - B / 2 * math.sin(phi) * dphi, A * math.cos(th) + B / 2 * math.cos(phi) * dphi])
        m_th = crank + MASS * vc @ vc + MASS * B ** 2 / 12 * dphi ** 2 + MASS * C ** 2 / 3 * dpsi ** 2
        assert lin.K[0, 0] == pytest.approx(d2V * Z[0] ** 2, rel=1e-7)
        assert lin.M[0, 0] == pytest.approx(m_th * Z[0] ** 2, rel=1e-10)
        md = lin.modes()
        assert md.frequencies[0] == pytest.approx(math.sqrt(abs(d2V / m_th)), rel=1e-7)
        assert md.kinds[0] == ("oscillatory" if kind == "min" else "divergent")
        # the mode shape, in the original coordinates, is the tangent of the curve
        assert np.allclose(md.shapes[:, 0] / md.shapes[0, 0], tangent, rtol=1e-9)
        # the classification's reduced Hessian (orthonormal tangent basis): V'' / |tangent|^2
        e = lin.equilibrium
        assert e is None or e.hessian_eigenvalues[0] == pytest.approx(d2V / (tangent @ tangent), rel=1e-7)
        eq = min(model.equilibria(), key=lambda e: abs(wrap(e.q[0] - th)))
        assert eq.hessian_eigenvalues[0] == pytest.approx(d2V / (tangent @ tangent), rel=1e-7)


def test_four_bar_multipliers_are_the_hinge_force(model):
    """lambda of the closing hinge against statics of the rocker and the coupler (moments about
    their fixed and crank-end pivots)."""
    for e in model.equilibria():
        th, phi, psi = e.q[0], e.q[0] + e.q[1], e.q[2]
        w = MASS * G
        # unknown hinge force F on the rocker at its end E = (D + C cos psi, C sin psi):
        # rocker about pivot2:  (E - P2) x F - (C/2 cos psi) w = 0
        # coupler (force -F at E) about the crank end A:  (E - A) x (-F) - (B/2 cos phi) w = 0
        rE = np.array([C * math.cos(psi), C * math.sin(psi)])
        rA = np.array([B * math.cos(phi), B * math.sin(phi)])
        Mx = np.array([[-rE[1], rE[0]], [rA[1], -rA[0]]])
        F = np.linalg.solve(Mx, [C / 2 * math.cos(psi) * w, B / 2 * math.cos(phi) * w])
        lam = np.array([e.lambdas["close.fx"], e.lambdas["close.fy"]])
        # docs/mechanics.md: the multipliers of a loop-closing joint are the reaction on the
        # child (the rocker) along the axes of the parent joint frame (the coupler's, angle phi)
        R = np.array([[math.cos(phi), -math.sin(phi)], [math.sin(phi), math.cos(phi)]])
        assert np.allclose(R @ lam, F, rtol=0, atol=1e-9 * np.linalg.norm(F))


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
def test_cli_tables(tmp_path, capsys):
    import json

    from mechdsl.cli import main

    assert main(["equilibrium", str(MODELS / "four_bar.mech"), "--model", "FourBar", "-o",
                 str(tmp_path / "eq.json")]) == 0
    out = capsys.readouterr().out
    assert "lambda[close.fx]" in out and "lambda[close.fy]" in out and "reduced Hessian eigenvalues" in out
    assert "redundant constraint(s) close.fz, close.tx, close.ty dropped" in out
    data = json.loads((tmp_path / "eq.json").read_text())
    assert data["count"] == 2 and set(data["equilibria"][0]["multipliers"]) == {
        "close.fx", "close.fy", "close.fz", "close.tx", "close.ty"}
    assert main(["linearize", str(MODELS / "four_bar.mech"), "--model", "FourBar",
                 "-o", str(tmp_path / "lin.json")]) == 0
    out = capsys.readouterr().out
    assert "Z (basis of the tangent space)" in out and "lambda[close.fx] =" in out
    assert "shapes in the original coordinates" in out
    lin = json.loads((tmp_path / "lin.json").read_text())
    assert lin["reduced_coordinates"] == ["crank_pivot.phi"] and len(lin["M"]) == 1
    assert lin["equilibrium"]["stable"] is False       # the one nearest the start (crank up)
    assert lin["modes"][0]["kind"] == "divergent"
