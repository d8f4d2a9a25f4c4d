"""Inertia data (issue 26): only tensors that are not symmetric or not positive semidefinite are
always refused; the triangle inequality broken by rounding is a located warning with the amount,
beyond that an error with a hint; `measured_inertia = true` opts out; a planar body (one that turns
about one axis of its own only) is not judged by the triangle inequality."""
from __future__ import annotations

import numpy as np
import pytest

import mechdsl
from mechdsl.cli import main
from mechdsl.diagnostics import MechError


def body_model(I: str, joint: str = "Spherical j(parent = world, child = b, phi(start = 0.3));", extra: str = "") -> str:
    return f"""
model A
  Gravity g;
  Body b(m = 1, r_cm = {{0.3, 0, 0}}, {I}{extra});
  {joint}
end A;
"""


def codes(text):
    try:
        m = mechdsl.loads(text)
    except MechError as e:
        return [d.code for d in e.diagnostics]
    return [w.code for w in m.warnings]


def test_rounding_is_a_warning_with_the_amount(capsys, tmp_path):
    text = body_model("I = diagonal({0.1, 0.1, 0.2000001})")
    m = mechdsl.loads(text)
    (w,) = [w for w in m.warnings if w.code == "W509"]
    assert w.severity == "warning" and w.span.line == 4
    assert "5e-07 of I3" in w.message and "1e-07" in w.message    # the amount, absolute and relative
    m.simulate(0.1)                                               # and it runs
    f = tmp_path / "r.mech"
    f.write_text(text)
    assert main(["check", str(f)]) == 0
    err = capsys.readouterr().err
    assert f"{f}:4:3: warning[W509]" in err


@pytest.mark.parametrize("I33, expected", [(0.2 * (1 + 1e-13), []), (0.2 * (1 + 9e-7), ["W509"]),
                                           (0.2 * (1 + 2e-6), ["E509"]), (0.3, ["E509"])])
def test_tolerance_bands(I33, expected):
    assert codes(body_model(f"I = diagonal({{0.1, 0.1, {I33!r}}})")) == expected


def test_a_larger_violation_hints_at_the_opt_out():
    with pytest.raises(MechError) as e:
        mechdsl.loads(body_model("I = diagonal({0.1, 0.1, 0.3})"))
    d = e.value.diagnostics[0]
    assert d.code == "E509" and "0.333 of I3" in d.message and "measured_inertia = true" in d.help


def test_measured_inertia_opts_out_of_the_triangle_inequality_only():
    m = mechdsl.loads(body_model("I = diagonal({0.1, 0.1, 0.3})", extra=", measured_inertia = true"))
    assert not m.warnings and m.model.body("b").measured
    r = m.simulate(0.2)
    assert np.all(np.isfinite(r.q))
    # not positive semidefinite: refused even for measured data
    assert codes(body_model("I = {{0.1, 0.2, 0}, {0.2, 0.1, 0}, {0, 0, 0.3}}", extra=", measured_inertia = true")) \
        == ["E509"]


def test_sympy_planar_inertia_on_a_hinge_is_accepted_and_exact():
    """sympy's inertia(B, 0, 0, Izz): a body on a hinge about z feels only Izz, so the equations
    are those of a compound pendulum, theta'' = -m g r sin(theta) / (Izz + m r^2)."""
    text = body_model("I_33 = 0.2", joint="Revolute j(parent = world, child = b, axis = {0, 0, 1}, phi(start = 0.3));")
    text = text.replace("Gravity g;", "Gravity g(g = {0, -9.81, 0});").replace("r_cm = {0.3, 0, 0}", "r_cm = {0, -0.5, 0}")
    m = mechdsl.loads(text)
    assert not m.warnings
    import casadi as ca

    e = m.eom
    f = ca.Function("f", [e.q, e.qd, e.t, e.p], [e.qdd])
    for th in (0.3, -1.1, 2.0):
        assert float(f([th], [0.7], 0, e.param_values)) == pytest.approx(-9.81 * 0.5 * np.sin(th) / (0.2 + 0.25),
                                                                         rel=1e-13)


