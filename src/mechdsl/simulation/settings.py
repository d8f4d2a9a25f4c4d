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
from typing import Any

from ..diagnostics import Diagnostic, MechError, UsageError, did_you_mean
from ..model.records import record
from .registry import check_formulation, check_method


DEFAULT_POINTS = 501
DEFAULT_RTOL = 1e-8
DEFAULT_ATOL = 1e-10
DEFAULT_T_END = 10.0
DEFAULT_BUDGET = 1_000_000      # output points; fixed steps: STEPS_PER_BUDGET times this
STEPS_PER_BUDGET = 10
MIN_RTOL = 1e-14            # below this double precision cannot deliver the tolerance
MAX_TIME = 1e15             # |t| beyond this: the time grid loses sub-second resolution
# scene settings (semantic.SCENE_SETTINGS) -> settings name (flat: see from_kwargs for the groups)
SCENE_KEYS = {"stop_time": "t_end", "start_time": "t_start", "rtol": "rtol", "atol": "atol",
              "method": "method", "points": "points", "outputs": "outputs", "formulation": "formulation",
              "dt": "dt", "reactions": "reactions", "compiled": "compiled", "rest_speed": "rest_speed",
              "impact_order": "impact_order", "output_events": "output_events"}


IMPACT_ORDERS = ("simultaneous", "sequential")


@record
class DaeOptions:
    """The settings group of constrained models (docs/constraints.md)."""

    formulation: str = "auto"            # auto (= projection) | projection | ggl | baumgarte | partitioning | augmented
    reactions: bool = False              # record every multiplier and every reaction output
    baumgarte: Any = None                # None (automatic), rate omega, or (alpha, beta)
    singular_tol: float = 1e-6           # sigma_min / sigma_max of the scaled G below this: singular
    max_interval: float | None = None    # longest segment between checks (default: monitoring grid)
    drift_bound: float | None = None     # default max(10 atol, 1e-10)
    repartition_cond: float = 10.0       # partitioning: re-partition when cond(G_v) grows by this factor
    force_index: bool = False            # skip the index guard (benchmarks only)

    def bound(self, atol: float) -> float:
        """The constraint drift a run holds: drift_bound, else max(10 atol, 1e-10)."""
        return self.drift_bound if self.drift_bound is not None else max(10 * atol, 1e-10)

    def validated(self) -> "DaeOptions":
        import dataclasses

        for name in ("reactions", "force_index"):
            if not isinstance(getattr(self, name), (bool, int)):
                raise UsageError(f"{name} must be true or false (got {getattr(self, name)!r})")
        for name, optional in (("singular_tol", False), ("max_interval", True), ("drift_bound", True),
                               ("repartition_cond", False)):
            v = getattr(self, name)
            if v is None and optional:
                continue
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not (math.isfinite(v) and v > 0):
                raise UsageError(f"{name} must be a positive number (got {v!r})")
        b = self.baumgarte
        if b is not None:
            parts = b if isinstance(b, (tuple, list)) else (b,)
            if len(parts) not in (1, 2) or any(isinstance(x, bool) or not isinstance(x, (int, float))
                                               or not math.isfinite(x) or x < 0 for x in parts):
                raise UsageError(f"baumgarte must be a rate omega >= 0 or a pair (alpha, beta) (got {b!r})")
        return dataclasses.replace(self, formulation=str(self.formulation or "auto").lower(),
                                   reactions=bool(self.reactions), force_index=bool(self.force_index),
                                   baumgarte=tuple(b) if isinstance(b, list) else b)


