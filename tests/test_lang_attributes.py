"""Issue 17, attributes: b.w_body (body-axes angular velocity), p.a (point acceleration) and
b.alpha (angular acceleration), against hand derivations at random states."""
from __future__ import annotations

import numpy as np
import pytest

import mechdsl
from mechdsl.diagnostics import MechError
from reach_util import output_values
from test_lang_units_zero import omega_body_zyx
import mechdsl.examples

G, L = 9.81, 1.3

ROD = """
model P
  parameter Real L(unit = "m") = 1.3;
  Gravity g(g = {0, -9.81, 0});
  Rod rod(m = 2, L = L, axis = {0, -1, 0});
  Revolute j(parent = world, child = rod.a, phi = PHI);
  coordinate Real th(start = 0.4);
  output Real a[3](unit = "m/s2") = rod.b.a;
  output Real al[3](unit = "1/s2") = rod.alpha;
  output Real wb[3](unit = "1/s") = rod.w_body;
  output Real aw[3] = world.a;
end P;
"""


def _vec(out, name):
    return np.concatenate([out[f"{name}[{i}]"] for i in (1, 2, 3)])


@pytest.mark.parametrize("binding, factor", [("th", 1.0), ("2*th", 2.0)])   # aba route; crba (an expression)
def test_rod_end_acceleration_and_angular_acceleration(binding, factor):
    m = mechdsl.loads(ROD.replace("PHI", binding))
    rng = np.random.default_rng(7)
    for _ in range(3):
        th, thd = rng.uniform(-2, 2), rng.uniform(-3, 3)
        out = output_values(m, [th], [thd], [f"{n}[{i}]" for n in ("a", "al", "wb", "aw") for i in (1, 2, 3)])
        phi, phid = factor * th, factor * thd
        phidd = -3 * G / (2 * L) * np.sin(phi)          # uniform rod pivoted at its end
        a = L * np.array([phidd * np.cos(phi) - phid**2 * np.sin(phi), phidd * np.sin(phi) + phid**2 * np.cos(phi), 0])
        assert _vec(out, "a") == pytest.approx(a, rel=1e-9, abs=1e-9)
        assert _vec(out, "al") == pytest.approx([0, 0, phidd], rel=1e-9, abs=1e-9)
        assert _vec(out, "wb") == pytest.approx([0, 0, phid], rel=1e-12, abs=1e-12)
        assert _vec(out, "aw") == pytest.approx([0, 0, 0], abs=0)


TOP = """
model Top
  Body b(m = 1, I = diagonal({1, 2, 3}));
  Spherical s(parent = world, child = b);
  output Real wb[3](unit = "1/s") = b.w_body;
  output Real al[3](unit = "1/s2") = transpose(b.R)*b.alpha;
end Top;
"""


def test_body_angular_velocity_and_euler_equations():
    """w_body of the zyx chart by hand; b.alpha in body axes satisfies Euler's equations
    I w' + w x I w = 0 of the torque-free body (the body frame turns, so R^T alpha = w_body')."""
    m = mechdsl.loads(TOP)
    I = np.diag([1.0, 2.0, 3.0])
    rng = np.random.default_rng(11)
    for _ in range(3):
        q, qd = rng.uniform(-1, 1, 3), rng.uniform(-2, 2, 3)
        out = output_values(m, q, qd, [f"{n}[{i}]" for n in ("wb", "al") for i in (1, 2, 3)])
        w = omega_body_zyx(q, qd)
        assert _vec(out, "wb") == pytest.approx(w, rel=1e-12, abs=1e-12)
        assert I @ _vec(out, "al") + np.cross(w, I @ w) == pytest.approx(np.zeros(3), abs=1e-9)


@pytest.mark.parametrize("extra, at", [
    ("  Force f(point = rod.b, F = 0.1*rod.b.a);\nend P;", "Force f"),
    ("  parameter Real J(unit = \"kg.m2\") = 1;\n  Torque tq(body = rod, tau = {0, 0, J*rod.alpha[3]});\nend P;",
     "Torque tq"),
    ("  parameter Real mL(unit = \"kg.m2\") = 1;\nequation\n  force(th) = mL*rod.b.a[2];\nend P;", "force(th)"),
], ids=["force", "torque", "generalized-force"])
def test_acceleration_in_a_force_is_refused(extra, at):
    """...at the force or term that uses it (the diagnostic had no place: `<input>: error`)."""
    bad = ROD.replace("PHI", "th").replace("end P;", extra)
    with pytest.raises(MechError) as err:
        mechdsl.loads(bad).eom
    assert "E725" in str(err.value) and "outputs only" in str(err.value)
    assert at in bad.splitlines()[err.value.first.span.line - 1]



def test_accelerations_in_a_closed_loop_are_the_derivatives_of_the_velocities():
    """Four-bar (a DAE: the accelerations carry the multipliers): p.a and b.alpha along a run
    equal the central differences of the recorded p.v and b.w."""
    from pathlib import Path
    text = mechdsl.examples.path("four_bar").read_text() + """
model FB2
  extends FourBar;
  output Real ab[3] = coupler.b.a;
  output Real vb[3] = coupler.b.v;
  output Real al[3] = coupler.alpha;
  output Real w[3] = coupler.w;
end FB2;
"""
    r = mechdsl.loads(text, model="FB2").simulate(0.1, points=201, rtol=1e-10, atol=1e-12)
    for a, v in (("ab[1]", "vb[1]"), ("ab[2]", "vb[2]"), ("al[3]", "w[3]")):
        fd = np.gradient(r.signals[v], r.t)[1:-1]
        acc = r.signals[a][1:-1]
        assert np.max(np.abs(fd - acc)) < 1e-3 * np.max(np.abs(acc))
