"""A closed-loop model (slider-crank, a DAE) with a unilateral stop, from .mech text.

Checks, independent of the impact code: the work-energy balance E(t) - E(0) = work of the
motor torque + energy changes at the impacts; the pin force equals the slider's mass times
its acceleration (the pin is the only force on the slider along x); the loop stays closed."""
import numpy as np
import pytest

import mechdsl

TEXT = """
model SliderCrankStop "Slider-crank whose slider knocks against a stop"
  parameter Real r(unit = "m") = 0.1;
  parameter Real l(unit = "m") = 0.3;
  parameter Real m1(unit = "kg") = 0.5;
  parameter Real m2(unit = "kg") = 1;
  parameter Real m3(unit = "kg") = 2;
  parameter Real tau(unit = "N.m") = 0.5;
  Rod crank(m = m1, L = r, axis = {1, 0, 0});
  Rod rod(m = m2, L = l, axis = {1, 0, 0});
  Box slider(m = m3, size = {0.06, 0.03, 0.03});
  Revolute j1(parent = world, child = crank.a, axis = {0, 0, 1}, phi(start = pi/2, speed = 10));
  Revolute j2(parent = crank.b, child = rod.a, axis = {0, 0, 1},
              phi(start = -pi/2 - asin(r/l), fixed = false, speed_fixed = false));
  Prismatic j3(parent = world, child = slider, axis = {1, 0, 0},
               s(start = sqrt(l^2 - r^2), fixed = false, speed_fixed = false));
  Revolute j4(parent = rod.b, child = slider, axis = {0, 0, 1}) "closes the loop";
  Torque motor(body = crank, tau = {0, 0, tau});
  Contact stop(point = slider, surface = "plane", normal = {1, 0, 0}, offset = 0.23, e = 0.5);
  output Real x_slider(unit = "m") = slider.x;
  output Real F_pin[3] = reaction_force(j4);
  output Real crank_end_x = crank.b.x;
  output Real crank_end_y = crank.b.y;
end SliderCrankStop;
"""


@pytest.fixture(scope="module")
def run():
    m = mechdsl.loads(TEXT)
    return m.simulate(1.0, rtol=1e-10, atol=1e-12, points=2001, error_estimate="off")   # exact balances, no estimate


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
def test_impacts_and_energy_balance(run):
    r = run
    assert r.success, r.message
    imp = [e for e in r.events if e["kind"] == "impact"]
    assert len(imp) == 2 and all(e["contact"] == "stop" for e in imp)
    assert all(e["speed_after"] == pytest.approx(-0.5 * e["speed_before"], rel=1e-9) for e in imp)
    # work of the constant motor torque: tau * (phi(t) - phi(0)), exact
    work = 0.5 * (r["j1.phi"] - r["j1.phi"][0])
    jumps = np.array([sum(e["energy_change"] for e in imp if e["time"] <= t) for t in r.t])
    balance = r["energy"] - r["energy"][0] - work - jumps
    assert np.max(np.abs(balance)) < 1e-8


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
def test_pin_force_accelerates_the_slider(run):
    r = run
    v = r["der(j3.s)"]
    a = np.gradient(v, r.t)
    F = r["F_pin[1]"]
    # away from the impacts (central differences across a jump are meaningless)
    ok = np.ones(len(r.t), bool)
    for e in r.events:
        ok &= np.abs(r.t - e["time"]) > 3 * (r.t[1] - r.t[0])
    ok[[0, -1]] = False
    assert np.max(np.abs(F[ok] - 2.0 * a[ok])) < 1e-3 * max(1.0, np.max(np.abs(F[ok])))


def test_loop_stays_closed(run):
    r = run
    # slider at x = sqrt(l^2 - (crank end height)^2) + crank end x
    x = r["crank_end_x"] + np.sqrt(0.3 ** 2 - r["crank_end_y"] ** 2)
    assert np.max(np.abs(x - r["x_slider"])) < 1e-9
    assert np.all(r["x_slider"] >= 0.23 - 1e-10)
