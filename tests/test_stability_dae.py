"""The constrained cases of the stability suite (benchmarks/stability) on small sizes.

Cartesian pendulum (closed form), Andrews' squeezer (the IVP Test Set's reference), the
four-bar's change point (the same mechanism in one coordinate), the Bricard linkage's
redundant constraint (rank of G, energy, loop closure).  Full sizes are marked slow.
"""
from __future__ import annotations

import importlib
import sys

import pytest

from conftest import ROOT

sys.path.insert(0, str(ROOT / "benchmarks"))

CASES = ["cartesian", "andrews", "fourbar", "bricard"]


def _run(name, size):
    mod = importlib.import_module(f"stability.{name}")
    case = mod.run(size)
    assert case.checks, f"{name}: no checks"
    assert case.holds, "\n" + case.report()
    return case


@pytest.mark.parametrize("name", CASES)
def test_stability_dae_small(name):
    _run(name, "small")


@pytest.mark.slow
@pytest.mark.parametrize("name", CASES)
def test_stability_dae_full(name):
    _run(name, "full")
