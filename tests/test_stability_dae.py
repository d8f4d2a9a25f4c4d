"""The constrained cases of the stability suite (benchmarks/stability) on small sizes.

Cartesian pendulum (closed form), Andrews' squeezer (the IVP Test Set's reference), the
four-bar's change point (the same mechanism in one coordinate), the Bricard linkage's
redundant constraint (rank of G, energy, loop closure).  Full sizes are marked slow.
"""
from __future__ import annotations

import pytest

from conftest import run_stability_case

CASES = ["cartesian", "andrews", "fourbar", "bricard"]


@pytest.mark.slow_cases('bricard', 'cartesian', 'fourbar')  # CPU budget: the cheaper tests of this file stay in the default run
@pytest.mark.parametrize("name", CASES)
def test_stability_dae_small(name):
    run_stability_case(name, "small")


@pytest.mark.slow
@pytest.mark.parametrize("name", CASES)
def test_stability_dae_full(name):
    run_stability_case(name, "full")