@record
class ContactOptions:
    rest_speed: float = 1e-3        # m/s: an impact leaving a contact slower than this ends in persistent contact
    impact_order: str = "simultaneous"
    output_events: bool = False     # also record the state just before and just after each event
    gap_tol: float | None = None    # m: contacts this close take part in an impact (default max(1e-9, 100 atol))
    event_offset: float | None = None   # m: events fire at gap = -event_offset (default atol)
    max_events: int = 100000
    step_limit: int = 200_000       # steps in one run (Python steps cost ~0.1-0.5 ms, compiled free flight
                                    # ~1 us): a collapsed step size, or a run estimated to need more, fails
    max_step: float | None = None
    proj_tol: float | None = None   # drift of active constraints that triggers a projection (default 100 atol)
    samples: int = 4                # sub-intervals per step on which event functions are sampled
    acc_tol: float = 1e-8           # m/s2: contact accelerations below this count as zero (relative to max(1, |a|))
    contacts: tuple | None = None   # ContactGap / Fixation / ir.Contact objects (None: the model's contacts)
    fixations: tuple = ()           # more Fixation objects

    def validated(self) -> "ContactOptions":
        import dataclasses

        order = str(self.impact_order or "simultaneous").lower()
        if order not in IMPACT_ORDERS:
            raise UsageError(f"impact order must be one of {', '.join(IMPACT_ORDERS)}, got '{self.impact_order}'")
        v = self.rest_speed
        if isinstance(v, bool) or not (isinstance(v, (int, float)) and 0 < v < float("inf")):
            raise UsageError(f"rest_speed must be a positive number, got {v!r}")
        for name in ("gap_tol", "event_offset", "max_step", "proj_tol", "acc_tol"):
            x = getattr(self, name)
            if x is not None and (isinstance(x, bool) or not isinstance(x, (int, float)) or not math.isfinite(x)
                                  or x < 0 or (x == 0 and name in ("max_step",))):
                raise UsageError(f"{name} must be a {'positive' if name == 'max_step' else 'non-negative'} "
                                 f"number, got {x!r}")
        for name, least in (("samples", 1), ("max_events", 1), ("step_limit", 1)):
            x = getattr(self, name)
            if isinstance(x, float) and x.is_integer():
                x = int(x)
            if isinstance(x, bool) or not isinstance(x, int) or x < least:
                raise UsageError(f"{name} must be at least {least}" + (f", got {x!r}" if name != "samples" else ""))
        if not isinstance(self.output_events, (bool, int)):
            raise UsageError(f"output_events must be true or false (got {self.output_events!r})")
        contacts = None if self.contacts is None else tuple(self.contacts)
        return dataclasses.replace(self, impact_order=order, rest_speed=float(v), output_events=bool(self.output_events),
                                   samples=int(self.samples), max_events=int(self.max_events),
                                   step_limit=int(self.step_limit), contacts=contacts,
                                   fixations=tuple(self.fixations or ()))


@record
class OdeOptions:
    """The settings group of the ODE back end."""

    singularity_threshold: float = 0.05     # warn when a singularity monitor comes closer than this to zero
    functions: Any = None                   # a mapping of CasADi Functions replacing the model's ("ode", ...)

    def validated(self) -> "OdeOptions":
        v = self.singularity_threshold
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not (math.isfinite(v) and v >= 0):
            raise UsageError(f"singularity_threshold must be a number >= 0 (got {v!r})")
        if self.functions is not None and not hasattr(self.functions, "__getitem__"):
            raise UsageError("functions must be a mapping of CasADi Functions by name (\"ode\", ...)")
        return dataclasses.replace(self, singularity_threshold=float(v))


@record
class FixedStepOptions:
    """The settings group of the fixed-step methods (canonical ones and the ODE's rk, collocation)."""

    dt: float | None = None             # the step (None: from rtol and the time scale, or span / STEPS_DEFAULT)
    newton_tol: float = 1e-12           # implicit stages: Newton's tolerance
    max_newton: int = 30                # implicit stages: most Newton iterations a step

    STEPS_DEFAULT = 1000                # (a class constant, not a field): canonical steps without dt

    def step(self, span: float) -> float:
        """The step of a canonical fixed-step run: dt, else span / 1000."""
        return self.dt if self.dt is not None else span / self.STEPS_DEFAULT

    def validated(self, span: float, budget: int) -> "FixedStepOptions":
        dt = self.dt
        if dt is not None:
            dt = _number("dt", dt)
            if not (math.isfinite(dt) and dt > 0):
                raise SettingError("dt", f"dt must be a positive number (got {dt})")
            if span / dt > STEPS_PER_BUDGET * budget:
                raise SettingError("dt", f"dt = {dt:g} makes {span / dt:.3g} steps, more than the budget of "
                                   f"{STEPS_PER_BUDGET * budget} ({STEPS_PER_BUDGET} x budget); "
                                   "pass a larger budget (--budget N, budget=N) or a larger dt")
        tol = _number("newton_tol", self.newton_tol)
        if not (math.isfinite(tol) and tol > 0):
            raise UsageError(f"newton_tol must be a positive number (got {self.newton_tol!r})")
        return dataclasses.replace(self, dt=dt, newton_tol=tol, max_newton=_count("max_newton", self.max_newton, 1))


