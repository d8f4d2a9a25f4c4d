"""One reader of the numbers a person types, and one meaning for them.

``number("2*pi/3")`` and ``assignments(["m=2,L=0.5"])`` read values from the command line:
Python's ``ast`` restricted to arithmetic, evaluated in floating point (so that ``9^9^9``
overflows instead of building a huge integer); values finite, at most 200 characters.

A value may say its unit: ``45 deg``, ``deg(45)``, ``0.785 rad``, ``30 cm``.  A bare number given
for a parameter (or a start value) means the unit that quantity is **declared** in: for
``parameter Real alpha(unit = "deg") = 30``, ``alpha = 45`` is 45 degrees on every path (a scene
modifier, ``--set``, ``Model.with_params``, ``mech sweep --grid/--table``, the samplers).  The
one conversion is :func:`declared_value` (a value -> SI, for the parameter vector) with its
inverse :func:`in_declared_unit`; :func:`show` writes an SI value back in its declared unit.

In Python, ``mechdsl.deg(45)`` and ``mechdsl.Quantity(0.785, "rad")`` carry their unit, and
text such as ``"45 deg"`` is read as here.
"""
from __future__ import annotations

import ast
import math
import operator
import re
from .diagnostics import UsageError
from .model.records import record

MAX_VALUE_TEXT = 200          # characters in one value: enough for any expression a person types

_OPS = {ast.Add: operator.add, ast.Sub: operator.sub, ast.Mult: operator.mul, ast.Div: operator.truediv,
        ast.Pow: operator.pow, ast.USub: operator.neg, ast.UAdd: operator.pos}
_NAMES = {"pi": math.pi, "e": math.e}
_FUNCS = {"sin": math.sin, "cos": math.cos, "tan": math.tan, "asin": math.asin, "acos": math.acos,
          "atan": math.atan, "sqrt": math.sqrt, "exp": math.exp, "log": math.log, "abs": abs,
          "deg": math.radians}
_UNIT_FUNCS = {"deg"}                          # functions that say the result's unit (radians)
_TOP_COMMA = re.compile(r",(?![^(]*\))")        # commas outside parentheses
_TRAILING_UNIT = re.compile(r"^(.*?[0-9.)\s])\s*([A-Za-z][A-Za-z0-9_.*/^]*)$")
HINT = "(numbers, pi, e, + - * / ^, sqrt, sin, cos, tan, asin, acos, atan, exp, log, abs, deg; a unit after the number: 45 deg)"


@record
class Quantity:
    """A number with the unit it was given in: ``Quantity(45, "deg")``; unit None is a bare
    number, which means the unit its quantity is declared in."""

    value: float
    unit: str | None = None

    def si(self) -> float:
        """The value in SI units (a bare number is returned as it is)."""
        return self.value if self.unit is None else self.value * _unit(self.unit, "value")[0]

    def __str__(self) -> str:
        return f"{self.value:g}" + (f" {self.unit}" if self.unit else "")


def deg(x) -> Quantity:
    """An angle in degrees, for any parameter, start value or sweep value: ``deg(45)``."""
    return Quantity(finite(x, "deg(...)"), "deg")


def rad(x) -> Quantity:
    """An angle in radians: ``rad(0.785)``."""
    return Quantity(finite(x, "rad(...)"), "rad")


def quantity(text, what: str = "value") -> Quantity:
    """A value as a person typed it: ``1.5``, ``2*pi/3``, ``45 deg``, ``45deg``, ``deg(45)``,
    ``0.785 rad``.  A trailing unit or a unit function (``deg(...)``: radians) makes it explicit;
    anything else is a bare number (unit None)."""
    if isinstance(text, Quantity):
        return text
    s = str(text).strip()
    if len(s) > MAX_VALUE_TEXT:
        raise UsageError(f"{what}: a value of {len(s)} characters is too long (at most {MAX_VALUE_TEXT})")
    try:
        v, unit = _expression(s, what)
        return Quantity(v, unit)
    except UsageError:
        m = _TRAILING_UNIT.match(s)
        if (m is None or m.group(2) in _NAMES or not m.group(1).strip()
                or re.match(r"[eE][+-]?\d", m.group(2))):        # 1e400: an exponent, not a unit
            raise
        unit = m.group(2)
        try:
            _unit(unit, what)
        except UsageError:
            raise UsageError(f"{what}: cannot read {s!r} as a number {HINT}") from None
        v, inner = _expression(m.group(1).strip(), what)
        if inner is not None:
            raise UsageError(f"{what}: {s!r} gives two units ({inner} by deg(...) and {unit})") from None
        return Quantity(v, unit)


