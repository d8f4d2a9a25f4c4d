"""The slider-crank (models/slider_crank.mech) with its motor torque set to zero and gravity
added, against the same mechanism written here in one minimal coordinate (the crank angle th,
slider position and rod angle from the loop's closed-form solution), analysed as an ODE:
equilibria, stability, the linear model and the pin force at rest."""
import math

import casadi as ca
import numpy as np
import pytest

import mechdsl
from conftest import MODELS
from mechdsl import eom as E

R, L, M1, M2, M3, G = 0.1, 0.3, 0.5, 1.0, 2.0, 9.81


@pytest.fixture(scope="module")
def loop_model():
    text = (MODELS / "slider_crank.mech").read_text()
    text = text.replace('tau(unit = "N.m") = 0.5', 'tau(unit = "N.m") = 0')
    text = text.replace("  Box slider(", '  Gravity gravity(g = {0, -9.81, 0});\n  Box slider(')
    assert "Gravity gravity" in text and "= 0 \"motor torque" in text
    return mechdsl.loads(text, model="SliderCrank")


def minimal():
    """One coordinate th; rods uniform (crank about its end: m1 r^2/3), slider a point mass
    on the x axis at s = r cos th + sqrt(l^2 - r^2 sin^2 th)."""
    q, qd, t, p = ca.SX.sym("q", 1), ca.SX.sym("qd", 1), ca.SX.sym("t"), ca.SX.sym("p", 0)
    th = q[0]
    A = ca.vertcat(R * ca.cos(th), R * ca.sin(th))
    s = R * ca.cos(th) + ca.sqrt(L ** 2 - R ** 2 * ca.sin(th) ** 2)
    beta = ca.atan2(-R * ca.sin(th), s - R * ca.cos(th))
    cm = (A + ca.vertcat(s, 0)) / 2

    def vel(x):
        return ca.jacobian(x, q) @ qd

    T = (0.5 * M1 * R ** 2 / 3 * qd[0] ** 2 + 0.5 * M2 * ca.sumsqr(vel(cm)) + 0.5 * M2 * L ** 2 / 12 * vel(beta) ** 2
         + 0.5 * M3 * vel(s) ** 2)
    V = G * (M1 * R / 2 * ca.sin(th) + M2 * cm[1])
    eom = E.from_lagrangian("SliderCrankMinimal", ["th"], [], [], q, qd, t, p, T, V, q0=[math.pi / 2])
    return eom, ca.Function("geo", [q], [s, beta])


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
def test_equilibria_match_minimal_coordinates(loop_model):
    from mechdsl.analysis.equilibrium import equilibria

    eom_min, geo = minimal()
    ref = equilibria(eom_min)
    got = loop_model.equilibria()
    # V = (m1 + m2) g r sin(th) / 2: th = -pi/2 stable, th = pi/2 unstable
    assert sorted(round(e["th"], 9) for e in ref) == [round(-math.pi / 2, 9), round(math.pi / 2, 9)]
    assert len(got) == 2
    for r in ref:
        e = min(got, key=lambda e: abs(math.remainder(e["j1.phi"] - r["th"], 2 * math.pi)))
        assert abs(math.remainder(e["j1.phi"] - r["th"], 2 * math.pi)) < 1e-9
        s, beta = (float(v) for v in geo(r["th"]))
        assert e["j3.s"] == pytest.approx(s, rel=1e-10)
        assert math.remainder(e["j2.phi"] - (beta - r["th"]), 2 * math.pi) == pytest.approx(0, abs=1e-9)
        assert e.stable is r.stable
        assert r.stable is (r["th"] < 0)
        # the reduced Hessian (unit tangent) carries the curvature of V along the curve
        dq = np.array([1.0, *_slopes(geo, r["th"])])
        assert e.hessian_eigenvalues[0] == pytest.approx(r.hessian_eigenvalues[0] / (dq @ dq), rel=1e-7)


def _slopes(geo, th, h=1e-6):
    (s1, b1), (s2, b2) = ([float(v) for v in geo(x)] for x in (th - h, th + h))
    return (b2 - b1) / (2 * h) - 1.0, (s2 - s1) / (2 * h)        # d(j2.phi)/dth, ds/dth


def test_linear_model_matches_minimal_coordinates(loop_model):
    from mechdsl.analysis.linearize import linearize

    eom_min, _ = minimal()
    for th in (-math.pi / 2, math.pi / 2):
        ref = linearize(eom_min, at={"th": th})
        lin = loop_model.linearize(at={"j1.phi": th})
        assert ref.kind == lin.kind == "equilibrium"
        z = lin.reduced_coords[0]
        scale = lin.basis[0, 0]                 # d(j1.phi)/dz
        assert lin.basis[lin.coords.index(z), 0] == pytest.approx(1.0, abs=1e-12)
        assert lin.M[0, 0] == pytest.approx(ref.M[0, 0] * scale ** 2, rel=1e-9)
        assert lin.K[0, 0] == pytest.approx(ref.K[0, 0] * scale ** 2, rel=1e-9)
        assert lin.modes().frequencies == pytest.approx(ref.modes().frequencies, rel=1e-9)
        assert lin.modes().kinds == ref.modes().kinds
    # closed form at the bottom: K = V'' = (m1 + m2) g r / 2; the crank end and the slider both
    # move at r th' horizontally (ds/dth = r there), so the rod translates: M = (m1/3 + m2 + m3) r^2
    ref = linearize(eom_min, at={"th": -math.pi / 2})
    assert ref.K[0, 0] == pytest.approx((M1 + M2) * G * R / 2, rel=1e-10)
    assert ref.M[0, 0] == pytest.approx((M1 / 3 + M2 + M3) * R ** 2, rel=1e-10)


def test_pin_force_at_rest(loop_model):
    """At the bottom the slider feels half the rod's weight through the pin and no horizontal
    force: (0, -m2 g / 2) in the world, along the rod's axes (the parent joint frame)."""
    e = min(loop_model.equilibria(), key=lambda e: e["j1.phi"])
    beta = e["j1.phi"] + e["j2.phi"]
    lam = np.array([e.lambdas["j4.fx"], e.lambdas["j4.fy"]])
    Rm = np.array([[math.cos(beta), -math.sin(beta)], [math.sin(beta), math.cos(beta)]])
    assert np.allclose(Rm @ lam, [0.0, -M2 * G / 2], atol=1e-10)
    assert e.lambdas["j4.fz"] == e.lambdas["j4.tx"] == e.lambdas["j4.ty"] == 0.0
