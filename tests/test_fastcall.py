"""Model.fast_function (issue 24, item 6): the model's Function called from Python through
preallocated buffers, compiled, with p and u bound.  It must give what the plain Function
gives (at random states, the parameters and inputs bound as asked)."""
from __future__ import annotations

import numpy as np
import pytest

import mechdsl

from conftest import MODELS
from mechdsl.eom.codegen import find_compiler



@pytest.mark.slow_cases('True')  # CPU budget: the cheaper tests of this file stay in the default run
@pytest.mark.parametrize("compiled", [True, False])
def test_fast_function_equals_the_plain_call(compiled):
    m = mechdsl.load(str(MODELS / "arm7.mech"))
    f = m.fast_function(compiled=compiled)
    plain = m.casadi()["ode"]
    assert f.inputs == ("t", "x")
    if compiled and find_compiler() is not None:
        assert f.function.class_name() == "External"
    rng = np.random.default_rng(4)
    for _ in range(5):
        x = rng.uniform(-1, 1, 2 * m.eom.n)
        a = f(0.3, x)
        b = np.array(plain(0.3, x, [], m.parameter_vector()), float).ravel()
        np.testing.assert_allclose(a, b, rtol=1e-12, atol=1e-12)
        assert a is not f(0.3, x)                     # a new array each call


def test_fast_function_binds_parameters_and_inputs():
    m = mechdsl.load(str(MODELS / "cart_pole.mech"), model="CartPole")
    p = m.parameter_vector(l=2.0)
    f = m.fast_function(p=p, u=[3.0])
    x = np.array([0.1, 0.4, -0.2, 0.3])
    want = np.array(m.casadi()["ode"](0.0, x, [3.0], p), float).ravel()
    np.testing.assert_allclose(f(0.0, x), want, rtol=1e-12, atol=1e-13)
    other = np.array(m.casadi()["ode"](0.0, x, [0.0], m.parameter_vector()), float).ravel()
    assert np.abs(f(0.0, x) - other).max() > 1e-3              # the binding matters
    np.testing.assert_allclose(m.fast_function()(0.0, x), other, rtol=1e-12, atol=1e-13)
