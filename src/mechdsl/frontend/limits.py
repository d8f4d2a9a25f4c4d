"""Size and work budgets of the front end (docs/language.md, "Limits").

A hostile or mistaken model (an array of a million coordinates, a 19 MB file, a name of a
million characters) must fail early with a located, coded error instead of exhausting memory
or hanging in a later phase.  Each budget has a default meant to be far above any real model
and can be raised by people who really mean it:

    mech check model.mech --limit coordinates=5000 --limit file_bytes=50000000

or, from Python, ``with mechdsl.frontend.limits.override(coordinates=5000): ...``.  The current values
live in a context variable (no process-wide state: threads and nested overrides are
independent); the phases read them with :func:`get` where they count.
"""
from __future__ import annotations

import contextlib
import contextvars
import math
from typing import Iterator, Mapping

from ..model.records import record


@record
class Limit:
    name: str
    default: int
    code: str          # the diagnostic that reports an excess
    meaning: str


_ALL = (
    Limit("file_bytes", 1_000_000, "E005", "size of a model file in bytes"),
    Limit("models", 500, "E317", "models and scenes in one file"),
    Limit("name_length", 256, "E314", "characters in an identifier"),
    Limit("nesting", 200, "E104", "brackets nested in one expression"),
    Limit("depth", 600, "E104", "depth of a syntax tree (long operator chains)"),
    Limit("arrays", 100_000, "E303", "elements of one array, range or built array"),
    Limit("iterations", 200_000, "E303", "for-loop and comprehension iterations of a model, all loops together"),
    Limit("integers", 1_000_000, "E315", "magnitude of an Integer parameter (they are structural)"),
    Limit("coordinates", 500, "E316", "generalized coordinates of a model"),
    Limit("outputs", 10_000, "E316", "output scalars of a model"),
    Limit("components", 10_000, "E316", "component instances of a model (bodies, points, joints, forces)"),
    Limit("scalars", 20_000, "E316", "scalars of a model: parameters, coordinates and outputs together"),
)
LIMITS: dict[str, Limit] = {lim.name: lim for lim in _ALL}
DEFAULTS: dict[str, int] = {lim.name: lim.default for lim in _ALL}

_CURRENT: contextvars.ContextVar[Mapping[str, int]] = contextvars.ContextVar("mechdsl_limits", default=DEFAULTS)


def get(name: str) -> int:
    """The budget `name` in force (a KeyError for an unknown name is a bug in the caller)."""
    return _CURRENT.get()[name]


def current() -> dict[str, int]:
    return dict(_CURRENT.get())


@contextlib.contextmanager
def override(values: Mapping[str, int] | None = None, **kw: int) -> Iterator[dict[str, int]]:
    """Raise (or lower) budgets inside a ``with`` block: ``override(coordinates=5000)``."""
    merged = dict(_CURRENT.get())
    for name, value in {**(values or {}), **kw}.items():
        if name not in LIMITS:
            raise ValueError(f"unknown limit '{name}' (limits: {', '.join(LIMITS)})")
        if isinstance(value, bool) or not isinstance(value, int) or value < 1:
            raise ValueError(f"limit {name} must be a positive whole number, not {value!r}")
        merged[name] = value
    token = _CURRENT.set(merged)
    try:
        yield dict(merged)
    finally:
        _CURRENT.reset(token)


def parse_setting(text: str) -> tuple[str, int]:
    """'arrays=1000000' (also '1e6', '1_000_000') -> ('arrays', 1000000); ValueError with a message otherwise."""
    name, sep, raw = text.partition("=")
    name, raw = name.strip(), raw.strip().replace("_", "")
    if not sep or name not in LIMITS:
        raise ValueError(f"--limit takes NAME=NUMBER with NAME one of: {', '.join(LIMITS)} (got '{text}')")
    try:
        value = int(raw) if raw.isdigit() else float(raw)
    except ValueError:
        value = math.nan
    if not (math.isfinite(value) and value >= 1 and value == int(value)):
        raise ValueError(f"--limit {name}: '{raw}' is not a positive whole number")
    return name, int(value)


def hint(name: str) -> str:
    """The second half of a help line: how to raise the budget `name`."""
    return f"the limit is {get(name):,}; raise it with `--limit {name}=N` (or mechdsl.frontend.limits.override) if you mean it"


__all__ = ["LIMITS", "DEFAULTS", "Limit", "get", "current", "override", "parse_setting", "hint"]