@record
class SimulationSettings:
    """Everything a run needs besides the model: the common fields and one typed option group
    per kind of back end (``ode``, ``dae``, ``contacts``, ``fixed_step``); ``validated()``
    returns the checked copy.  Keyword arguments and scene settings are flat names
    (``from_kwargs`` puts each into its place: ``formulation`` into ``dae``, ``dt`` into
    ``fixed_step``, ...)."""

    t_end: float = DEFAULT_T_END
    t_start: float = 0.0
    rtol: float = DEFAULT_RTOL
    atol: float = DEFAULT_ATOL
    method: str = "auto"
    points: int | None = None          # None: 501 (fixed-step methods: every step, at most 20001)
    outputs: tuple[str, ...] | None = None
    x0: Any = None                     # [q; qd] or {coordinate | "der(c)": value}
    p: Any = None                      # parameter vector or {name: value}
    inputs: dict | None = None         # {input name: number | table | u(t) | u(t, x) | casadi.Function} (drive.py)
    compiled: bool | None = None       # None: automatic (the ODE back end compiles when it pays)
    max_steps: int | None = None       # integrator steps per output interval (ODE, DAE)
    integrator_options: dict | None = None
    budget: int = DEFAULT_BUDGET
    estimate_error: bool = False       # the thorough check: a second run 100x tighter, every output compared
    error_estimate: str = "on"         # on | off | coordinates: the default estimate (simulation/estimate.py)
    warn: bool = True                  # a MechWarning for what the run warns about (sweeps collect them instead)
    ode: OdeOptions = OdeOptions()
    dae: DaeOptions = DaeOptions()
    contacts: ContactOptions = ContactOptions()
    fixed_step: FixedStepOptions = FixedStepOptions()

    def validated(self) -> "SimulationSettings":
        return validate(self)

    def replace(self, **kw) -> "SimulationSettings":
        """A copy with fields replaced; flat names of the groups (``dt``, ``formulation``, ...)
        replace the field of their group."""
        groups: dict[str, dict] = {}
        for k in list(kw):
            g = GROUP_OF.get(k)
            if g is not None:
                groups.setdefault(g, {})[k] = kw.pop(k)
        for g, values in groups.items():
            kw[g] = dataclasses.replace(kw.get(g, getattr(self, g)), **values)
        return dataclasses.replace(self, **kw)

    @property
    def dt(self) -> float | None:
        return self.fixed_step.dt

    @property
    def formulation(self) -> str:
        return self.dae.formulation

    @property
    def reactions(self) -> bool:
        return self.dae.reactions

    @property
    def output_events(self) -> bool:
        return self.contacts.output_events

    def as_dict(self) -> dict:
        """The settings as plain data (for the metadata and ``--emit problem``): the common
        fields, then each group as a dict."""
        out: dict[str, Any] = {}
        for f in dataclasses.fields(self):
            if f.name == "warn":           # how the caller hears of warnings, not what runs
                continue
            v = getattr(self, f.name)
            if f.name in GROUPS:
                out[f.name] = {g.name: _plain(g.name, getattr(v, g.name)) for g in dataclasses.fields(v)}
                continue
            out[f.name] = _plain(f.name, v)
        return out


def _plain(name, v):
    if name in ("x0", "p") and v is not None and not isinstance(v, dict):
        return [float(x) for x in v]
    if name == "inputs" and v is not None:     # plain data: numbers, else what kind of signal
        return {k: (float(x) if isinstance(x, (int, float)) and not isinstance(x, bool) else type(x).__name__)
                for k, x in v.items()}
    if name in ("contacts", "fixations") and v is not None:
        return [str(getattr(c, "name", None) or getattr(c, "label", None) or type(c).__name__) for c in v]
    if name == "functions" and v is not None:
        return sorted(str(k) for k in (v.keys() if hasattr(v, "keys") else ()))
    return list(v) if isinstance(v, tuple) else v


