"""The error estimate's comparison of a run with its companion (estimate.py), without CasADi:
what a prepared warm run (warm_run.py) computes the same way."""
from __future__ import annotations

import numpy as np


def compare(r, other, factor: float, s, unit_of) -> None:
    """Fill r.metadata["accuracy"] from the companion ``other`` (times ``t``, coordinates ``q``,
    ``failure``): the largest difference over the common times divided by ``factor``, where,
    its unit (``unit_of(coordinate)``), its ratio to the tolerance class of the settings ``s``."""
    acc = r.metadata.setdefault("accuracy", {})
    idx, jdx = common_times(r.t, other.t, s.t_end - s.t_start)
    qa, qb, ta = r.q[idx], other.q[jdx], r.t[idx]
    if len(ta) == 0:
        why = (f"the companion run failed at its start ({other.failure})" if other.failure is not None
               else "no output time in common with the companion run")
        acc.update(error_estimate=None, error_estimate_unavailable=why)
        return
    # (coordinates, times): each coordinate's values contiguous, so that the reductions over the
    # times run along rows (numpy's max over axis 0 of a (501, 2) block took 23 us, of the
    # transposed copy 3.5 us); the same elements, so the same maxima and the same first argmax
    diff = np.abs(np.ascontiguousarray(qa.T) - np.ascontiguousarray(qb.T)) / factor
    if not np.isfinite(np.add.reduce(diff, axis=None)):
        diff[~np.isfinite(diff)] = np.inf
    per = diff.max(axis=1) if diff.size else np.zeros(len(r.coordinates))
    if r.q.size:
        qmax = np.abs(np.ascontiguousarray(r.q.T)).max(axis=1)
        if np.isnan(qmax).any():
            qmax = np.nanmax(np.abs(r.q), axis=0)
    else:
        qmax = np.zeros(r.q.shape[1] if r.q.ndim == 2 else 0)
    tol = s.rtol * qmax + s.atol if r.q.size else qmax        # tolerance_class(r.q, rtol, atol)
    if not len(per):
        acc.update(error_estimate=0.0, error_estimate_ratio=0.0)
        return
    k = int(np.argmax(per))
    it = int(np.argmax(diff[k]))
    acc.update(error_estimate=float(per[k]), error_estimate_coordinate=r.coordinates[k],
               error_estimate_unit=unit_of(r.coordinates[k]),
               error_estimate_time=float(ta[it]), error_estimate_ratio=float((per / tol).max()))
    size = qmax + s.atol                                      # each coordinate's largest magnitude
    rel = per / size
    kr = int(np.argmax(rel))
    acc.update(error_estimate_relative=float(rel[kr]), error_estimate_relative_coordinate=r.coordinates[kr])
    if s.error_estimate == "coordinates":
        acc["error_estimate_by_coordinate"] = {c: float(v) for c, v in zip(r.coordinates, per)}
        acc["tolerance_class"] = {c: float(v) for c, v in zip(r.coordinates, tol)}
    if other.failure is not None:
        acc["error_estimate_note"] = (f"the companion run stopped at t = {other.failure.time:.6g} "
                                      f"({other.failure.cause}): the estimate covers the times before")


def common_times(t: np.ndarray, u: np.ndarray, span: float) -> tuple[np.ndarray, np.ndarray]:
    """Indices (i, j) with t[i] = u[j] up to 1e-12 of the span (grids computed alike may differ
    in the last bit); rows of events (repeated times) are skipped.  The companion's grid (every
    k-th time of t, no repeated times): two slices instead of index arrays."""
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
