"""Reproducible samplers for Monte Carlo sweeps: ``uniform`` and ``normal``.

    s = mechdsl.sample.uniform({"m": (0.5, 2.0), "l": (0.9, 1.1)}, n=1000, seed=1)
    s = mechdsl.sample.normal(m=(1.0, 0.05), n=1000, seed=1)      # (mean, standard deviation)
    s = mechdsl.sample.uniform(m=(0.5, 2), n=100, seed=1) & mechdsl.sample.normal(l=(1, 0.01), n=100, seed=2)
    m.sweep(params=s, t_end=10)

A sampler is a table of ``n`` rows (one run per row).  The numbers depend only on the
ranges, ``n`` and ``seed`` (numpy's PCG64 generator, one stream per name in sorted name
order), never on the machine, the back end or what ran before.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .diagnostics import UsageError

__all__ = ["Sampler", "uniform", "normal"]


@dataclass(frozen=True)
class Sampler:
    """``n`` rows drawn from independent distributions, one per name."""

    dists: tuple[tuple[str, str, float, float, int], ...]     # (name, kind, a, b, seed)
    n: int

    def table(self) -> dict[str, np.ndarray]:
        """The drawn values: {name: array of n}."""
        out = {}
        for name, kind, a, b, seed in self.dists:
            # one independent stream per (seed, name): adding a name does not change the others
            rng = np.random.default_rng([int(seed), *name.encode()])
            out[name] = rng.uniform(a, b, self.n) if kind == "uniform" else rng.normal(a, b, self.n)
        return out

    def __and__(self, other: "Sampler") -> "Sampler":
        if not isinstance(other, Sampler):
            return NotImplemented
        if other.n != self.n:
            raise UsageError(f"cannot combine samplers of {self.n} and {other.n} runs: give both the same n")
        clash = {d[0] for d in self.dists} & {d[0] for d in other.dists}
        if clash:
            raise UsageError(f"{', '.join(sorted(clash))} sampled twice")
        return Sampler(self.dists + other.dists, self.n)

    def __len__(self) -> int:
        return self.n


def uniform(ranges: dict | None = None, *, n, seed: int = 0, **kw) -> Sampler:
    """``n`` runs with each name uniform in [low, high): ``{name: (low, high)}``."""
    return _make("uniform", ranges, kw, n, seed)


def normal(ranges: dict | None = None, *, n, seed: int = 0, **kw) -> Sampler:
    """``n`` runs with each name normal: ``{name: (mean, standard deviation)}``."""
    return _make("normal", ranges, kw, n, seed)


def _make(kind: str, ranges, kw, n, seed) -> Sampler:
    spec = dict(ranges or {})
    spec.update(kw)
    if not spec:
        raise UsageError(f"sample.{kind}: give at least one name with its {_what(kind)}")
    if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n < 1:
        raise UsageError(f"sample.{kind}: the sample size n must be an integer >= 1 (got {n!r})")
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise UsageError(f"sample.{kind}: seed must be an integer >= 0 (got {seed!r})")
    dists = []
    for name in sorted(spec):
        v = spec[name]
        try:
            a, b = (float(x) for x in v)
        except (TypeError, ValueError):
            raise UsageError(f"sample.{kind}: '{name}' needs a pair ({_what(kind)}), got {v!r}") from None
        if not (math.isfinite(a) and math.isfinite(b)):
            raise UsageError(f"sample.{kind}: '{name}' has a non-finite bound {v!r}")
        if kind == "uniform" and not a < b:
            raise UsageError(f"sample.uniform: '{name}' needs low < high (got {a:g}, {b:g})")
        if kind == "normal" and not b > 0:
            raise UsageError(f"sample.normal: '{name}' needs a standard deviation > 0 (got {b:g})")
        dists.append((str(name), kind, a, b, int(seed)))
    return Sampler(tuple(dists), int(n))


def _what(kind: str) -> str:
    return "(low, high)" if kind == "uniform" else "(mean, standard deviation)"
