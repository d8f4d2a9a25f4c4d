"""Options of a constrained simulation (``simulate_dae``), validated in one place.

``mechdsl.simulate.simulate`` forwards its whole calling convention here (t_start, rtol,
atol, method, points, outputs, x0, p, progress and its extra options), so every option of
the ODE simulator is accepted; those that mean nothing for a DAE are listed in the
metadata notes rather than silently dropped.
"""
from __future__ import annotations

from dataclasses import dataclass, fields

from ..diagnostics import UsageError, did_you_mean

FORMULATIONS = ("projection", "ggl", "baumgarte", "partitioning", "augmented")
DEFAULT_FORMULATION = "projection"
# method names (those of mechdsl.integrators included) -> the CVODES multistep method
ODE_METHODS = {"auto": "auto", "bdf": "bdf", "cvodes": "bdf", "cvodes-bdf": "bdf", "adams": "adams",
               "cvodes-adams": "adams", "erk": "erk"}
STEPS_PER_INTERVAL = 5000     # default step budget per monitoring interval (>= 60 intervals per run)
DAE_METHODS = {"auto": "idas", "idas": "idas"}

# options of the ODE simulator that have no meaning here (reported in the metadata notes)
_IGNORED = ("dt", "integrator_options", "singularity_threshold", "functions", "name", "scene",
            "verbose")


@dataclass(kw_only=True)
class DaeOptions:
    formulation: str = "auto"
    rtol: float = 1e-8
    atol: float = 1e-10
    method: str = "auto"
    points: int | None = None
    t_start: float = 0.0
    p: object = None                     # parameter vector (array) or {name: value}
    x0: object = None                    # start overrides: [q; qd] or {coordinate | "der(c)": value}
    progress: object = None              # callable(t, t_end), or None
    reactions: bool = False              # record every multiplier and every reaction output
    outputs: tuple[str, ...] | None = None
    baumgarte: object = None             # None (automatic), rate omega, or (alpha, beta)
    singular_tol: float = 1e-6           # sigma_min / sigma_max of the scaled G below this: singular
    max_steps: int | None = None         # integrator steps per interval at the start (default 5000)
    max_interval: float | None = None    # longest segment between checks (default: monitoring grid)
    drift_bound: float | None = None     # default max(10 atol, 1e-10)
    repartition_cond: float = 10.0       # partitioning: re-partition when cond(G_v) grows by this factor
    force_index: bool = False            # skip the index guard (benchmarks only)
    compiled: bool = False               # ODE formulations: the integrated right-hand side as C (gcc)

    @property
    def bound(self) -> float:
        return self.drift_bound if self.drift_bound is not None else max(10 * self.atol, 1e-10)

    @property
    def steps(self) -> int:
        """Integrator steps allowed per output interval of an integrator call until a segment
        succeeded; then also up to 8 times the steps per unit time seen (see the driver)."""
        return int(self.max_steps or STEPS_PER_INTERVAL)


def parse_options(kw: dict) -> tuple[DaeOptions, dict]:
    """Split keyword options into DaeOptions and ignored extras; unknown names are an error."""
    aliases = {"start_time": "t_start", "tolerance": "rtol", "params": "p", "parameters": "p"}
    known = {f.name for f in fields(DaeOptions)}
    clean, extra = {}, {}
    for k, v in kw.items():
        k2 = aliases.get(k, k)
        if k2 in known:
            if v is not None or k2 in ("points", "outputs", "baumgarte", "max_interval", "drift_bound", "p", "x0"):
                clean[k2] = v
        elif k in _IGNORED:
            if v not in (None, False, {}):
                extra[k] = v
        else:
            hint = did_you_mean(k, sorted(known | set(_IGNORED)))
            raise UsageError(f"unknown option {k!r} for a constrained simulation" + (f"; {hint}" if hint else ""))
    o = DaeOptions(**clean)
    if "tolerance" in kw and "atol" not in kw:
        o.atol = float(kw["tolerance"])
    try:
        o.rtol, o.atol, o.t_start = float(o.rtol), float(o.atol), float(o.t_start)
    except (TypeError, ValueError):
        raise UsageError("t_start, rtol and atol must be numbers") from None
    if not (0 < o.rtol < 1 and 0 < o.atol < 1):
        raise UsageError(f"rtol and atol must be positive and below 1 (got {o.rtol}, {o.atol})")
    f = str(o.formulation or "auto").lower()
    if f in ("auto", "dae"):
        f = DEFAULT_FORMULATION
    if f == "index1":
        f = "baumgarte"
    if f not in FORMULATIONS:
        raise UsageError(f"unknown formulation {o.formulation!r}; choose one of: auto, " + ", ".join(FORMULATIONS))
    o.formulation = f
    meth = str(o.method or "auto").lower()
    table = DAE_METHODS if f == "ggl" else ODE_METHODS
    if meth not in table:
        raise UsageError(f"method {o.method!r} does not apply to formulation {f!r} of a constrained model; "
                         f"choose one of: {', '.join(table)}")
    o.method = table[meth]
    if o.points is not None:
        if isinstance(o.points, float) and o.points == int(o.points):
            o.points = int(o.points)
        if not isinstance(o.points, int) or isinstance(o.points, bool) or o.points < 2:
            raise UsageError(f"points must be an integer of at least 2; got {o.points!r}")
    if isinstance(o.outputs, str):
        o.outputs = (o.outputs,)
    elif o.outputs is not None:
        o.outputs = tuple(o.outputs)
    if o.progress is not None and not callable(o.progress):
        o.progress = None
    return o, extra
