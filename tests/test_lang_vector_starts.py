"""Issue 17: vector starts of spatial joints. `omega(start = {..}, frame = ..)` on Spherical and
Free joints for every chart, `r(start = ..)`, `v(start = ..)` on Free joints; checked at the
start state against the given vectors and the closed-form energy, and a torque-free
axisymmetric body started from its body angular velocity precesses at the closed-form rate."""
from __future__ import annotations

import casadi as ca
import numpy as np
import pytest

import mechdsl
from mechdsl.diagnostics import MechError
from reach_util import evaluator

I_DIAG = (1.0, 2.0, 3.0)
M = 2.0
W0 = (0.7, -1.1, 1.9)
R0 = (0.3, -0.2, 1.5)
V0 = (1.0, 0.5, -2.0)


def _quat():
    n = np.array([1.0, 2.0, -0.5]) / np.linalg.norm([1.0, 2.0, -0.5])
    return [np.cos(0.35)] + list(np.sin(0.35) * n)


def start_rotation(chart):
    from scipy.spatial.transform import Rotation
    if chart == "quaternion":
        q = _quat()
        return Rotation.from_quat(q[1:] + q[:1]).as_matrix()
    return Rotation.from_euler(chart.upper(), [0.3, 0.7, -0.4]).as_matrix()   # upper case: intrinsic


def model_text(joint, chart, frame, orient=True):
    if chart == "quaternion":
        opts = 'parametrization = "quaternion"'
        qs = _quat()
        starts = ", ".join(f"q{i}(start = {float(qs[i])!r})" for i in range(4)) if orient else ""
    else:
        opts = f'sequence = "{chart}"'
        starts = "phi(start = 0.3), theta(start = 0.7), psi(start = -0.4)" if orient else ""
    extra = ", r(start = {%s, %s, %s}), v(start = {%s, %s, %s})" % (R0 + V0) if joint == "Free" else ""
    parent = "" if joint == "Free" else "parent = world, "
    return f"""
model Top
  parameter Real w2(unit = "1/s") = {W0[1]};
  Body b(m = {M}, I = diagonal({{{I_DIAG[0]}, {I_DIAG[1]}, {I_DIAG[2]}}}));
  {joint} s({parent}child = b, {opts}{", " + starts if starts else ""},
            omega(start = {{{W0[0]}, w2, {W0[2]}}}, frame = "{frame}"){extra});
  output Real wb[3] = b.w_body;
  output Real w[3] = b.w;
  output Real r[3] = b.r;
  output Real v[3] = b.v;
end Top;
"""


def start_values(m):
    e = m.eom
    f = ca.Function("s", [e.p], [e.q0, e.qd0])
    q0, qd0 = (np.array(x, float).reshape(-1) for x in f(e.param_values))
    names = [f"{n}[{i}]" for n in ("wb", "w", "r", "v") for i in (1, 2, 3)]
    vals = evaluator(e, *[e.outputs[k] for k in names], e.T)(q0, qd0)
    out = dict(zip(names + ["T"], vals))
    vec = lambda n: np.concatenate([out[f"{n}[{i}]"] for i in (1, 2, 3)])  # noqa: E731
    return vec("wb"), vec("w"), vec("r"), vec("v"), out["T"][0]


CHARTS = ["zyx", "zxz", "xyz", "yzy", "quaternion"]


@pytest.mark.parametrize("joint", ["Spherical", "Free"])
@pytest.mark.parametrize("frame", ["body", "world"])
@pytest.mark.parametrize("chart", CHARTS)
def test_omega_start_gives_the_angular_velocity_and_energy(joint, chart, frame):
    m = mechdsl.loads(model_text(joint, chart, frame))
    wb, w, r, v, T = start_values(m)
    assert (wb if frame == "body" else w) == pytest.approx(W0, rel=1e-12, abs=1e-12)
    R = start_rotation(chart)                      # independent: scipy's rotation of the start chart
    wb_expect = np.array(W0) if frame == "body" else R.T @ np.array(W0)
    assert wb == pytest.approx(wb_expect, rel=1e-12, abs=1e-12)
    T_rot = 0.5 * wb_expect @ (np.array(I_DIAG) * wb_expect)
    T_expect = T_rot + (0.5 * M * np.dot(V0, V0) if joint == "Free" else 0.0)
    assert T == pytest.approx(T_expect, rel=1e-12)
    assert np.linalg.norm(w) == pytest.approx(np.linalg.norm(W0), rel=1e-12)   # a rotation keeps the length
    if joint == "Free":
        assert r == pytest.approx(R0, rel=1e-12) and v == pytest.approx(V0, rel=1e-12)