def number(text, what: str = "value") -> float:
    """A finite number from the command line: 1.5, 2e-3, -pi/2, 2*pi/3, sqrt(2), deg(30), 2^3;
    with an explicit unit (``30 deg``, ``2 min``) converted to SI."""
    return quantity(text, what).si()


def _expression(s: str, what: str) -> tuple[float, str | None]:
    try:
        tree = ast.parse(s.replace("^", "**"), mode="eval").body
        v = float(_ev(tree))
    except OverflowError:
        raise UsageError(f"{what}: {s!r} is out of the floating-point range (|x| < 1.8e308)") from None
    except (SyntaxError, ValueError, TypeError, ZeroDivisionError, KeyError, RecursionError, MemoryError):
        raise UsageError(f"{what}: cannot read {s!r} as a number {HINT}") from None
    if not math.isfinite(v):
        raise UsageError(f"{what}: {s!r} is not a finite number")
    used = any(isinstance(n, ast.Call) and isinstance(n.func, ast.Name) and n.func.id in _UNIT_FUNCS
               for n in ast.walk(tree))
    return v, ("rad" if used else None)


def _ev(n) -> float:
    """Floating-point evaluation of a tiny arithmetic tree (ints become floats first, so a power
    overflows instead of building a huge integer)."""
    if isinstance(n, ast.Constant) and isinstance(n.value, (int, float)) and not isinstance(n.value, bool):
        return float(n.value)
    if isinstance(n, ast.BinOp) and type(n.op) in _OPS:
        a, b = _ev(n.left), _ev(n.right)
        v = _OPS[type(n.op)](a, b)
        if isinstance(v, complex):
            raise ValueError("complex result")
        return v
    if isinstance(n, ast.UnaryOp) and type(n.op) in _OPS:
        return _OPS[type(n.op)](_ev(n.operand))
    if isinstance(n, ast.Name):
        return _NAMES[n.id]
    if (isinstance(n, ast.Call) and isinstance(n.func, ast.Name) and n.func.id in _FUNCS and len(n.args) == 1
            and not n.keywords):
        return float(_FUNCS[n.func.id](_ev(n.args[0])))
    raise ValueError("not an arithmetic expression")


def assignments(items, option: str = "--set", units: bool = False) -> dict:
    """``NAME=VALUE`` items (several per item, comma-separated) -> {name: value}, in order.
    Values are SI floats, or with ``units=True`` :class:`Quantity` objects that keep whether a
    unit was given (a bare number then means the declared unit: :func:`declared_value`)."""
    out: dict = {}
    for item in items or []:
        for part in item if isinstance(item, (list, tuple)) else [item]:
            for piece in [s for s in _TOP_COMMA.split(str(part)) if s.strip()]:
                if "=" not in piece:
                    raise UsageError(f"{option} expects NAME=VALUE, got {piece.strip()!r}")
                name, text = (s.strip() for s in piece.split("=", 1))
                if not name:
                    raise UsageError(f"{option} expects NAME=VALUE, got {piece.strip()!r}")
                q = quantity(text, what=f"{option} {name}")
                out[name] = q if units else q.si()
    return out


# --------------------------------------------------------------------------- declared units


