"""What ``mech bench`` runs: method specifications and tolerance sweeps.

A method specification names one way of integrating a model (docs/performance.md):

    METHOD                      erk, cvodes-bdf, scipy-dop853, stormer-verlet, rk, auto, ...
    FORMULATION+METHOD          constrained models: projection+cvodes-bdf, ggl+idas, ...
    NAME[key=value;key=value]   options for either part, passed to simulate by name:
                                baumgarte[baumgarte=0]+cvodes-bdf, rk[dt=0.01]

Lists are comma separated (commas inside brackets do not split).  ``--formulations`` gives
formulations for every method that names none; a constrained model benchmarked without any
formulation uses the scene's (or the simulator's default).

Tolerances: ``1e-2,1e-4`` (a list), ``1e-2..1e-12`` (half decades) or ``1e-2..1e-12/4``
(four points a decade, geometric).  Each run uses rtol = atol = tolerance.
"""
from __future__ import annotations

import math
import re
from dataclasses import dataclass

from ..diagnostics import UsageError
from ..simulation.registry import SPECS

DEFAULT_TOLERANCES = "1e-2..1e-12"
DEFAULT_ODE_METHODS = ("erk", "cvodes-adams", "cvodes-bdf", "scipy-dop853")
# methods whose step is fixed: the tolerance of the sweep sets their step (see step_for)
# fixed-step methods in canonical variables (rk4: not symplectic; rattle: stormer-verlet of a
# constrained model) and their orders, from the method registry
SYMPLECTIC_ORDER = {m.name: m.order for m in SPECS if m.family == "canonical" and m.name != "rattle"}


@dataclass(frozen=True, kw_only=True)
class Variant:
    """One formulation x integrator combination, with its extra options."""

    label: str
    method: str
    formulation: str | None = None
    options: tuple[tuple[str, object], ...] = ()          # simulate keyword arguments

    @property
    def kwargs(self) -> dict:
        kw = dict(self.options)
        if self.formulation is not None:
            kw["formulation"] = self.formulation
        return kw

    @property
    def fixed_dt(self) -> float | None:
        """dt given in the specification: the method then runs once, not over the sweep."""
        v = dict(self.options).get("dt")
        return None if v is None else float(v)


def split_top(text: str) -> list[str]:
    """Split on commas outside brackets."""
    out, depth, cur = [], 0, []
    for ch in text:
        if ch == "[":
            depth += 1
        elif ch == "]":
            depth -= 1
            if depth < 0:
                raise UsageError(f"unbalanced ']' in {text!r}")
        if ch == "," and depth == 0:
            out.append("".join(cur))
            cur = []
        else:
            cur.append(ch)
    if depth:
        raise UsageError(f"unbalanced '[' in {text!r}")
    out.append("".join(cur))
    return [s.strip() for s in out if s.strip()]


_PART = re.compile(r"^([A-Za-z0-9_.\-]+)(?:\[(.*)\])?$")


def _part(text: str) -> tuple[str, tuple[tuple[str, object], ...]]:
    m = _PART.match(text.strip())
    if not m:
        raise UsageError(f"cannot read the method specification {text!r} "
                         "(expected NAME or NAME[key=value;...], e.g. erk, rk[dt=0.01])")
    name, opts = m.group(1).lower(), []
    if m.group(2):
        for item in m.group(2).split(";"):
            if not item.strip():
                continue
            if "=" not in item:
                raise UsageError(f"option {item!r} in {text!r} must be key=value")
            k, v = (s.strip() for s in item.split("=", 1))
            opts.append((k, _value(v)))
    return name, tuple(opts)


def _value(text: str):
    low = text.lower()
    if low in ("true", "false"):
        return low == "true"
    if text.startswith("(") and text.endswith(")"):
        return tuple(_value(s) for s in text[1:-1].split() if s)
    try:
        return float(text) if any(c in text for c in ".eE") or not text.lstrip("-").isdigit() else int(text)
    except ValueError:
        return text


def parse_variant(text: str, formulation: str | None = None) -> Variant:
    """``[FORMULATION[opts]+]METHOD[opts]`` -> Variant; ``formulation`` fills a missing one."""
    parts = [s for s in text.split("+")]
    if len(parts) > 2 or not all(p.strip() for p in parts):
        raise UsageError(f"cannot read the method specification {text!r} "
                         "(expected METHOD or FORMULATION+METHOD, e.g. projection+cvodes-bdf)")
    method, mopts = _part(parts[-1])
    form, fopts = (None, ())
    if len(parts) == 2:
        form, fopts = _part(parts[0])
    elif formulation:
        form, fopts = _part(formulation)
    label = (f"{_label(form, fopts)}+" if form else "") + _label(method, mopts)
    return Variant(label=label, method=method, formulation=form, options=fopts + mopts)


def _label(name, opts) -> str:
    if not opts:
        return name
    return name + "[" + ";".join(f"{k}={_fmt(v)}" for k, v in opts) + "]"


def _fmt(v) -> str:
    if isinstance(v, tuple):
        return "(" + " ".join(_fmt(x) for x in v) + ")"
    return str(v).lower() if isinstance(v, bool) else f"{v:g}" if isinstance(v, float) else str(v)


def parse_variants(methods, formulations=None) -> list[Variant]:
    """Methods (list or comma text) x formulations (for the methods that name none)."""
    items = split_top(methods) if isinstance(methods, str) else [m for s in methods for m in split_top(s)]
    forms = (split_top(formulations) if isinstance(formulations, str)
             else [f for s in (formulations or []) for f in split_top(s)])
    out: list[Variant] = []
    for m in items:
        if "+" in m or not forms:
            out.append(parse_variant(m))
        else:
            out.extend(parse_variant(m, f) for f in forms)
    labels = [v.label for v in out]
    dup = sorted({x for x in labels if labels.count(x) > 1})
    if dup:
        raise UsageError(f"method {dup[0]!r} is listed twice")
    if not out:
        raise UsageError("no methods to benchmark")
    return out


def parse_tolerances(text: str | None) -> list[float]:
    """'1e-2,1e-4' | '1e-2..1e-12' (half decades) | '1e-2..1e-12/k' (k points a decade);
    returned from loose to tight."""
    text = (text or DEFAULT_TOLERANCES).strip()
    if ".." in text:
        left, right = text.split("..", 1)
        right, _, per_text = right.partition("/")
        a, b = _tol(left), _tol(right)
        try:
            per = int(per_text) if per_text.strip() else 2
        except ValueError:
            raise UsageError(f"cannot read tolerances {text!r} (e.g. 1e-2..1e-12 or 1e-2..1e-12/4)") from None
        if per < 1:
            raise UsageError("points a decade must be at least 1")
        hi, lo = max(a, b), min(a, b)
        n = round(math.log10(hi / lo) * per)
        tols = [hi * 10 ** (-i / per) for i in range(n + 1)]
        tols = [float(f"{t:.6g}") for t in tols]
    else:
        tols = [_tol(s) for s in text.split(",") if s.strip()]
    if not tols:
        raise UsageError("no tolerances given")
    return sorted(set(tols), reverse=True)


def _tol(s: str) -> float:
    try:
        v = float(s)
    except ValueError:
        raise UsageError(f"tolerance {s!r} is not a number") from None
    if not (0 < v < 1):
        raise UsageError(f"tolerances must lie in (0, 1) (got {v:g})")
    if v < 1e-14:
        raise UsageError(f"tolerance {v:g} is below what double precision can deliver (use at least 1e-14)")
    return v
