"""Input tables are data (issue 24, item 3): the stepping loop reads them at run time, never as
code.  A table of 10^6 samples runs (it used to be unrolled into C: 60,001 samples gave a
2.4 GB C file), adds nothing to the model's compiled code, and the result matches the closed
form of a mass pushed by the tabulated force."""
from __future__ import annotations

import numpy as np
import pytest

import mechdsl
from conftest import needs_cc

SLIDER = """
model Slider
  parameter Real m(unit = "kg") = 2;
  input Real F(unit = "N") "push";
  coordinate Real x(start = 0, speed = 0, unit = "m");
equation
  kinetic = 0.5*m*der(x)^2;
  force(x) = F;
end Slider;
"""


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
@needs_cc
def test_a_million_sample_hold_runs_in_the_loop_and_matches_the_closed_form(tmp_path, monkeypatch):
    monkeypatch.setenv("MECHDSL_CACHE", str(tmp_path))
    m = mechdsl.loads(SLIDER, model="Slider")
    m.simulate(1.0, inputs={"F": 1.0}, error_estimate="off")   # the model's own code, compiled once
    libs = sorted(p.name for p in tmp_path.glob("*.so"))
    n = 1_000_000
    t = np.linspace(0.0, 1.0, n + 1)
    F = np.where(np.arange(n + 1) % 2 == 0, 1.0, -3.0)          # a hold flipping at every sample
    # against the closed form: no error estimate (its companion run steps the million samples again)
    r = m.simulate(1.0, inputs={"F": np.c_[t, F]}, rtol=1e-8, atol=1e-10, points=3, error_estimate="off")
    assert r.success and r.metadata["method"] == "dop853"
    assert any("read by the stepping loop" in s for s in r.metadata["notes"])
    assert sorted(p.name for p in tmp_path.glob("*.so")) == libs      # no code was generated for the table
    # closed form: on [t_k, t_k+1) the acceleration is F_k / m; speeds and positions add up exactly
    a = F[:-1] / 2.0
    h = np.diff(t)
    v = np.r_[0.0, np.cumsum(a * h)]
    x = np.r_[0.0, np.cumsum(v[:-1] * h + 0.5 * a * h * h)]
    assert r.q[-1, 0] == pytest.approx(x[-1], abs=1e-9)
    assert r.qd[-1, 0] == pytest.approx(v[-1], abs=1e-9)
    assert r.stats["steps"] >= n                       # no step crossed a sample
    np.testing.assert_array_equal(r["F"], [1.0, 1.0, F[-1]])


@needs_cc
def test_a_million_sample_linear_table_matches_the_closed_form():
    m = mechdsl.loads(SLIDER, model="Slider")
    t = np.linspace(0.0, 2.0, 1_000_001)
    r = m.simulate(2.0, inputs={"F": mechdsl.table(t, np.sin(t), hold="linear")}, rtol=1e-9, atol=1e-12, points=5,
                   error_estimate="off")                     # against the closed form
    assert r.success and r.metadata["method"] == "dop853"
    # x'' = sin(t) / m: x = (t - sin t) / m (the interpolation error of 2 us samples is ~1e-12)
    np.testing.assert_allclose(r.q[:, 0], (r.t - np.sin(r.t)) / 2.0, rtol=0, atol=1e-8)
    np.testing.assert_allclose(r["F"], np.sin(r.t), rtol=0, atol=1e-11)