def declared_value(value, unit: str | None, name: str = "value", speed: bool = False) -> float:
    """The SI value of what was given for a quantity declared in ``unit`` (the one conversion of
    every path: scene modifiers do the same in the front end).

    A bare number (int, float, numpy scalar, text without a unit) means the declared unit; a
    :class:`Quantity`, ``deg(45)`` or text with a unit (``"45 deg"``) is converted from its own
    unit, which must have the declared unit's dimension.  ``speed=True``: the value is the speed
    of a coordinate declared in ``unit`` (per second; the same factor)."""
    q = value if isinstance(value, Quantity) else (quantity(value, name) if isinstance(value, str)
                                                   else Quantity(finite(value, name)))
    if q.unit is None:
        return q.value * (_unit(unit, name)[0] if unit else 1.0)
    factor, dim = _unit(q.unit, name)
    if unit:
        from .model.units import TIME

        want = _unit(unit, name)[1] / (TIME if speed else TIME ** 0)
        if dim != want:
            said = f"{unit}/s" if speed else unit
            raise UsageError(f"{name} is declared in {said}, and {q} is not a value of that kind "
                             f"(give a bare number, meaning {said}, or a value in a unit of the same kind)")
    return q.value * factor


def in_declared_unit(value, unit: str | None, name: str = "value", speed: bool = False) -> float:
    """What was given, expressed in the declared unit (a bare number stays exactly as it is):
    the numbers a sweep's table holds, and start values handed to the front end."""
    q = value if isinstance(value, Quantity) else (quantity(value, name) if isinstance(value, str)
                                                   else Quantity(finite(value, name)))
    if q.unit is None:
        return q.value
    return declared_value(q, unit, name, speed) / (_unit(unit, name)[0] if unit else 1.0)


def start_value(model, key: str, value) -> float:
    """The SI start value (key ``c``) or speed (``der(c)``) of a coordinate of ``model`` (an
    ir.Model) from what was given: a bare number means the coordinate's declared unit."""
    from .model.names import split_state

    name, speed = split_state(key)
    try:
        unit = model.coordinate(name).unit
    except KeyError:
        unit = None
    return declared_value(value, unit, f"{name}.{'speed' if speed else 'start'}", speed=speed)


def in_unit(si_value: float, unit: str | None) -> float:
    """An SI value expressed in ``unit`` (its declared unit): ``in_unit(0.5236, "deg")`` = 30."""
    if not unit:
        return si_value
    try:
        factor = _unit(unit, "unit")[0]
    except UsageError:
        return si_value
    # the division brings back the number as declared up to the last bit (30 -> 29.999999999999996)
    return si_value if factor == 1.0 else float(f"{si_value / factor:.14g}")


def show(si_value: float, unit: str | None, digits: int = 6) -> str:
    """An SI value written in its declared unit: ``show(0.5236, "deg")`` -> ``"30 deg"``."""
    v = in_unit(si_value, unit)
    return f"{v:.{digits}g}" + (f" {unit}" if unit else "")


# SI units that model.units.si_unit gives back as written (tests/test_coldstart_cache.py checks
# each against it): the common units of coordinates and results
SI_AS_WRITTEN = frozenset(("rad", "m", "kg", "s", "N", "J", "W", "rad/s", "m/s", "rad/s2", "m/s2", "N.m", "kg.m2"))


def si_unit(unit: str | None) -> str | None:
    """The unit the values of a quantity declared in ``unit`` are held in (results, the parameter
    vector, equilibria are SI): "rad" for deg, "rad/s" for rpm, "m" for mm; None when unknown
    (model.units.si_unit, with None for no unit)."""
    if unit in SI_AS_WRITTEN:         # without importing the unit parser (fractions, decimal: 3-5 ms)
        return unit
    from .model.units import si_unit as si

    return si(unit) or None


def _unit(unit: str, what: str):
    from .model.units import parse_unit

    try:
        return parse_unit(str(unit).strip())
    except ValueError:
        raise UsageError(f"{what}: unknown unit {unit!r} (units look like deg, rad, m, cm, kg, s)") from None


def finite(x, what: str) -> float:
    """x as a finite float (bool and non-numbers refused): a UsageError naming ``what``."""
    if isinstance(x, bool):
        raise UsageError(f"{what} must be a number, got {x!r}")
    try:
        v = float(x)
    except (TypeError, ValueError):
        raise UsageError(f"{what} must be a number, got {x!r}") from None
    if not math.isfinite(v):
        raise UsageError(f"{what} must be finite")
    return v
