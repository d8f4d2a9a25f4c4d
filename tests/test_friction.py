"""Issue 17: regularized Coulomb friction (Friction component), against closed forms."""
import math

import numpy as np
import pytest

import mechdsl

from conftest import MODELS

FILE = MODELS / "friction.mech"


def test_block_on_incline_decelerates_and_stops_at_the_closed_form_time():
    m = mechdsl.load(FILE, scene="Incline")
    g, alpha, mu, v0, v_eps = 9.81, 0.3, 0.5, 2.0, 1e-4
    a = g * (mu * math.cos(alpha) - math.sin(alpha))          # deceleration while sliding
    t_stop = v0 / a
    r = m.simulate(points=2001)
    t, v, s = r.t, r["v"], r["slide.s"]
    sliding = t < t_stop - 0.01
    assert v[sliding] == pytest.approx(v0 - a * t[sliding], abs=1e-7)
    assert s[sliding] == pytest.approx(v0 * t[sliding] - a * t[sliding]**2 / 2, abs=1e-7)
    # the time the speed falls to 1 cm/s (linear interpolation between output points)
    k = int(np.argmax(v < 0.01))
    t_cross = t[k - 1] + (v[k - 1] - 0.01) / (v[k - 1] - v[k]) * (t[k] - t[k - 1])
    assert t_cross == pytest.approx((v0 - 0.01) / a, abs=1e-6)
    assert s[t > t_stop + 0.1][0] == pytest.approx(v0**2 / (2 * a), abs=1e-3)
    # afterwards the regularized law creeps at v_eps atanh(tan(alpha)/mu) (it cannot hold the block)
    assert v[-1] == pytest.approx(v_eps * math.atanh(math.tan(alpha) / mu), rel=1e-3)


def test_flywheel_with_bearing_friction_torque():
    m = mechdsl.load(FILE, model="FrictionFlywheel")
    I, tau, w0 = 3 * 0.2**2 / 2, 0.05, 10.0                 # disk about its axis: m R^2 / 2
    r = m.simulate(15.0, points=151, rtol=1e-10, atol=1e-10)
    t, w = r.t, r["der(bearing.phi)"]
    t_stop = I * w0 / tau                                   # 12 s
    before = t < t_stop - 0.05
    assert w[before] == pytest.approx(w0 - tau / I * t[before], abs=1e-6)
    assert abs(w[-1]) < 1e-6                                # at rest (no other torque: no creep)
    assert r["bearing.phi"][-1] == pytest.approx(w0**2 / (2 * tau / I), rel=1e-4)


def test_regularization_is_visible_in_check_and_metadata(capsys):
    from mechdsl.cli import main

    rc = main(["check", str(FILE)])             # in this process: the subject is what check prints
    p = capsys.readouterr()
    assert rc == 0, p.err
    assert "rub: Coulomb friction on slide.s: -F tanh(der(slide.s)/v_eps), v_eps = 0.0001" in p.out
    assert "drag: Coulomb friction on bearing.phi" in p.out and "v_eps = 0.001" in p.out
    r = mechdsl.load(FILE, model="FrictionIncline").with_params(v_eps=0.002).simulate(0.1, points=3)
    assert r.metadata["friction"] == ["rub: Coulomb friction on slide.s: -F tanh(der(slide.s)/v_eps), v_eps = 0.002"]


def _bad(line):
    return f"""
model B
  PointMass p(m = 1);
  Prismatic j(parent = world, child = p, axis = {{1, 0, 0}}, s(start = 0, speed = 1));
  {line}
end B;
"""


def test_nonpositive_regularization_is_a_located_error():
    with pytest.raises(mechdsl.MechError) as info:
        mechdsl.loads(_bad("Friction f(coordinate = j.s, F = 1, v_eps = 0);"), filename="b.mech").eom
    d = info.value.diagnostics[0]
    assert d.code == "E241" and "v_eps" in d.message and d.span.line == 5


def test_friction_force_needs_force_units():
    with pytest.raises(mechdsl.MechError) as info:
        mechdsl.loads(_bad('Friction f(coordinate = j.s, F = 1*j.s);'), filename="b.mech").eom
    assert info.value.diagnostics[0].code.startswith("E4")


SLIDE = """
model Slide "a point mass sliding down an incline plane: a persistent contact with friction"
  parameter Real m(unit = "kg") = 2;
  parameter Real g(unit = "m/s2") = 9.81;
  parameter Real alpha(unit = "rad") = 0.3;
  parameter Real mu = 0.5;
  parameter Real v0(unit = "m/s") = 2;
  Gravity gravity(g = {0, -g, 0});
  PointMass block(m = m);
  Planar plane(parent = world, child = block, axis = {0, 0, 1},
               x(start = 0, speed = v0*cos(alpha)), y(start = 0, speed = -v0*sin(alpha)));
  Contact slope(point = block, surface = "plane", normal = {sin(alpha), cos(alpha), 0}, e = 0,
                mu = mu, v_eps = 1e-2);
end Slide;
"""


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
def test_block_sliding_on_a_contact_with_friction():
    """The contact's normal force N = m g cos(alpha) carries the friction mu N: the same stop time
    as the block on the guide, found by the contact simulator with the normal force it computes."""
    g, alpha, mu, v0, m, v_eps = 9.81, 0.3, 0.5, 2.0, 2.0, 1e-2
    a = g * (mu * math.cos(alpha) - math.sin(alpha))
    r = mechdsl.loads(SLIDE, filename="slide.mech").simulate(1.5, points=151, rtol=1e-9, atol=1e-11)
    assert r.success and [e["kind"] for e in r.events] == ["close"]
    t = r.t
    v = r["der(plane.x)"] / math.cos(alpha)                    # speed down the slope
    assert r["der(plane.y)"] == pytest.approx(-math.tan(alpha) * r["der(plane.x)"], abs=1e-9)   # stays on it
    sliding = v > 0.2
    assert v[sliding] == pytest.approx(v0 - a * t[sliding], abs=1e-7)
    assert r["slope.force"] == pytest.approx(m * g * math.cos(alpha), rel=1e-9)
    assert v[-1] == pytest.approx(v_eps * math.atanh(math.tan(alpha) / mu), rel=1e-4)      # the creep
    assert r.metadata["conservative"] is False and not r.metadata["warnings"]   # no claim of conservation


def test_contact_friction_needs_a_point():
    src = """
model G
  coordinate Real y(start = 1);
  Contact c(gap = y, e = 0.5, mu = 0.3);
equation
  kinetic = 1/2*der(y)^2;
  potential = 9.81*y;
end G;
"""
    with pytest.raises(mechdsl.MechError) as info:
        mechdsl.loads(src, filename="g.mech").simulate(1.0, points=3)
    assert info.value.diagnostics[0].code == "E862" and "friction" in info.value.diagnostics[0].message
