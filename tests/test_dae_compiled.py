"""Compiled code for the ODE formulations of constrained models (`compiled=True`)."""
from __future__ import annotations

import numpy as np
import pytest

import mechdsl
from mechdsl.eom.codegen import find_compiler

from conftest import MODELS


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
def test_projection_erk_compiled_equals_virtual_machine():
    m = mechdsl.load(MODELS / "andrews.mech")
    vm = m.simulate(0.01, rtol=1e-8, atol=1e-8, method="erk", formulation="projection", points=5)
    nat = m.simulate(0.01, rtol=1e-8, atol=1e-8, method="erk", formulation="projection", points=5, compiled=True)
    if find_compiler() is None:      # no C compiler: the run says so and uses the virtual machine
        assert nat.metadata["compiled"] is False and any("compiled" in n for n in nat.metadata["notes"])
    else:
        assert nat.metadata["compiled"] is True and vm.metadata["compiled"] is False
    # the same arithmetic up to rounding: the same steps, states equal to far below the tolerance
    assert nat.stats["nsteps"] == vm.stats["nsteps"]
    np.testing.assert_allclose(nat.q, vm.q, rtol=1e-10, atol=1e-12)


def test_ggl_says_compiled_code_is_not_used():
    m = mechdsl.load(MODELS / "pendulum_cartesian.mech", scene="Cash")
    r = m.simulate(0.1, formulation="ggl", compiled=True, points=3)
    assert r.metadata["compiled"] is False
    assert any("compiled" in n for n in r.metadata["notes"])
