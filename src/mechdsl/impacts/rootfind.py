"""Safeguarded bracketing root finder for event functions (Illinois regula falsi + bisection)."""
from __future__ import annotations

import math


def bracket_root(f, a: float, b: float, fa: float, fb: float, xtol: float, maxiter: int = 200):
    """Shrink [a, b] with f(a) > 0 >= f(b) until b - a <= xtol; returns (a, b, n_evaluations).

    The sign convention is kept: a is the last point seen on the positive side, b the first
    on the non-positive side.  Illinois steps (regula falsi with the stale end's value
    halved) converge superlinearly on smooth f; a bisection is forced whenever two steps
    did not halve the bracket, so the width falls at least by 2 every two steps.
    """
    if not fa > 0 >= fb:
        raise ValueError(f"not a bracket: f(a) = {fa}, f(b) = {fb}")
    wa, wb = fa, fb                    # Illinois weights (values, halved when stale)
    side = 0
    widths = [math.inf, math.inf, b - a]
    nev = 0
    while b - a > xtol and nev < maxiter:
        if b - a > 0.5 * widths[-3]:
            c = 0.5 * (a + b)
        else:
            c = (a * wb - b * wa) / (wb - wa) if wb != wa else 0.5 * (a + b)
            if not math.isfinite(c):
                c = 0.5 * (a + b)
            margin = 1e-3 * (b - a)
            c = min(max(c, a + margin), b - margin)
        if not a < c < b:
            break
        fc = f(c)
        nev += 1
        if fc > 0:
            a, wa = c, fc
            if side == 1:
                wb *= 0.5
            side = 1
        else:
            b, wb = c, fc
            if side == -1:
                wa *= 0.5
            side = -1
        widths.append(b - a)
    return a, b, nev
