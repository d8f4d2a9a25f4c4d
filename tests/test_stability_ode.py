"""The stability suite (benchmarks/stability) on small sizes: what fails and what works.

Each case runs its scene and checks its claims against independent references (closed
forms, scipy on Euler's rigid-body equations, two methods at a tight tolerance); see the
case modules.  The full sizes (the charts of docs/performance.md) are marked slow.
"""
from __future__ import annotations

import importlib
import sys

import pytest

from conftest import ROOT

sys.path.insert(0, str(ROOT / "benchmarks"))

CASES = ["stiff", "energy", "gimbal", "chaos"]


def _run(name, size):
    mod = importlib.import_module(f"stability.{name}")
    case = mod.run(size)
    assert case.checks, f"{name}: no checks"
    assert case.holds, "\n" + case.report()
    return case


@pytest.mark.parametrize("name", CASES)
def test_stability_small(name):
    _run(name, "small")


@pytest.mark.slow
@pytest.mark.parametrize("name", CASES)
def test_stability_full(name):
    _run(name, "full")
