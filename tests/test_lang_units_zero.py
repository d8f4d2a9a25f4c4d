"""Issue 17, units: an exact zero (literal 0, the off-diagonal zeros of diagonal(), zeros(),
skew()) takes any unit, so `diagonal({I1, I2, I3})*w` is an angular momentum."""
from __future__ import annotations

import numpy as np
import pytest

import mechdsl
from mechdsl.diagnostics import MechError
from reach_util import output_values
from test_mech_rigid import omega_zyx

TOP = """
model Top
  parameter Real I1(unit = "kg.m2") = 1;
  parameter Real I2(unit = "kg.m2") = 2;
  parameter Real I3(unit = "kg.m2") = 3;
  Body b(m = 1, I = diagonal({I1, I2, I3}));
  Spherical s(parent = world, child = b);
  output Real L[3](unit = "kg.m2/s") = diagonal({I1, I2, I3})*(transpose(b.R)*b.w);
  output Real Lz(unit = "kg.m2/s") = zeros(3)*b.w + 0*b.x + I3*b.w[3];
  output Real S[3](unit = "1/s") = skew({0, 0, 1})*b.w + zeros(3);
  output Real C[3](unit = "1/s") = cross({0, 0, 1}, b.w);
end Top;
"""


def omega_body_zyx(q, qd):
    """Body angular velocity of the zyx chart R = Rz(phi) Ry(theta) Rx(psi) (by hand)."""
    return omega_zyx(q, qd)


def test_diagonal_times_angular_velocity_is_angular_momentum():
    m = mechdsl.loads(TOP)
    rng = np.random.default_rng(3)
    for _ in range(3):
        q, qd = rng.uniform(-1, 1, 3), rng.uniform(-2, 2, 3)
        names = ["L[1]", "L[2]", "L[3]", "Lz", "S[1]", "S[2]", "S[3]", "C[1]", "C[2]", "C[3]"]
        out = output_values(m, q, qd, names)
        L = np.concatenate([out["L[1]"], out["L[2]"], out["L[3]"]])
        assert L == pytest.approx(np.diag([1.0, 2.0, 3.0]) @ omega_body_zyx(q, qd), rel=1e-12, abs=1e-12)
        S = np.concatenate([out[f"S[{i}]"] for i in (1, 2, 3)])
        C = np.concatenate([out[f"C[{i}]"] for i in (1, 2, 3)])
        assert S == pytest.approx(C, rel=1e-12, abs=1e-12)


def test_a_nonzero_mismatch_is_still_refused():
    bad = TOP.replace("zeros(3)*b.w + 0*b.x", "ones(3)*b.w")
    with pytest.raises(MechError) as err:
        mechdsl.loads(bad)
    assert "E401" in str(err.value)
