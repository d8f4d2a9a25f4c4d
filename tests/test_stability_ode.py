"""The stability suite (benchmarks/stability) on small sizes: what fails and what works.

Each case runs its scene and checks its claims against independent references (closed
forms, scipy on Euler's rigid-body equations, two methods at a tight tolerance); see the
case modules.  The full sizes (the charts of docs/performance.md) are marked slow.
"""
from __future__ import annotations

import pytest

from conftest import run_stability_case

CASES = ["stiff", "energy", "gimbal", "chaos"]


@pytest.mark.slow_cases('chaos', 'energy', 'stiff')  # CPU budget: the cheaper tests of this file stay in the default run
@pytest.mark.parametrize("name", CASES)
def test_stability_small(name):
    run_stability_case(name, "small")


@pytest.mark.slow
@pytest.mark.parametrize("name", CASES)
def test_stability_full(name):
    run_stability_case(name, "full")
