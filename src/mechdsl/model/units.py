"""Units: physical dimensions of expressions and parsing of unit strings.

A :class:`Dim` is a vector of rational exponents over (length, mass, time, current,
temperature, amount, luminosity).  Unit strings are Modelica-style ("m/s2", "kg.m2",
"N.m/rad") or pint-style ("m/s**2"); common SI strings are read by a small fast path and
everything else by pint (imported lazily: it costs about half a second to load).
Values given in non-SI units are converted to SI (the factor is returned with the dimension).
"""
from __future__ import annotations

import re
from fractions import Fraction
from functools import lru_cache

from .records import record

_BASES = ("m", "kg", "s", "A", "K", "mol", "cd")


@record
class Dim:
    e: tuple[Fraction, ...] = (Fraction(0),) * 7

    def __mul__(self, o: "Dim") -> "Dim":
        return Dim(tuple(a + b for a, b in zip(self.e, o.e)))

    def __truediv__(self, o: "Dim") -> "Dim":
        return Dim(tuple(a - b for a, b in zip(self.e, o.e)))

    def __pow__(self, k) -> "Dim":
        k = Fraction(k).limit_denominator(1000)
        return Dim(tuple(a * k for a in self.e))

    @property
    def dimensionless(self) -> bool:
        return all(a == 0 for a in self.e)

    def __str__(self) -> str:
        if self.dimensionless:
            return "1"
        num = [_term(b, a) for b, a in zip(_BASES, self.e) if a > 0]
        den = [_term(b, -a) for b, a in zip(_BASES, self.e) if a < 0]
        s = ".".join(num) if num else "1"
        if den:
            s += "/" + (".".join(den) if len(den) == 1 else "(" + ".".join(den) + ")")
        return s


def _term(base: str, a: Fraction) -> str:
    if a == 1:
        return base
    return f"{base}{a}" if a.denominator == 1 else f"{base}^({a})"


def dim(**kw) -> Dim:
    idx = {b: i for i, b in enumerate(_BASES)}
    e = [Fraction(0)] * 7
    for k, v in kw.items():
        e[idx[k]] = Fraction(v)
    return Dim(tuple(e))


ONE = Dim()
LENGTH = dim(m=1)
MASS = dim(kg=1)
TIME = dim(s=1)
VELOCITY = dim(m=1, s=-1)
ACCEL = dim(m=1, s=-2)
FORCE = dim(kg=1, m=1, s=-2)
ENERGY = dim(kg=1, m=2, s=-2)
POWER = dim(kg=1, m=2, s=-3)
TORQUE = ENERGY
INERTIA = dim(kg=1, m=2)
STIFFNESS = dim(kg=1, s=-2)          # N/m
DAMPING = dim(kg=1, s=-1)            # N.s/m
GRAV_CONST = dim(m=3, kg=-1, s=-2)

# -- fast path ------------------------------------------------------------------------------
_PREFIX = {"": 1.0, "k": 1e3, "M": 1e6, "G": 1e9, "m": 1e-3, "u": 1e-6, "n": 1e-9, "c": 1e-2, "d": 1e-1}
_SYMBOLS: dict[str, tuple[float, Dim]] = {
    "m": (1.0, LENGTH), "g": (1e-3, MASS), "s": (1.0, TIME), "A": (1.0, dim(A=1)), "K": (1.0, dim(K=1)),
    "mol": (1.0, dim(mol=1)), "cd": (1.0, dim(cd=1)), "N": (1.0, FORCE), "J": (1.0, ENERGY), "W": (1.0, POWER),
    "Pa": (1.0, dim(kg=1, m=-1, s=-2)), "Hz": (1.0, dim(s=-1)), "rad": (1.0, ONE), "sr": (1.0, ONE),
    "min": (60.0, TIME), "h": (3600.0, TIME),
}
_NOPREFIX = {"rad", "sr", "min", "h", "deg"}
_TERM = re.compile(r"^([A-Za-z]+)(-?\d+)?$")


def _fast_symbol(sym: str) -> tuple[float, Dim] | None:
    if sym == "deg":
        import math

        return math.pi / 180, ONE
    if sym in _SYMBOLS:
        return _SYMBOLS[sym]
    for p, f in _PREFIX.items():
        if p and sym.startswith(p) and sym[len(p):] in _SYMBOLS and sym[len(p):] not in _NOPREFIX:
            base_f, d = _SYMBOLS[sym[len(p):]]
            return f * base_f, d
    return None


