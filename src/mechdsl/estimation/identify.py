"""Identifiability: which parameters, or combinations of them, the data cannot determine.

``identifiability(J, names, values, kinds)``: the singular value decomposition of the
sensitivity matrix in log-parameter space (each column times the unknown's value: d r / d log
theta), so that a direction of the null space reads as a product of powers.  A singular value
below ``rank_tol`` times the largest is a direction the outputs do not depend on (to the
integrator's accuracy): moving along it changes nothing measured.

    one name in the direction       m: "the motion does not depend on it"
    two names, v = (a, b)           g^a L^b cannot be determined; g^b / L^a can (g/L for a = b)
    more names                      the product along the direction cannot be determined

Exponents are written as small fractions when they are within 1e-3 of one (2, 1/2, 3/2).
Start values (and parameters whose value is 0) enter additively, not as powers.
"""
from __future__ import annotations

import dataclasses
from fractions import Fraction

import numpy as np

from ..model.records import record

RANK_TOL = 1e-6          # singular values below this fraction of the largest: not determined
ZERO_COMPONENT = 1e-3    # components of a unit null direction smaller than this are left out


@record
class Combination:
    names: tuple[str, ...]             # the unknowns involved
    exponents: tuple[float, ...]       # the direction (largest |component| = 1)
    text: str                          # what cannot be determined, in the model's terms
    determinable: str | None           # what can (two names: the complementary ratio), else None
    singular_value: float              # relative to the largest
    determinable_exponents: tuple[float, ...] = ()
    value: float | None = None         # the determinable combination's estimate (SI), a fit's
    standard_error: float | None = None
    unit: str = ""                     # its SI unit

    def to_dict(self) -> dict:
        return {"names": list(self.names), "exponents": [float(e) for e in self.exponents], "text": self.text,
                "determinable": self.determinable, "relative_singular_value": float(self.singular_value),
                "value": self.value, "standard_error": self.standard_error, "unit": self.unit}


def log_scale(values, kinds) -> np.ndarray:
    """Column scales: the value for a nonzero parameter (log space), 1 otherwise (additive)."""
    return np.array([abs(v) if k == "parameter" and v != 0 else 1.0 for v, k in zip(values, kinds)], float)


def identifiability(J, names, values, kinds, rank_tol: float = RANK_TOL) -> tuple[list[Combination], np.ndarray]:
    """(combinations the data cannot determine, relative singular values) of the sensitivity
    matrix J (rows: weighted residuals, columns: the unknowns in SI)."""
    J = np.asarray(J, float)
    if J.size == 0:
        return [], np.zeros(0)
    scale = log_scale(values, kinds)
    Js = J * scale[None, :]
    norms = np.linalg.norm(Js, axis=0)
    top = float(norms.max()) if norms.size else 0.0
    s_all = np.linalg.svd(Js, compute_uv=False)
    rel = s_all / s_all.max() if s_all.size and s_all.max() > 0 else np.zeros_like(s_all)
    # an unknown nothing measured depends on: its own name
    alone = [j for j in range(J.shape[1]) if norms[j] <= rank_tol * top or top == 0.0]
    out = [_combination(np.eye(J.shape[1])[j], names, kinds, values, norms[j] / top if top else 0.0)
           for j in alone]
    rest = [j for j in range(J.shape[1]) if j not in alone]
    if len(rest) > 1:
        _, s, Vt = np.linalg.svd(Js[:, rest], full_matrices=True)
        srel = np.zeros(len(rest))
        srel[:s.size] = s / s.max()
        for i in range(len(rest)):
            if srel[i] <= rank_tol:
                v = np.zeros(J.shape[1])
                v[rest] = Vt[i]
                out.append(_combination(v, names, kinds, values, float(srel[i])))
    return _unique(out), rel


def _unique(combos):
    seen, out = set(), []
    for c in combos:
        if c.text not in seen:
            seen.add(c.text)
            out.append(c)
    return out


def _combination(v, names, kinds, values, rel) -> Combination:
    v = np.asarray(v, float)
    v = v / v[np.argmax(np.abs(v))]
    idx = [j for j in range(len(v)) if abs(v[j]) >= ZERO_COMPONENT]
    nm = tuple(names[j] for j in idx)
    ex = tuple(float(v[j]) for j in idx)
    logs = all(kinds[j] == "parameter" and values[j] != 0 for j in idx)
    if len(idx) == 1:
        return Combination(nm, ex, f"{nm[0]} (the measured outputs do not depend on it)", None, rel)
    if logs:
        text = power_product(nm, ex)
        other = (ex[1], -ex[0]) if len(idx) == 2 else ()
        if other and other[_lead(other)] < 0:      # the larger power on top (a tie: the name given first)
            other = (-other[0], -other[1])
        return Combination(nm, ex, text, power_product(nm, other) if other else None, rel, other)
    terms = " ".join(f"{'+' if e >= 0 else '-'} {_num(abs(e))}*{'log ' if kinds[j] == 'parameter' and values[j] != 0 else ''}{n}"
                     for j, n, e in zip(idx, nm, ex))
    return Combination(nm, ex, f"the direction {terms.lstrip('+ ')}", None, rel)


def determined(c: Combination, names, theta, cov_log, units) -> Combination:
    """The determinable combination's value, standard error (from the covariance of the
    logarithms ``cov_log``) and SI unit, for a combination of two parameters."""
    from ..model.units import parse_unit

    if not c.determinable_exponents:
        return c
    idx = [list(names).index(n) for n in c.names]
    e = np.array(c.determinable_exponents, float)
    value = float(np.prod([abs(theta[j]) ** ej for j, ej in zip(idx, e)]))
    var = float(e @ cov_log[np.ix_(idx, idx)] @ e)
    dim = None
    try:
        for j, ej in zip(idx, e):
            d = parse_unit(units[j] or "1")[1] ** Fraction(ej).limit_denominator(12)
            dim = d if dim is None else dim * d
    except ValueError:
        dim = None
    return dataclasses.replace(c, value=value, standard_error=value * np.sqrt(max(var, 0.0)),
                               unit="" if dim is None or dim.dimensionless else str(dim))


def _lead(exponents) -> int:
    """The exponent that decides the orientation: the largest in size, the first of a tie."""
    a = np.abs(np.asarray(exponents, float))
    return int(np.flatnonzero(a >= a.max() * (1 - 1e-6))[0])


def _num(e: float) -> str:
    f = Fraction(e).limit_denominator(4)
    if abs(float(f) - e) <= 1e-3 * max(1.0, abs(e)):
        return str(f.numerator) if f.denominator == 1 else f"({f.numerator}/{f.denominator})"
    return f"{e:.3g}"


def power_product(names, exponents) -> str:
    """``g^1 L^-1`` -> "g/L"; ``m1 m2`` -> "m1*m2"; exponents as small fractions when close."""
    def term(n, e):
        a = _num(abs(e))
        return n if a == "1" else f"{n}^{a}"

    sign = 1.0 if exponents[_lead(exponents)] > 0 else -1.0
    num = [term(n, e) for n, e in zip(names, exponents) if sign * e > 0]
    den = [term(n, e) for n, e in zip(names, exponents) if sign * e < 0]
    top = "*".join(num) if num else "1"
    if not den:
        return top
    bottom = den[0] if len(den) == 1 else "(" + "*".join(den) + ")"
    return f"{top}/{bottom}"
