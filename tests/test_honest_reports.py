"""Issue 23, part 4: the smaller silent wrong answers, each against what it should say."""
import math
import warnings

import numpy as np
import pytest

import mechdsl
from conftest import MODELS

STIFF = """
model Stiff "a Cartesian pendulum beside a stiff spring on another coordinate"
  parameter Real m(unit = "kg") = 1;
  parameter Real L(unit = "m") = 1.6454;
  parameter Real k(unit = "N/m") = 1e12;
  Gravity gravity(g = {0, -9.81, 0});
  PointMass bob(m = m, r(start = {0.3, -1.6}));
  coordinate Real s(start = 0.001, unit = "m");
equation
  kinetic = 1/2*m*der(s)^2;
  potential = 1/2*k*s^2;
  bob.x^2 + bob.y^2 = L^2 "rod";
end Stiff;
"""


def test_a_positive_eigenvalue_beside_a_stiff_spring_is_not_zero():
    """The constrained equilibrium at the bottom has the reduced Hessian eigenvalue m g / L = 5.962
    (and k along s): stable.  Before, a tolerance of 1e-9 x max|K| (1e12) called 5.962 a zero
    eigenvalue ("undetermined"), and one force scale for all coordinates accepted a dozen points
    along the circle, where gravity still pulls with up to 9.81 N, as equilibria."""
    eqs = mechdsl.loads(STIFF).equilibria()
    assert len(eqs) == 1
    (e,) = eqs
    assert e.q == pytest.approx([0.0, -1.6454, 0.0], abs=1e-12)
    assert e.stable is True and "positive definite" in e.reason
    assert e.hessian_eigenvalues == pytest.approx([9.81 / 1.6454, 1e12], rel=1e-9)
