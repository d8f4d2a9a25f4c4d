"""The error estimate's comparison of a run with its companion (estimate.py), without CasADi:
what a prepared warm run (warm_run.py) computes the same way."""
from __future__ import annotations

import math

from ..eom.vmprog import data_address


def compare(r, other, factor: float, s, unit_of, rt=None) -> None:
    """Fill r.metadata["accuracy"] from the companion ``other`` (times ``t``, coordinates ``q``,
    ``failure``): the largest difference over the common times divided by ``factor``, where,
    its unit (``unit_of(coordinate)``), its ratio to the tolerance class of the settings ``s``.
    ``rt``: the stepping loop's runtime library (ctypes) when it is loaded: the differences,
    their places and the run's largest magnitudes in one pass in C (crk_compare), the same
    numbers as fill's numpy."""
    import numpy as np

    acc = r.metadata.setdefault("accuracy", {})
    fast = _in_c(rt, r, other, s.t_end - s.t_start, factor) if rt is not None else None
    if fast is not None:
        per, at, qmax, ta = fast
        report(acc, r.coordinates, per.tolist(), qmax.tolist(), lambda k: float(ta[int(at[k])]), s, unit_of,
               other.failure)
        return
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
    # (coordinates, times): each coordinate's values contiguous, so that the reductions over the
    # times run along rows (numpy's max over axis 0 of a (501, 2) block took 23 us, of the
    # transposed copy 3.5 us); the same elements, so the same maxima and the same first argmax
    diff = np.ascontiguousarray(np.asarray(diff, float).T) / factor
    if not np.isfinite(np.add.reduce(diff, axis=None)):
        diff[~np.isfinite(diff)] = np.inf
    per = diff.max(axis=1) if diff.size else np.zeros(len(r.coordinates))
    if r.q.size:
        qmax = np.abs(np.ascontiguousarray(r.q.T)).max(axis=1)
        if np.isnan(qmax).any():
            qmax = np.nanmax(np.abs(r.q), axis=0)
    else:
        qmax = np.zeros(len(r.coordinates))
    report(acc, r.coordinates, per.tolist(), qmax.tolist(), lambda k: float(ta[int(np.argmax(diff[k]))]), s,
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


def _rows(a, n: int):
    """(address, row stride in doubles) of a (rows, n) float64 array whose rows are n contiguous
    doubles at a fixed stride, else None."""
    if a.ndim != 2 or a.dtype.char != "d":
        return None
    s0, s1 = a.strides
    if a.shape[1] != n or s1 != 8 or s0 % 8 or s0 < 8 * n:
        return None
    return data_address(a), s0 // 8


def _in_c(rt, r, other, span, factor):
    """fill's numbers by the runtime's crk_compare when the companion's times are every
    k-th of the run's (its own grid) and the arrays are laid out as the runs leave them;
    (per, index of each coordinate's largest difference among the common times, qmax, the
    common times) or None (the numpy path then)."""
    import numpy as np

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
    if fn is None or fn(data_address(t), nt, data_address(u), nu, k, 1e-12 * max(span, 1e-300), a[0], a[1], b[0],
                        b[1], n, float(factor), data_address(out)):
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