def test_planar_through_oriented_frames_and_chains():
    """Planar means: every rotation between the body and the world is about one axis of the body.
    Only the moment about that axis enters the equations (it may even be 0: the body then turns
    like a point mass); the other moments are placeholders. Two hinges in a chain keep the end
    body planar when their axes are parallel (here made so by the second joint's rpy, which the
    check composes); crossed hinges do not."""
    tilted = """
model T
  Gravity g;
  Body b(m = 1, r_cm = {0, 0.5, 0}, I_11 = 0.2);
  Point p(body = world, rpy = {0, pi/2, 0});
  Point c(body = b, rpy = {0, -pi/2, 0});
  Revolute j(parent = p, child = c, axis = {0, 0, 1}, phi(start = 0.3));
end T;
"""
    assert codes(tilted) == []
    assert codes(tilted.replace("Revolute j(parent = p, child = c, axis = {0, 0, 1}, phi(start = 0.3));",
                                "Spherical j(parent = p, child = c, phi(start = 0.3));")) == ["E509"]
    chain = """
model C
  Gravity g;
  Body a(m = 1, r_cm = {0.5, 0, 0}, I_33 = 0.1);
  Body b(m = 1, r_cm = {0, 0.5, 0}, I_11 = 0.2);
  Point e(body = a, r = {1, 0, 0});
  Revolute j1(parent = world, child = a, axis = {0, 0, 1}, phi(start = 0.3));
  Prismatic s(parent = e, axis = {1, 0, 0}, s(start = 0.1));
  Revolute j2(parent = s, child = b, axis = {1, 0, 0}, RPY phi(start = 0.1));
end C;
"""
    assert codes(chain.replace("RPY", "rpy = {0, -pi/2, 0},")) == []
    with pytest.raises(MechError) as e:
        mechdsl.loads(chain.replace("RPY", ""))
    assert [(d.code, d.span.line) for d in e.value.diagnostics] == [("E509", 5)]     # b turns about two axes


def test_a_zero_tensor_with_rounding_noise_is_zero():
    """iCub's head: I = 0 but for ixz = 2.4e-35, beside 1.3 kg 0.11 m off the link origin. Beside the
    mass's own moment about the origin (m |r_cm|^2 = 0.017) the tensor is zero, not 'negative'; so is
    a 1e-20 tensor of any shape. Where m |r_cm|^2 is larger than I3 the tolerances are relative to it."""
    noise = "I = {{0, 0, 2.40741e-35}, {0, 0, 0}, {2.40741e-35, 0, 0}}"
    assert codes(body_model(noise).replace("m = 1, r_cm = {0.3, 0, 0}", "m = 1.33687, r_cm = {0.0185, -0.1108, 0}")) == []
    tiny = "I = {{2.71e-20, -1.69e-21, 1.355e-20}, {-1.69e-21, 5.42e-20, 3.39e-21}, {1.355e-20, 3.39e-21, 1.355e-20}}"
    assert codes(body_model(tiny)) == []
    with pytest.raises(MechError) as e:                  # where the tensor is the scale, its shape counts
        mechdsl.loads(body_model(tiny).replace("r_cm = {0.3, 0, 0}", "r_cm = {0, 0, 0}"))
    assert e.value.diagnostics[0].code == "E509"
    (w,) = mechdsl.loads(body_model("I = diagonal({0.01, 0.01, 0.02000002})")).warnings   # 2e-8 of m|r_cm|^2 = 0.09
    assert w.code == "W509" and "of m |r_cm|^2 = 0.09" in w.message


def test_with_params_judges_the_new_values():
    text = """
model P
  parameter Real Izz = 0.2;
  Gravity g;
  Body b(m = 1, r_cm = {0.5, 0, 0}, I = diagonal({0.1, 0.1, Izz}));
  Spherical j(parent = world, child = b, phi(start = 0.3));
end P;
"""
    m = mechdsl.loads(text)
    m.with_params(Izz=0.2 * (1 + 5e-7))               # rounding: accepted
    with pytest.raises(MechError) as e:
        m.with_params(Izz=0.25)
    assert e.value.diagnostics[0].code == "E509"
