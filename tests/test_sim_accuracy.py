"""Accuracy of simulate() against closed forms (see ../shared/references, copied in tests/references/README.md)."""
from __future__ import annotations

import numpy as np
import pytest
from scipy.optimize import brentq
from scipy.special import ellipj, ellipk

from mechdsl.simulate import simulate
from sim_models import forced_oscillator, pendulum

T_REF = 2.367841947576237   # L = 1, g = 9.81, from 90 deg: 4 sqrt(L/g) K(sin^2(pi/4)) (references/README.md)


def hermite_crossings(t, q, qd):
    """Times where q falls through 0, located on the cubic Hermite interpolant of (q, qd)."""
    out = []
    for i in np.flatnonzero((q[:-1] > 0) & (q[1:] <= 0)):
        h = t[i + 1] - t[i]

        def c(s, i=i, h=h):
            u = (s - t[i]) / h
            h00, h10, h01, h11 = 2 * u**3 - 3 * u**2 + 1, u**3 - 2 * u**2 + u, -2 * u**3 + 3 * u**2, u**3 - u**2
            return h00 * q[i] + h10 * h * qd[i] + h01 * q[i + 1] + h11 * h * qd[i + 1]

        out.append(brentq(c, t[i], t[i + 1], xtol=1e-15, rtol=1e-15))
    return np.array(out)


def test_reference_value_is_the_elliptic_integral():
    assert abs(4 * np.sqrt(1 / 9.81) * ellipk(np.sin(np.pi / 4) ** 2) - T_REF) < 1e-14


@pytest.mark.parametrize("method", ["erk", "cvodes-adams"])
def test_large_amplitude_pendulum_period(method):
    r = simulate(pendulum(), 4 * T_REF + 0.5, method=method, rtol=1e-12, atol=1e-12, points=8001)
    assert r.success, r.message
    tc = hermite_crossings(r.t, r["theta"], r["der(theta)"])
    assert len(tc) == 4
    periods = np.diff(tc)
    assert np.abs(periods / T_REF - 1).max() < 1e-9, periods - T_REF


def test_pendulum_trajectory_matches_jacobi_elliptic_solution():
    # sin(theta/2) = k cd(w t | k^2), w = sqrt(g/L), k = sin(a/2)   (references/README.md)
    r = simulate(pendulum(), 5.0, method="erk", rtol=1e-11, atol=1e-12, points=201)
    k = np.sin(np.pi / 4)
    sn, cn, dn, _ = ellipj(np.sqrt(9.81) * r.t, k**2)
    exact = 2 * np.arcsin(k * cn / dn)
    assert np.abs(r["theta"] - exact).max() < 1e-8


def test_damped_driven_oscillator_matches_closed_form():
    e = forced_oscillator()
    w, z, F, W = e.param_values
    r = simulate(e, 10.0, method="cvodes-bdf", rtol=1e-10, atol=1e-12, points=101)
    den = (w**2 - W**2) ** 2 + (2 * z * w * W) ** 2
    A, B = F * (w**2 - W**2) / den, F * 2 * z * w * W / den
    wd = w * np.sqrt(1 - z**2)
    C1 = 1.0 - A
    C2 = (0.0 + z * w * C1 - B * W) / wd
    t = r.t
    exact = np.exp(-z * w * t) * (C1 * np.cos(wd * t) + C2 * np.sin(wd * t)) + A * np.cos(W * t) + B * np.sin(W * t)
    assert np.abs(r["x"] - exact).max() < 1e-8
    assert r.metadata["conservative"] is False


def test_t_start_and_time_dependent_force_use_absolute_time():
    e = forced_oscillator()
    full = simulate(e, 4.0, method="erk", rtol=1e-11, atol=1e-12, points=5)
    x2 = {"x": float(full["x"][2]), "der(x)": float(full["der(x)"][2])}
    tail = simulate(e, 4.0, t_start=2.0, x0=x2, method="erk", rtol=1e-11, atol=1e-12, points=3)
    assert tail.t[0] == 2.0
    assert abs(tail["x"][-1] - full["x"][-1]) < 1e-9
