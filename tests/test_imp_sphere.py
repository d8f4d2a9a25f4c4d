"""Persistent contact and its release: a particle sliding on a sphere leaves it where the
normal force vanishes (cos th = 2/3 cos th0 from rest); inside a spherical bowl it stays in
contact and moves as a pendulum of length R."""
import numpy as np
import pytest
from scipy.special import ellipk

from imp_models import particle_sphere
from mechdsl.impacts import simulate_with_contacts

R, G, M = 1.0, 9.81, 1.0


@pytest.mark.slow_cases('0.02-0.0', '0.1-0.0')  # CPU budget: the cheaper tests of this file stay in the default run
@pytest.mark.parametrize("th0, v0", [(0.1, 0.0), (0.02, 0.0), (0.3, 1.0)])
def test_particle_leaves_sphere_where_normal_force_vanishes(th0, v0):
    eom, sphere = particle_sphere(R, G, M, th0, speed0=v0)
    r = simulate_with_contacts(eom, [sphere], 3.0, points=301, rtol=1e-10, atol=1e-12)
    assert r.success, r.message
    kinds = [(e["kind"], e["contact"]) for e in r.events]
    assert kinds == [("close", "sphere"), ("release", "sphere")]
    t_rel = r.events[1]["time"]
    # release angle: v^2 = v0^2 + 2 g R (cos th0 - cos th) and g cos th = v^2 / R
    cos_expected = (2 * np.cos(th0) + v0 ** 2 / (G * R)) / 3
    k = np.searchsorted(r.t, t_rel)
    x, y = r.q[k - 1]
    # on the sphere until the release; the grid point just before it is a little higher
    assert np.hypot(x, y) == pytest.approx(R, abs=1e-9)
    assert y / R > cos_expected
    # the release state itself, from a run that ends there
    r2 = simulate_with_contacts(eom, [sphere], t_rel, points=2, rtol=1e-10, atol=1e-12)
    x, y = r2.q[-1]
    assert y / np.hypot(x, y) == pytest.approx(cos_expected, abs=1e-7)
    # the normal force while in contact: m (g cos th - v^2/R) = m g (3 cos th - 2 cos th0) - m v0^2/R
    on = r.t < t_rel
    cos_t = r.q[on, 1] / R
    lam_expected = M * G * (3 * cos_t - 2 * np.cos(th0)) - M * v0 ** 2 / R
    assert np.max(np.abs(r["sphere.force"][on] - lam_expected)) < 1e-6
    assert np.all(r["sphere.force"][~on] == 0.0)
    # afterwards a free parabola that stays off the sphere, energy kept throughout
    assert np.all(r["sphere.gap"][~on] > 0)
    assert np.max(np.abs(r["energy"] - r["energy"][0])) < 1e-8


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
def test_particle_in_bowl_is_a_pendulum():
    th0 = 0.8
    eom, bowl = particle_sphere(R, G, M, th0, inside=True)
    period = 4 * np.sqrt(R / G) * ellipk(np.sin(th0 / 2) ** 2)
    r = simulate_with_contacts(eom, [bowl], period, points=5, rtol=1e-10, atol=1e-12)
    assert r.success, r.message
    assert [e["kind"] for e in r.events] == ["close"]
    # quarter periods: bottom, other side, bottom, back at the start
    ang = np.arctan2(r.q[:, 0], -r.q[:, 1])
    assert ang == pytest.approx([th0, 0.0, -th0, 0.0, th0], abs=1e-7)
    assert np.max(np.abs(np.hypot(r.q[:, 0], r.q[:, 1]) - R)) < 1e-9
    # normal force at the bottom: m g (3 - 2 cos th0)
    assert r["sphere.force"][1] == pytest.approx(M * G * (3 - 2 * np.cos(th0)), rel=1e-7)
