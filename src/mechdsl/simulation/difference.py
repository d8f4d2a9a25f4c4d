"""The error estimate's comparison of a run with its companion (estimate.py), without CasADi:
what a prepared warm run (warm_run.py) computes the same way."""
from __future__ import annotations

import numpy as np

SMALL = 16       # coordinates up to this many: the comparison's last steps on Python floats

def compare(r, other, factor: float, s, unit_of, rt=None) -> None:
    """Fill r.metadata["accuracy"] from the companion ``other`` (times ``t``, coordinates ``q``,
    ``failure``): the largest difference over the common times divided by ``factor``, where,
    its unit (``unit_of(coordinate)``), its ratio to the tolerance class of the settings ``s``.
    ``rt``: the stepping loop's runtime library (ctypes) when it is loaded: the differences,
    their places and the run's largest magnitudes in one pass in C (crk_compare), the same
    numbers as the numpy below."""
    acc = r.metadata.setdefault("accuracy", {})
    fast = _in_c(rt, r, other, s.t_end - s.t_start, factor) if rt is not None else None
    if fast is not None:
        per, at, qmax, ta = fast
        time_of = lambda k: float(ta[int(at[k])])       # noqa: E731
    else:
        per, qmax, ta, diff = _in_numpy(r, other, factor, s)
        if per is None:
            why = (f"the companion run failed at its start ({other.failure})" if other.failure is not None
                   else "no output time in common with the companion run")
            acc.update(error_estimate=None, error_estimate_unavailable=why)
            return
        time_of = lambda k: float(ta[int(np.argmax(diff[k]))])      # noqa: E731
    if fast is not None and len(per) <= SMALL and s.atol > 0 and np.isfinite(np.add.reduce(qmax)):
        # a few coordinates, every magnitude finite, no division by 0: the same IEEE operations on Python floats
        # (numpy's call per operation on a 2-vector cost more than the operation)
        per_l, qmax_l, rtol, atol = per.tolist(), qmax.tolist(), s.rtol, s.atol
        tol = [rtol * q + atol for q in qmax_l]
        k = per_l.index(max(per_l))                         # the first largest, as argmax
        ratio = max([p / t for p, t in zip(per_l, tol)])
        rel_l = [p / (q + atol) for p, q in zip(per_l, qmax_l)]
        kr = rel_l.index(max(rel_l))
        acc.update(error_estimate=per_l[k], error_estimate_coordinate=r.coordinates[k],
                   error_estimate_unit=unit_of(r.coordinates[k]), error_estimate_time=time_of(k),
                   error_estimate_ratio=ratio, error_estimate_relative=rel_l[kr],
                   error_estimate_relative_coordinate=r.coordinates[kr])
        tol = np.array(tol)
    else:
        tol = s.rtol * qmax + s.atol if r.q.size else qmax        # tolerance_class(r.q, rtol, atol)
        if not len(per):
            acc.update(error_estimate=0.0, error_estimate_ratio=0.0)
            return
        k = int(np.argmax(per))
        acc.update(error_estimate=float(per[k]), error_estimate_coordinate=r.coordinates[k],
                   error_estimate_unit=unit_of(r.coordinates[k]),
                   error_estimate_time=time_of(k), error_estimate_ratio=float((per / tol).max()))
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


def _in_numpy(r, other, factor, s):
    """(per coordinate the largest difference / factor, the run's largest magnitudes, the common
    times, the differences (coordinates, times)); per None when there is no common time."""
    idx, jdx = common_times(r.t, other.t, s.t_end - s.t_start)
    qa, qb, ta = r.q[idx], other.q[jdx], r.t[idx]
    if len(ta) == 0:
        return None, None, ta, None
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
    return per, qmax, ta, diff


def _rows(a, n: int):
    """(address, row stride in doubles) of a (rows, n) float64 array whose rows are n contiguous
    doubles at a fixed stride, else None."""
    if (a.dtype != np.float64 or a.ndim != 2 or a.shape[1] != n or a.strides[1] != 8 or a.strides[0] % 8
            or a.strides[0] < 8 * n):
        return None
    return a.ctypes.data, a.strides[0] // 8


def _in_c(rt, r, other, span, factor):
    """_in_numpy's numbers by the runtime's crk_compare when the companion's times are every
    k-th of the run's (its own grid) and the arrays are laid out as the runs leave them;
    (per, index of each coordinate's largest difference among the common times, qmax, the
    common times) or None (the numpy path then)."""
    t, u, qa, qb = r.t, other.t, r.q, other.q
    nt, nu = len(t), len(u)
    n = qa.shape[1] if qa.ndim == 2 else 0
    if (n == 0 or nu < 2 or nt < nu or (nt - 1) % (nu - 1) or qa.shape[0] != nt or qb.ndim != 2
            or qb.shape != (nu, n) or t.dtype != np.float64 or u.dtype != np.float64
            or not t.flags.c_contiguous or not u.flags.c_contiguous):
        return None
    a, b = _rows(qa, n), _rows(qb, n)
    if a is None or b is None:
        return None
    k = (nt - 1) // (nu - 1)
    out = np.empty(3 * n)
    fn = _compare_fn(rt)
    if fn is None or fn(t.ctypes.data, nt, u.ctypes.data, nu, k, 1e-12 * max(span, 1e-300), a[0], a[1], b[0], b[1],
                        n, float(factor), out.ctypes.data):
        return None
    return out[:n], out[n:2 * n], out[2 * n:], t[::k]


def _compare_fn(rt):
    """The runtime's crk_compare with its argument types, or None (a runtime built before it)."""
    import ctypes

    fn = getattr(rt, "_compare", None)
    if fn is None:
        try:
            fn = rt.crk_compare
        except AttributeError:
            fn = False
        else:
            v, i, d = ctypes.c_void_p, ctypes.c_longlong, ctypes.c_double
            fn.restype, fn.argtypes = ctypes.c_int, [v, i, v, i, i, d, v, i, v, i, i, d, v]
        rt._compare = fn
    return fn or None


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
