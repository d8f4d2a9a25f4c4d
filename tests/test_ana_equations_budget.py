"""`mech equations` decides what to print by counting operations, never by the clock: the same
model gives the same text on an idle and on a loaded machine (issue 11)."""
from __future__ import annotations

import os
import signal

import pytest

from mechdsl.api import load_model_ir
from mechdsl.mechanics.printing import format_equations
import mechdsl.examples

MODELS = str(mechdsl.examples.folder())


def test_a_slow_machine_prints_the_same_equations(monkeypatch):
    """A machine 10^5 times slower is simulated by shrinking every interval timer: the output
    must not change (before: the 20 s alarm fired and only the structure was printed)."""
    model = load_model_ir(os.path.join(MODELS, "pendulum.mech"))
    idle = format_equations(model)
    assert "Lagrange's equations in 1 coordinate" in idle
    real = signal.setitimer
    monkeypatch.setattr(signal, "setitimer", lambda which, seconds, *a: real(which, min(seconds, 2e-4) if seconds else 0))
    assert format_equations(model) == idle


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
def test_the_operation_budget_is_deterministic():
    model = load_model_ir(os.path.join(MODELS, "double_pendulum.mech"))
    small = [format_equations(model, max_total_ops=50) for _ in range(2)]
    assert small[0] == small[1]
    assert "needs more than 50 operations" in small[0]
    assert "structure of M(q)" in small[0]
    assert "Lagrange's equations in 2 coordinates" in format_equations(model)
