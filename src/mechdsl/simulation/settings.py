"""One settings object for every simulation: ``SimulationSettings`` (frozen, validated once).

Resolved once with one precedence, argument (CLI or API) > scene > default, by
:func:`resolve`; every command and the Python API go through it, and every back end reads
its options from it.  The checks here are the only ones on times, tolerances and counts
(one rule for ODE, DAE, contact and fixed-step runs).

Budget.  A run may ask for at most ``budget`` output points (default 10^6) and at most
10 x ``budget`` fixed steps ((t_end - t_start) / dt); this keeps a mistyped ``points`` or
``dt`` from running for hours or exhausting memory.  Pass ``budget=`` (``--budget`` on the
command line) to allow more.
"""
from __future__ import annotations

import dataclasses
import math
from dataclasses import field
from typing import Any

from ..diagnostics import UsageError, did_you_mean
from ..model.records import record

DEFAULT_POINTS = 501
DEFAULT_RTOL = 1e-8
DEFAULT_ATOL = 1e-10
DEFAULT_T_END = 10.0
DEFAULT_BUDGET = 1_000_000      # output points; fixed steps: STEPS_PER_BUDGET times this
STEPS_PER_BUDGET = 10
MIN_RTOL = 1e-14            # below this double precision cannot deliver the tolerance
MAX_TIME = 1e15             # |t| beyond this: the time grid loses sub-second resolution
# scene settings (semantic.SCENE_SETTINGS) -> settings field
SCENE_KEYS = {"stop_time": "t_end", "start_time": "t_start", "rtol": "rtol", "atol": "atol",
              "method": "method", "points": "points", "outputs": "outputs", "formulation": "formulation",
              "dt": "dt", "reactions": "reactions", "compiled": "compiled", "rest_speed": "rest_speed",
              "impact_order": "impact_order", "output_events": "output_events"}


@record
class SimulationSettings:
    """Everything a run needs besides the model; ``validated()`` returns the checked copy."""

    t_end: float
    t_start: float = 0.0
    rtol: float = DEFAULT_RTOL
    atol: float = DEFAULT_ATOL
    method: str = "auto"
    formulation: str = "auto"          # constrained models: auto | projection | ggl | baumgarte | partitioning | augmented
    points: int | None = None          # None: 501 (fixed-step methods: every step, at most 20001)
    outputs: tuple[str, ...] | None = None
    x0: Any = None                     # [q; qd] or {coordinate | "der(c)": value}
    p: Any = None                      # parameter vector or {name: value}
    inputs: dict | None = None         # {input name: number | table | u(t) | u(t, x) | casadi.Function} (drive.py)
    dt: float | None = None            # fixed-step methods
    reactions: bool = False
    compiled: bool | None = None       # None: automatic (the ODE back end compiles when it pays)
    max_steps: int | None = None
    integrator_options: dict | None = None
    rest_speed: float | None = None    # contacts
    impact_order: str | None = None    # contacts
    output_events: bool = False        # contacts: also record the state before and after each event
    budget: int = DEFAULT_BUDGET
    estimate_error: bool = False
    extra: dict = field(default_factory=dict)   # back-end specific options (checked by the back end)

    def validated(self) -> "SimulationSettings":
        return validate(self)

    def replace(self, **kw) -> "SimulationSettings":
        return dataclasses.replace(self, **kw)

    def as_dict(self) -> dict:
        """The settings as plain data (for the metadata and ``--emit problem``)."""
        out = {}
        for f in dataclasses.fields(self):
            v = getattr(self, f.name)
            if f.name in ("x0", "p") and v is not None and not isinstance(v, dict):
                v = [float(x) for x in v]
            if f.name == "inputs" and v is not None:     # plain data: numbers, else what kind of signal
                v = {k: (float(x) if isinstance(x, (int, float)) and not isinstance(x, bool) else type(x).__name__)
                     for k, x in v.items()}
            out[f.name] = list(v) if isinstance(v, tuple) else v
        return out


FIELDS = tuple(f.name for f in dataclasses.fields(SimulationSettings))
_ALIASES = {"stop_time": "t_end", "start_time": "t_start", "tolerance": "tolerance", "t0": "t_start"}