def _fast_parse(s: str) -> tuple[float, Dim] | None:
    s = s.strip()
    if s in ("", "1"):
        return 1.0, ONE
    num, _, den = s.partition("/")
    if "/" in den or "(" in s or "*" in s or "^" in s:
        return None
    factor, d = 1.0, ONE
    for part, sign in ((num, 1), (den, -1)):
        if not part:
            continue
        for term in part.split("."):
            if term == "1":
                continue
            m = _TERM.match(term)
            if not m:
                return None
            sym = _fast_symbol(m.group(1))
            if sym is None:
                return None
            k = int(m.group(2) or 1) * sign
            factor *= sym[0] ** k
            d = d * (sym[1] ** k)
    return factor, d


@lru_cache(maxsize=None)
def _pint_registry():
    import pint

    return pint.UnitRegistry()


_PINT_DIMS = {"[length]": 0, "[mass]": 1, "[time]": 2, "[current]": 3, "[temperature]": 4,
              "[substance]": 5, "[luminosity]": 6}


@lru_cache(maxsize=None)
def parse_unit(s: str) -> tuple[float, Dim]:
    """(factor to SI, dimension) of a unit string; raises ValueError when it is not a unit."""
    fast = _fast_parse(s)
    if fast is not None:
        return fast
    text = re.sub(r"([A-Za-z])(-?\d+)", r"\1**\2", s).replace(".", "*")
    try:
        ureg = _pint_registry()
        q = ureg.Quantity(1, text)
        base = q.to_base_units()
        e = [Fraction(0)] * 7
        for k, v in q.dimensionality.items():
            if k not in _PINT_DIMS:
                raise ValueError(f"unsupported dimension {k}")
            e[_PINT_DIMS[k]] = Fraction(v).limit_denominator(1000)
        return float(base.magnitude), Dim(tuple(e))
    except ValueError:
        raise
    except Exception as ex:  # pint raises many kinds; all mean "not a unit"
        raise ValueError(str(ex)) from None


def force_unit_text(d: "Dim") -> str:
    """A dimension written the way forces are: N, N.m, N/m, N.m2, ... (else the SI base units)."""
    per = d / FORCE
    e = per.e
    if all(a == 0 for i, a in enumerate(e) if i != 0) and e[0].denominator == 1:
        k = int(e[0])
        return "N" if k == 0 else ("N.m" if k == 1 else (f"N.m{k}" if k > 1 else ("N/m" if k == -1 else f"N/m{-k}")))
    return str(d)


def multiplier_unit(residual: "Dim | None") -> str | None:
    """The unit of the multiplier of a constraint whose residual g has dimension ``residual``.

    The constraint force on coordinate j is -(dg/dq_j) lambda, a generalized force, whose unit
    times q_j's is an energy; so [lambda] = [Q_j] [q_j] / [g] = J / [g] whatever the coordinates:
    N for a length (m), N.m for an angle (rad is 1), N/m for a squared length (x^2 + y^2 = L^2)."""
    if residual is None:
        return None
    return force_unit_text(ENERGY / residual)


# -- the unit values are held in -------------------------------------------------------------
_SI_BASE = {"g": "kg", "min": "s", "h": "s", "deg": "rad"}
_PINT_SI = {"meter": "m", "kilogram": "kg", "second": "s", "ampere": "A", "kelvin": "K", "mole": "mol",
            "candela": "cd", "radian": "rad", "steradian": "sr"}


@lru_cache(maxsize=None)
def si_unit(unit: str | None) -> str:
    """The unit a quantity declared in ``unit`` is held and reported in.  Everything computes in
    SI (a value given in "deg" is stored in rad), so a results column, a table header or an FMU
    variable must say the SI unit: "deg" -> "rad", "cm" -> "m", "deg/s" -> "rad/s", "km/h" ->
    "m/s", "g" -> "kg".  A unit with factor 1 ("rad", "N.m", "kg.m2", "N.m/rad") comes back as
    written, and so does a string that is not a unit; None and "" give ""."""
    if not unit:
        return ""
    try:
        factor, d = parse_unit(unit)
    except ValueError:
        return unit
    if abs(factor - 1.0) <= 1e-12:
        return unit
    fast = _si_terms(unit)
    if fast is not None:
        return fast
    try:
        q = _pint_registry().Quantity(1, re.sub(r"([A-Za-z])(-?\d+)", r"\1**\2", unit).replace(".", "*"))
        base = q.to_base_units()
        # unit_items() since pint 0.23; the units' own mapping before
        items = list(base.unit_items()) if hasattr(type(base), "unit_items") else list(base._units.items())
    except Exception:  # pint raises many kinds; parse_unit read it, so this is not expected
        items = None
    if items is None or any(name not in _PINT_SI for name, _ in items):
        text = str(d)
    else:
        text = _join([(_PINT_SI[name], Fraction(e).limit_denominator(1000)) for name, e in items]) or "1"
    if "rad" not in text and re.search(r"deg|rev|rpm|turn|grad|arcmin|arcsec|cycle", unit):
        # an angle in another unit: older pint (0.22) reduces revolutions to 1, newer ones to rad
        text = "rad" if text == "1" else ("rad" + text[1:] if text.startswith("1/") else "rad." + text)
    return text


