"""Shared by the sweep tests: a sweep interrupted (KeyboardInterrupt) at its n-th chunk."""
from __future__ import annotations


def interrupt_at_chunk(monkeypatch, n: int) -> list:
    """Make the n-th chunk a sweep starts raise KeyboardInterrupt (as Ctrl-C there would);
    returns the list of chunk starts seen."""
    from mechdsl.sweep import runs, schedulers

    calls: list = []

    def interrupted(job, first, values):
        calls.append(first)
        if len(calls) == n:
            raise KeyboardInterrupt
        return runs.run_chunk(job, first, values)

    monkeypatch.setattr(schedulers, "run_chunk", interrupted)
    return calls
