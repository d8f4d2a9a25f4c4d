"""Reproducible samplers for Monte Carlo sweeps: ``uniform``, ``normal``, ``sobol`` and
``latin_hypercube``.

    s = mechdsl.sample.uniform({"m": (0.5, 2.0), "l": (0.9, 1.1)}, n=1000, seed=1)
    s = mechdsl.sample.normal(m=(1.0, 0.05), n=1000, seed=1)      # (mean, standard deviation)
    s = mechdsl.sample.sobol({"m": (0.5, 2.0), "l": (0.9, 1.1)}, n=1024, seed=1)   # quasi-random
    s = mechdsl.sample.latin_hypercube({"m": (0.5, 2.0)}, n=100, seed=1)
    s = mechdsl.sample.uniform(m=(0.5, 2), n=100, seed=1) & mechdsl.sample.normal(l=(1, 0.01), n=100, seed=2)
    m.sweep(params=s, t_end=10)

A sampler is a table of ``n`` rows (one run per row).  The numbers depend only on the
ranges, ``n`` and ``seed``, never on the machine, the back end or what ran before:
``uniform`` and ``normal`` draw one independent stream per name (numpy's PCG64, seeded by
the seed and the name, so adding a name does not change the others); ``sobol`` (scrambled
Sobol' points) and ``latin_hypercube`` (scipy.stats.qmc) place the names of one call jointly
in the unit cube, scaled to their ranges, from a generator seeded by ``seed`` (the same
scipy version gives the same points).  Sobol' points keep their balance for ``n`` a power
of two (each of the n equal slices of every range holds one point); a Latin hypercube has
that property for any ``n``.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .diagnostics import UsageError

__all__ = ["Sampler", "uniform", "normal", "sobol", "latin_hypercube"]

JOINT = ("sobol", "latin_hypercube")        # kinds drawn jointly over the names of one call


@dataclass(frozen=True)
class Sampler:
    """``n`` rows drawn from distributions, one per name (the names of one ``sobol`` or
    ``latin_hypercube`` call jointly)."""

    dists: tuple[tuple[str, str, float, float, int], ...]     # (name, kind, a, b, seed)
    n: int
    groups: tuple[tuple[str, ...], ...] = ()                  # names drawn together (joint kinds)

    def table(self) -> dict[str, np.ndarray]:
        """The drawn values: {name: array of n}."""
        out = {}
        by_name = {d[0]: d for d in self.dists}
        for name, kind, a, b, seed in self.dists:
            if kind in JOINT:
                if name not in out:
                    group = next(g for g in self.groups if name in g)
                    ds = [by_name[g] for g in group]
                    unit = _unit_cube(kind, len(ds), self.n, seed)
                    for j, (g, _, lo, hi, _) in enumerate(ds):
                        out[g] = lo + (hi - lo) * unit[:, j]
                continue
            # one independent stream per (seed, name): adding a name does not change the others
            rng = np.random.default_rng([int(seed), *name.encode()])
            out[name] = rng.uniform(a, b, self.n) if kind == "uniform" else rng.normal(a, b, self.n)
        return {d[0]: out[d[0]] for d in self.dists}

    def __and__(self, other: "Sampler") -> "Sampler":
        if not isinstance(other, Sampler):
            return NotImplemented
        if other.n != self.n:
            raise UsageError(f"cannot combine samplers of {self.n} and {other.n} runs: give both the same n")
        clash = {d[0] for d in self.dists} & {d[0] for d in other.dists}
        if clash:
            raise UsageError(f"{', '.join(sorted(clash))} sampled twice")
        return Sampler(self.dists + other.dists, self.n, self.groups + other.groups)

    def __len__(self) -> int:
        return self.n


def uniform(ranges: dict | None = None, *, n, seed: int = 0, **kw) -> Sampler:
    """``n`` runs with each name uniform in [low, high): ``{name: (low, high)}``."""
    return _make("uniform", ranges, kw, n, seed)


def normal(ranges: dict | None = None, *, n, seed: int = 0, **kw) -> Sampler:
    """``n`` runs with each name normal: ``{name: (mean, standard deviation)}``."""
    return _make("normal", ranges, kw, n, seed)


def sobol(ranges: dict | None = None, *, n, seed: int = 0, **kw) -> Sampler:
    """``n`` runs on scrambled Sobol' points over the box ``{name: (low, high)}`` (the names
    jointly); balanced for ``n`` a power of two."""
    return _make("sobol", ranges, kw, n, seed)


def latin_hypercube(ranges: dict | None = None, *, n, seed: int = 0, **kw) -> Sampler:
    """``n`` runs on a Latin hypercube over the box ``{name: (low, high)}``: each name's range
    cut into ``n`` equal slices holds exactly one run in each."""
    return _make("latin_hypercube", ranges, kw, n, seed)


def _unit_cube(kind: str, d: int, n: int, seed: int) -> np.ndarray:
    """(n, d) points in [0, 1)^d from scipy.stats.qmc, seeded."""
    import warnings

    from scipy.stats import qmc

    cls = qmc.Sobol if kind == "sobol" else qmc.LatinHypercube
    gen = np.random.default_rng(int(seed))
    try:
        engine = cls(d, scramble=True, rng=gen)
    except TypeError:               # scipy before 1.15 names the generator 'seed'
        engine = cls(d, scramble=True, seed=gen)
    with warnings.catch_warnings():
        # Sobol' for n not a power of two: scipy warns that the balance is lost (documented)
        warnings.simplefilter("ignore", UserWarning)
        return np.asarray(engine.random(n), float)


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
        if kind != "normal" and not a < b:
            raise UsageError(f"sample.{kind}: '{name}' needs low < high (got {a:g}, {b:g})")
        if kind == "normal" and not b > 0:
            raise UsageError(f"sample.normal: '{name}' needs a standard deviation > 0 (got {b:g})")
        dists.append((str(name), kind, a, b, int(seed)))
    groups = (tuple(d[0] for d in dists),) if kind in JOINT else ()
    return Sampler(tuple(dists), int(n), groups)


def _what(kind: str) -> str:
    return "(mean, standard deviation)" if kind == "normal" else "(low, high)"