def from_kwargs(t_end, **kw) -> SimulationSettings:
    """Settings from the keyword arguments of ``mechdsl.simulate.simulate`` (validated).

    Names that are not settings go to ``extra`` (the back end checks them); None means
    'not given' (the default applies)."""
    clean: dict[str, Any] = {}
    extra: dict[str, Any] = dict(kw.pop("extra", None) or {})
    tol = kw.pop("tolerance", None)
    for k, v in kw.items():
        k = _ALIASES.get(k, k)
        if k in FIELDS:
            if v is not None:
                clean[k] = v
        else:
            extra[k] = v
    if tol is not None:
        clean.setdefault("rtol", tol)
        clean.setdefault("atol", tol)
    return validate(SimulationSettings(t_end=t_end, extra=extra, **clean))


def resolve(scene_settings: dict | None, args: dict, where=None) -> SimulationSettings:
    """argument > scene > default; ``args`` holds the CLI/API arguments (None = not given).

    The scene's ``tolerance`` sets rtol and atol where neither the scene nor an argument
    sets them (docs/language.md).  A value the scene gave that fails validation (a scene's
    ``dt = 1e-320``) is the model's error: E604 located at the scene (``where``, its span);
    a value given as an argument stays a usage error."""
    try:
        return _resolve(scene_settings, args)
    except SettingError as e:
        from_scene = {name for key, name in SCENE_KEYS.items() if (scene_settings or {}).get(key) is not None}
        if (scene_settings or {}).get("tolerance") is not None:
            from_scene |= {"rtol", "atol"}
        given = {_ALIASES.get(k, k) for k, v in args.items() if v is not None}
        if where is None or e.setting not in from_scene or e.setting in given:
            raise
        from ..diagnostics import Diagnostic, MechError

        key = next((k for k, n in SCENE_KEYS.items() if n == e.setting), e.setting)
        raise MechError(Diagnostic("E604", f"scene setting {key}: {e}", where,
                                   "change the scene's value (or override it on the command line)")) from None


def _resolve(scene_settings: dict | None, args: dict) -> SimulationSettings:
    s = dict(scene_settings or {})
    merged: dict[str, Any] = {}
    for key, name in SCENE_KEYS.items():
        if s.get(key) is not None:
            merged[name] = s[key]
    if s.get("tolerance") is not None:
        merged.setdefault("rtol", s["tolerance"])
        merged.setdefault("atol", s["tolerance"])
    for k, v in args.items():
        if v is not None:
            merged[_ALIASES.get(k, k)] = v
    t_end = merged.pop("t_end", None)
    if t_end is None:
        raise UsageError("give t_end (no scene stop_time to default to)")
    return from_kwargs(t_end, **merged)


class SettingError(UsageError):
    """A setting that does not pass validation; ``setting`` names it (SimulationSettings field)."""

    def __init__(self, setting: str, message: str):
        super().__init__(message)
        self.setting = setting


def _number(name, v) -> float:
    if isinstance(v, bool):
        raise UsageError(f"{name} must be a number (got {v!r})")
    try:
        return float(v)
    except (TypeError, ValueError, OverflowError):
        raise UsageError(f"{name} must be a number (got {v!r})") from None


def _count(name, v, least: int) -> int:
    if isinstance(v, float) and math.isfinite(v) and v == int(v):
        v = int(v)
    if isinstance(v, int) and not isinstance(v, bool) and v > 2 ** 53:
        raise SettingError(name, f"{name} = {float(v):g} is too large to be a count")
    if isinstance(v, bool) or not isinstance(v, int) or v < least:
        raise SettingError(name, f"{name} must be an integer >= {least}; got {v!r}")
    return int(v)


