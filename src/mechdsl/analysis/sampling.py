"""Deterministic quasi-random points (a Halton sequence) for the guesses of the equilibrium
searches (equilibrium.py, manifold.py): the same points on every run, spread evenly."""
from __future__ import annotations

import numpy as np


def halton(i: int, dim: int) -> np.ndarray:
    """The i-th point (i >= 1) of the Halton sequence in [0, 1)^dim (bases: the first primes;
    beyond 20 dimensions the sequence restarts at a later index)."""
    primes = [2, 3, 5, 7, 11, 13, 17, 19, 23, 29, 31, 37, 41, 43, 47, 53, 59, 61, 67, 71]
    out = np.zeros(dim)
    for d in range(dim):
        b = primes[d % len(primes)]
        f, r, k = 1.0, 0.0, i + (d // len(primes)) * 7919
        while k > 0:
            f /= b
            r += f * (k % b)
            k //= b
        out[d] = r
    return out