def _si_terms(unit: str) -> str | None:
    """si_unit by the fast path's grammar (``a.b2/c``), term by term; None when it does not read it."""
    num, _, den = unit.strip().partition("/")
    if "/" in den or any(c in unit for c in "()*^"):
        return None
    terms = []
    for part, sign in ((num, 1), (den, -1)):
        for term in (part.split(".") if part else []):
            if term == "1":
                continue
            m = _TERM.match(term)
            if not m or _fast_symbol(m.group(1)) is None:
                return None
            sym, k = m.group(1), int(m.group(2) or 1) * sign
            if _fast_symbol(sym)[0] != 1.0:
                base = next((sym[len(p):] for p in sorted(_PREFIX, key=len, reverse=True)
                             if sym.startswith(p) and sym[len(p):] in _SYMBOLS), sym)
                sym = _SI_BASE.get(base, base)
                if sym not in _SI_BASE.values() and _SYMBOLS.get(sym, (0.0,))[0] != 1.0:
                    return None
            terms.append((sym, Fraction(k)))
    return _join(terms) or "1"


def _join(terms) -> str:
    """'m2.kg/s2' from [(symbol, exponent)] (a symbol given twice adds its exponents; order kept)."""
    total: dict[str, Fraction] = {}
    for sym, k in terms:
        total[sym] = total.get(sym, Fraction(0)) + k
    num = [_term(s, k) for s, k in total.items() if k > 0]
    den = [_term(s, -k) for s, k in total.items() if k < 0]
    s = ".".join(num) if num else ("1" if den else "")
    if den:
        s += "/" + (".".join(den) if len(den) == 1 else "(" + ".".join(den) + ")")
    return s


_MATRIX_UNITS = {"rad": {"M": "kg.m2", "C": "N.m.s/rad", "K": "N.m/rad"},
                 "m": {"M": "kg", "C": "N.s/m", "K": "N/m"}}


def matrix_units(coordinate_units) -> dict[str, str]:
    """The units of the linear model's M, C and K (and of the Hessian of V, K's unit) when every
    coordinate has the same unit u: M in J.s2/u2, C in J.s/u2, K in J/u2 (rad: kg.m2, N.m.s/rad,
    N.m/rad; m: kg, N.s/m, N/m).  {} when the units differ or one is unknown: then each entry has
    its own unit (J/(unit_i unit_j) for K) and the eigenvalues of the matrix have none."""
    units = {si_unit(u) for u in coordinate_units}
    if len(units) != 1 or "" in units:
        return {}
    u = units.pop()
    if u in _MATRIX_UNITS:
        return dict(_MATRIX_UNITS[u])
    try:
        d = parse_unit(u)[1]
    except ValueError:
        return {}
    return {"M": str(ENERGY * TIME ** 2 / d ** 2), "C": str(ENERGY * TIME / d ** 2), "K": str(ENERGY / d ** 2)}


_MOTION_UNITS = {"rad": ("rad/s", "kg.m2/s"), "m": ("m/s", "kg.m/s")}


def motion_units(unit: str) -> tuple[str, str]:
    """(speed unit, generalized momentum unit) of a coordinate whose SI unit is ``unit``: u/s and
    dT/dq' in J.s/u (rad: rad/s and kg.m2/s; m: m/s and kg.m/s); ("", "") when unknown."""
    u = si_unit(unit) if unit else ""
    if not u:
        return "", ""
    if u in _MOTION_UNITS:
        return _MOTION_UNITS[u]
    try:
        d = parse_unit(u)[1]
    except ValueError:
        return "", ""
    return str(d / TIME), str(ENERGY * TIME / d)


def coordinate_units(eom) -> list[str]:
    """The SI unit of each of ``eom``'s coordinates ('' when not declared or not known)."""
    model = getattr(eom, "model", None)
    by_name = {c.name: si_unit(c.unit) for c in getattr(model, "coordinates", ())}
    return [by_name.get(c, "") for c in eom.coords]
