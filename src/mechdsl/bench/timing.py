"""CPU time of a run: the minimum over repeats after one warm-up run.

The clock is ``time.process_time``: CPU seconds of this process, all threads included
(CasADi integrates in a worker thread).  On a shared machine it is far steadier than the
wall clock, which counts the time other processes hold the cores.  The warm-up run builds
what later runs reuse (CasADi integrator objects and their Jacobians, compiled code); its
time is kept separately.
"""
from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Any, Callable

TIMER = "time.process_time"
LONG = 5.0            # after a warm-up longer than this many CPU seconds, one timed run only


@dataclass(kw_only=True)
class Timing:
    best: float                      # min over the timed runs [s]
    runs: tuple[float, ...]          # every timed run [s]
    warmup: float                    # the warm-up run [s]
    result: Any                      # what the last run returned


def cpu_call(fn: Callable[[], Any]) -> tuple[float, Any]:
    c = time.process_time()
    out = fn()
    return time.process_time() - c, out


def timed(fn: Callable[[], Any], repeats: int, *, ok: Callable[[Any], bool] = lambda r: True,
          long: float = LONG) -> Timing:
    """Warm up once, then time ``repeats`` runs (one when the warm-up took longer than
    ``long``).  A warm-up whose result is not ``ok`` (a failed run) is not repeated: its
    time is the measurement."""
    warm, res = cpu_call(fn)
    if not ok(res) or repeats < 1:
        return Timing(best=warm, runs=(warm,), warmup=warm, result=res)
    runs = []
    for _ in range(1 if warm > long else repeats):
        dt, res = cpu_call(fn)
        runs.append(dt)
    return Timing(best=min(runs), runs=tuple(runs), warmup=warm, result=res)


class OverBudget(Exception):
    """Raised from a run's progress callback when the run has used its CPU seconds."""

    def __init__(self, t: float, cpu: float):
        super().__init__(f"stopped at t = {t:.6g} after {cpu:.3g} s of CPU")
        self.t, self.cpu = t, cpu


def cpu_cap(seconds: float, marks: list | None = None):
    """A progress callback (t, t_end) for simulate() that raises OverBudget once the run has
    used ``seconds`` of CPU since the callback was made.  The simulator calls it between
    output points (or segments, or events), so a run is stopped there, not inside a
    CasADi call.  ``marks`` (a list) collects (cpu, t) of every call."""
    c0 = time.process_time()

    def progress(t, _t_end):
        c = time.process_time() - c0
        if marks is not None:
            marks.append((c, float(t)))
        if c > seconds:
            raise OverBudget(float(t), c)

    return progress
