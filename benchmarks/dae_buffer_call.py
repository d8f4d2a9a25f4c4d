"""The DAE segments' integrator call through a FunctionBuffer (issue 25: Ctrl-C keeps the output
times an interrupted call wrote) against the ordinary call, side by side in one process.

    python benchmarks/dae_buffer_call.py

Prints, per formulation, the CPU time of a 20 s four-bar run (minimum of 3), the ratio
buffer / ordinary, and the largest difference of the final states (the same numbers).
"""
from __future__ import annotations

import time

import mechdsl
import mechdsl.examples
from mechdsl.dae import segments


def run(model, buffered: bool, formulation: str, repeats: int = 3):
    original = segments._buffered
    segments._buffered = original if buffered else (lambda F, args: None)
    try:
        best, r = float("inf"), None
        for _ in range(repeats):
            c0 = time.process_time()
            r = model.simulate(20.0, points=2001, formulation=formulation)
            best = min(best, time.process_time() - c0)
        return best, r
    finally:
        segments._buffered = original


def main() -> None:
    m = mechdsl.load(mechdsl.examples.path("four_bar"))
    print(f"{'formulation':12} {'ordinary [s]':>13} {'buffer [s]':>11} {'ratio':>6} {'segments':>9} {'max |dq|':>9}")
    for f in ("projection", "ggl"):
        (a, ra), (b, rb) = run(m, False, f), run(m, True, f)
        dq = float(abs(ra.q[-1] - rb.q[-1]).max())
        print(f"{f:12} {a:13.3f} {b:11.3f} {b / a:6.3f} {rb.stats.get('segments'):>9} {dq:9.2g}")


if __name__ == "__main__":
    main()