GROUPS = {"ode": OdeOptions, "dae": DaeOptions, "contacts": ContactOptions, "fixed_step": FixedStepOptions}
FIELDS = tuple(f.name for f in dataclasses.fields(SimulationSettings) if f.name not in GROUPS)
# flat name -> its group (every field of every group; names are unique across groups and fields)
GROUP_OF = {f.name: g for g, cls in GROUPS.items() for f in dataclasses.fields(cls)}
NAMES = FIELDS + tuple(GROUP_OF)
_ALIASES = {"stop_time": "t_end", "start_time": "t_start", "tolerance": "tolerance", "t0": "t_start",
            "params": "p", "parameters": "p"}


def from_kwargs(t_end=None, **kw) -> SimulationSettings:
    """Settings from flat keyword arguments (those of ``mechdsl.simulate.simulate`` and
    ``Model.simulate``), validated: each name goes to its field or group; an unknown name is
    a usage error with did-you-mean; None means 'not given' (the default applies)."""
    common: dict[str, Any] = {}
    groups: dict[str, dict] = {}
    tol = kw.pop("tolerance", None)
    for k, v in kw.items():
        k = _ALIASES.get(k, k)
        if v is None:
            continue
        if k in FIELDS:
            common[k] = v
        elif k in GROUP_OF:
            groups.setdefault(GROUP_OF[k], {})[k] = v
        elif k in GROUPS and isinstance(v, GROUPS[k]):
            common[k] = v
        else:
            raise unknown_setting(k)
    if tol is not None:
        common.setdefault("rtol", tol)
        common.setdefault("atol", tol)
    if t_end is not None:
        common["t_end"] = t_end
    for g, values in groups.items():
        common[g] = dataclasses.replace(common.get(g, GROUPS[g]()), **values)
    return validate(SimulationSettings(**common))


def resolve(scene_settings: dict | None, args: dict, where=None) -> SimulationSettings:
    """argument > scene > default; ``args`` holds the CLI/API arguments (None = not given).
    Without an end time from either, the run ends at DEFAULT_T_END (10 s), on every path.

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
    return from_kwargs(merged.pop("t_end", None), **merged)     # no end time: DEFAULT_T_END


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
    if s.inputs is not None and not (isinstance(s.inputs, dict) and all(isinstance(k, str) for k in s.inputs)):
        raise UsageError(f"inputs must be a dict {{input name: signal}} (got {type(s.inputs).__name__})")
    method = str(s.method or "auto").lower()
    check_method(method)
    dae = s.dae.validated()
    check_formulation(dae.formulation)
    outputs = s.outputs
    if isinstance(outputs, str):
        outputs = (outputs,)
    elif outputs is not None:
        if not isinstance(outputs, (list, tuple)) or not all(isinstance(o, str) for o in outputs):
            raise UsageError(f"outputs must be a list of names (got {outputs!r})")
        outputs = tuple(outputs)
    max_steps = None if s.max_steps is None else _count("max_steps", s.max_steps, 1)
    for name in ("compiled", "estimate_error"):
        if not isinstance(getattr(s, name), (bool, int)) and not (name == "compiled" and s.compiled is None):
            raise UsageError(f"{name} must be true or false (got {getattr(s, name)!r})")
    estimate = {True: "on", False: "off"}.get(s.error_estimate, s.error_estimate) \
        if isinstance(s.error_estimate, bool) else str(s.error_estimate).lower()
    if estimate not in ("on", "off", "coordinates"):
        raise UsageError(f"error_estimate must be on, off or coordinates (got {s.error_estimate!r})")
    if not isinstance(s.warn, (bool, int)):
        raise UsageError(f"warn must be true or false (got {s.warn!r})")
    if s.integrator_options is not None and not isinstance(s.integrator_options, dict):
        raise UsageError(f"integrator_options must be a dict (got {type(s.integrator_options).__name__})")
    return dataclasses.replace(s, t_start=t0, t_end=t1, rtol=rtol, atol=atol, points=points,
                               method=method, outputs=outputs, max_steps=max_steps,
                               compiled=None if s.compiled is None else bool(s.compiled), budget=budget,
                               estimate_error=bool(s.estimate_error), error_estimate=estimate, warn=bool(s.warn),
                               ode=s.ode.validated(), dae=dae,
                               contacts=s.contacts.validated(),
                               fixed_step=s.fixed_step.validated(t1 - t0, budget))


def unknown_setting(name: str) -> UsageError:
    hint = did_you_mean(name, NAMES)
    return UsageError(f"unknown simulation setting '{name}'" + (f"; {hint}" if hint else ""))