def validate(s: SimulationSettings) -> SimulationSettings:
    """The checks every run passes (one rule for every back end); returns the normalized copy."""
    t0, t1 = _number("the start time", s.t_start), _number("the end time", s.t_end)
    rtol, atol = _number("rtol", s.rtol), _number("atol", s.atol)
    if not (math.isfinite(t0) and abs(t0) <= MAX_TIME):
        # the start on its own first: an end time defaulted from it (start + 10 s) would
        # otherwise be blamed for the start's value (and lose the scene's location)
        raise SettingError("t_start", f"times must lie within +-{MAX_TIME:g} s (got the start time {t0:g}): "
                           "beyond that double precision cannot resolve a time step")
    if not (math.isfinite(t0) and math.isfinite(t1)) or t1 <= t0:
        raise SettingError("t_end", f"the end time must be a finite number after the start time (got {t0} .. {t1})")
    if max(abs(t0), abs(t1)) > MAX_TIME:
        raise SettingError("t_end" if abs(t1) > MAX_TIME else "t_start",
                           f"times must lie within +-{MAX_TIME:g} s (got {t0:g} .. {t1:g}): beyond that double "
                         "precision cannot resolve a time step")
    if t1 - t0 < 1e-12 * max(abs(t0), abs(t1)):
        raise UsageError(f"the time span {t1 - t0:g} s is below the resolution of double precision at t = {t1:g}")
    if not (0 < rtol < 1) or not (0 < atol < 1):
        raise SettingError("rtol" if not 0 < rtol < 1 else "atol", f"tolerances must lie in (0, 1) (got rtol={rtol}, atol={atol})")
    if rtol < MIN_RTOL:
        raise SettingError("rtol", f"rtol={rtol} is below what double precision can deliver (use at least {MIN_RTOL:g})")
    budget = _count("budget", s.budget, 2)
    points = None if s.points is None else _count("points", s.points, 2)
    if points is not None and points > budget:
        raise SettingError("points", f"points = {points} exceeds the budget of {budget} output points; "
                         "pass a larger budget (--budget N, budget=N) to allow it")
    dt = s.dt
    if dt is not None:
        dt = _number("dt", dt)
        if not (math.isfinite(dt) and dt > 0):
            raise SettingError("dt", f"dt must be a positive number (got {dt})")
        if (t1 - t0) / dt > STEPS_PER_BUDGET * budget:
            raise SettingError("dt", f"dt = {dt:g} makes {(t1 - t0) / dt:.3g} steps, more than the budget of "
                             f"{STEPS_PER_BUDGET * budget} ({STEPS_PER_BUDGET} x budget); "
                             "pass a larger budget (--budget N, budget=N) or a larger dt")
    if s.inputs is not None and not (isinstance(s.inputs, dict) and all(isinstance(k, str) for k in s.inputs)):
        raise UsageError(f"inputs must be a dict {{input name: signal}} (got {type(s.inputs).__name__})")
    method = str(s.method or "auto").lower()
    formulation = str(s.formulation or "auto").lower()
    from .registry import check_formulation, check_method

    check_method(method)
    check_formulation(formulation)
    outputs = s.outputs
    if isinstance(outputs, str):
        outputs = (outputs,)
    elif outputs is not None:
        if not isinstance(outputs, (list, tuple)) or not all(isinstance(o, str) for o in outputs):
            raise UsageError(f"outputs must be a list of names (got {outputs!r})")
        outputs = tuple(outputs)
    max_steps = None if s.max_steps is None else _count("max_steps", s.max_steps, 1)
    for name in ("reactions", "compiled", "estimate_error", "output_events"):
        if not isinstance(getattr(s, name), (bool, int)) and not (name == "compiled" and s.compiled is None):
            raise UsageError(f"{name} must be true or false (got {getattr(s, name)!r})")
    return dataclasses.replace(s, t_start=t0, t_end=t1, rtol=rtol, atol=atol, points=points, dt=dt,
                               method=method, formulation=formulation,
                               outputs=outputs, max_steps=max_steps, reactions=bool(s.reactions),
                               compiled=None if s.compiled is None else bool(s.compiled), budget=budget,
                               estimate_error=bool(s.estimate_error), output_events=bool(s.output_events))


def unknown_setting(name: str) -> UsageError:
    hint = did_you_mean(name, FIELDS)
    return UsageError(f"unknown simulation setting '{name}'" + (f"; {hint}" if hint else ""))
