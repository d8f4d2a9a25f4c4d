"""The error estimate's comparison of a run with its companion (estimate.py), without CasADi:
what a prepared warm run (warm_run.py) computes the same way."""
from __future__ import annotations

import math


def compare(r, other, factor: float, s, unit_of) -> None:
    """Fill r.metadata["accuracy"] from the companion ``other`` (times ``t``, coordinates ``q``,
    ``failure``): the largest difference over the common times divided by ``factor``, where,
    its unit (``unit_of(coordinate)``), its ratio to the tolerance class of the settings ``s``."""
    import numpy as np

    acc = r.metadata.setdefault("accuracy", {})
    idx, jdx = common_times(r.t, other.t, s.t_end - s.t_start)
    qa, qb, ta = r.q[idx], other.q[jdx], r.t[idx]
    if len(ta) == 0:
        why = (f"the companion run failed at its start ({other.failure})" if other.failure is not None
               else "no output time in common with the companion run")
        acc.update(error_estimate=None, error_estimate_unavailable=why)
        return
    fill(r, np.abs(qa - qb), ta, factor, s, unit_of, other.failure)


def fill(r, diff, ta, factor: float, s, unit_of, failure=None) -> None:
    """r.metadata["accuracy"] from the differences ``diff`` (times ``ta``, coordinates) of the run
    and its companion, divided by ``factor`` (the contact companion's segments give theirs
    directly: backends/event_companion.py); ``failure``: the companion's, noted."""
    import numpy as np

    acc = r.metadata.setdefault("accuracy", {})
    diff = np.asarray(diff, float) / factor                  # (times, coordinates)
    if not np.isfinite(np.add.reduce(diff, axis=None)):
        diff[~np.isfinite(diff)] = np.inf
    per = diff.max(axis=0) if diff.size else np.zeros(len(r.coordinates))
    if r.q.size:
        qmax = np.abs(r.q).max(axis=0)
        if np.isnan(qmax).any():
            qmax = np.nanmax(np.abs(r.q), axis=0)
    else:
        qmax = np.zeros(len(r.coordinates))
    report(acc, r.coordinates, per.tolist(), qmax.tolist(), lambda k: float(ta[int(np.argmax(diff[:, k]))]), s,
           unit_of, failure)


def report(acc: dict, coordinates, per: list, qmax: list, time_of, s, unit_of, failure=None) -> None:
    """The estimate's entries of ``acc`` from each coordinate's largest difference ``per`` and
    largest magnitude ``qmax`` (lists of floats; ``time_of(k)``: the time of coordinate k's
    largest difference): in plain Python, with numpy's rules for nan (max and argmax: the first
    nan) and division, so that compare (numpy) and a prepared warm run (warm_run.py, plain
    buffers) give the same numbers."""
    if not per:
        acc.update(error_estimate=0.0, error_estimate_ratio=0.0)
        return
    tol = [s.rtol * q + s.atol for q in qmax]                # tolerance_class(r.q, rtol, atol)
    k = _argmax(per)
    acc.update(error_estimate=per[k], error_estimate_coordinate=coordinates[k],
               error_estimate_unit=unit_of(coordinates[k]), error_estimate_time=time_of(k),
               error_estimate_ratio=_max([_div(a, b) for a, b in zip(per, tol)]))
    rel = [_div(a, q + s.atol) for a, q in zip(per, qmax)]    # over each coordinate's largest magnitude
    kr = _argmax(rel)
    acc.update(error_estimate_relative=rel[kr], error_estimate_relative_coordinate=coordinates[kr])
    if s.error_estimate == "coordinates":
        acc["error_estimate_by_coordinate"] = dict(zip(coordinates, per))
        acc["tolerance_class"] = dict(zip(coordinates, tol))
    if failure is not None:
        acc["error_estimate_note"] = (f"the companion run stopped at t = {failure.time:.6g} "
                                      f"({failure.cause}): the estimate covers the times before")


def _argmax(xs: list) -> int:
    """numpy.argmax of a list of floats: the first nan, else the first largest."""
    for i, x in enumerate(xs):
        if x != x:
            return i
    return xs.index(max(xs))


def _max(xs: list) -> float:
    """numpy's max of a list of floats: nan when there is one."""
    return xs[_argmax(xs)]


def _div(a: float, b: float) -> float:
    """a / b as numpy divides float64 (IEEE: x / 0 is inf with x's sign, 0 / 0 is nan)."""
    if b == 0.0:
        if a == 0.0 or a != a:
            return float("nan")
        return math.copysign(math.inf, a) * math.copysign(1.0, b)
    return a / b


def every_kth(t, u, span: float) -> int | None:
    """k when the times ``u`` are every k-th of the times ``t`` (up to 1e-12 of the span; no
    repeated times in t: the companion's grid), else None.  Plain Python over sequences."""
    if len(u) < 2 or len(t) < 2 or (len(t) - 1) % (len(u) - 1):
        return None
    k = (len(t) - 1) // (len(u) - 1)
    if max(abs(a - b) for a, b in zip(t[::k], u)) > 1e-12 * max(span, 1e-300):
        return None
    return k if all(b > a for a, b in zip(t, t[1:])) else None


def common_times(t, u, span: float) -> tuple:
    """Indices (i, j) with t[i] = u[j] up to 1e-12 of the span (grids computed alike may differ
    in the last bit); rows of events (repeated times) are skipped.  The companion's grid (every
    k-th time of t, no repeated times): two slices instead of index arrays."""
    import numpy as np

    if not len(t) or not len(u):
        return np.zeros(0, int), np.zeros(0, int)
    if len(u) >= 2 and (len(t) - 1) % (len(u) - 1) == 0:       # the companion's grid: every k-th time
        k = (len(t) - 1) // (len(u) - 1)
        if np.abs(t[::k] - u).max() <= 1e-12 * max(span, 1e-300) and (t[1:] > t[:-1]).all():
            return slice(None, None, k), slice(None)       # (no repeated times: rows of events)
    j = np.clip(np.searchsorted(u, t), 0, len(u) - 1)
    jm = np.clip(j - 1, 0, len(u) - 1)
    j = np.where(np.abs(u[jm] - t) < np.abs(u[j] - t), jm, j)
    ok = np.abs(u[j] - t) <= 1e-12 * max(span, 1e-300)
    ok &= np.r_[True, np.diff(t) > 0] & np.r_[np.diff(t) > 0, True]
    i = np.flatnonzero(ok)
    return i, j[i]