def test_world_and_body_frames_differ_by_the_start_rotation():
    wb, w, *_ = start_values(mechdsl.loads(model_text("Spherical", "zyx", "body")))
    assert not np.allclose(w, W0)          # the start orientation is not the identity
    assert wb == pytest.approx(W0, rel=1e-12)


@pytest.mark.parametrize("chart", ["zyx", "quaternion"])
def test_torque_free_axisymmetric_precession(chart):
    """A = I1 = I2, C = I3: the symmetry axis e3 turns about the fixed angular momentum L at the
    rate |L| / A (Euler), and w3 stays constant."""
    A, Cz = 1.0, 1.8
    text = model_text("Spherical", chart, "body").replace(
        "diagonal({1.0, 2.0, 3.0})", f"diagonal({{{A}, {A}, {Cz}}})").replace(
        "end Top;", "  output Real e3[3] = b.R*{0, 0, 1};\n  output Real R1[3] = b.R*{1, 0, 0};\n"
                    "  output Real R2[3] = b.R*{0, 1, 0};\nend Top;")
    m = mechdsl.loads(text)
    r = m.simulate(2.0, points=41, rtol=1e-11, atol=1e-12)
    assert r.success
    sig = r.signals
    e3 = np.stack([sig[f"e3[{i}]"] for i in (1, 2, 3)], axis=1)
    R_0 = np.stack([[sig[f"R{k}[{i}]"][0] for i in (1, 2, 3)] for k in (1, 2)] + [e3[0]], axis=1)
    L = R_0 @ (np.array([A, A, Cz]) * np.array(W0))         # world angular momentum at the start
    Lh, rate = L / np.linalg.norm(L), np.linalg.norm(L) / A
    for k in (10, 25, 40):
        ang = rate * r.t[k]
        e = e3[0]
        rot = e * np.cos(ang) + np.cross(Lh, e) * np.sin(ang) + Lh * (Lh @ e) * (1 - np.cos(ang))   # Rodrigues
        assert e3[k] == pytest.approx(rot, abs=1e-7)
    assert sig["wb[3]"] == pytest.approx(np.full(len(r.t), W0[2]), abs=1e-7)


def test_vector_start_errors():
    base = model_text("Spherical", "zyx", "body")
    bad = [(base.replace("phi(start = 0.3)", "phi(start = 0.3, speed = 1)"), "E211"),
           (base.replace('frame = "body"', 'frame = "space"'), "E217"),
           (base.replace("{0.7, w2, 1.9}", "{0.7, w2}"), "E301"),
           (base.replace("omega(start = {0.7, w2, 1.9}", "omega(speed = {0.7, w2, 1.9}"), "E204"),
           (base.replace("b.w_body;", "b.w_body;\n  Rod arm(m = 1, L = 1);\n  Revolute h(parent = world, child = arm.a);")
                .replace("parent = world, child = b", "parent = arm.b, child = b").replace('"body"', '"world"'), "E221"),
           (base.replace("omega(start = {0.7, w2, 1.9}, frame = \"body\")", "omega = {1, 2, 3}"), "E220"),
           (base.replace("theta(start = 0.7)", "theta(start = -pi/2)"), "E222")]
    for text, code in bad:
        with pytest.raises(MechError) as err:
            mechdsl.loads(text)
        assert code in str(err.value), (code, str(err.value))


@pytest.mark.parametrize("change, code, message", [
    (('frame = "body"', "frame = 3"), "E217", "the frame of omega must be a string, got a scalar"),
    (("{0.7, w2, 1.9}", '{0.7, w2, "a"}'), "E301", "the start of 'omega' of 's' must be numbers, got a string"),
])
def test_vector_start_errors_of_the_wrong_kind_say_what_and_where(change, code, message):
    """A non-string frame and a string inside the start vector: the message says what is wrong
    and points at the value (not at the joint, not "'' is not a valid frame")."""
    text = model_text("Spherical", "zyx", "body").replace(*change)
    with pytest.raises(MechError) as err:
        mechdsl.loads(text)
    d = err.value.first
    assert (d.code, d.message) == (code, message)
    line = text.splitlines()[d.span.line - 1]
    assert change[1] in line and line.index(change[1]) <= d.span.col - 1 < line.index(change[1]) + len(change[1])
