"""Options of a constrained simulation (``simulate_dae``), validated in one place."""
from __future__ import annotations

from dataclasses import dataclass, fields

from ..diagnostics import UsageError

FORMULATIONS = ("projection", "ggl", "baumgarte", "partitioning")
DEFAULT_FORMULATION = "projection"
ODE_METHODS = ("auto", "bdf", "adams", "cvodes")
DAE_METHODS = ("auto", "idas", "bdf")

# accepted from the generic simulator, meaningless here: passed through into metadata
_PASSTHROUGH = ("progress", "verbose", "events", "record_energy", "name", "scene")


@dataclass(kw_only=True)
class DaeOptions:
    formulation: str = "auto"
    rtol: float = 1e-6
    atol: float = 1e-8
    method: str = "auto"
    points: int | None = None
    t_start: float = 0.0
    p: object = None                     # parameter vector (array) or {name: value}
    reactions: bool = False              # record every multiplier and every reaction output
    outputs: tuple[str, ...] | None = None
    baumgarte: object = None             # None (automatic), rate omega, or (alpha, beta)
    singular_tol: float = 1e-6           # sigma_min / sigma_max of the scaled G below this: singular
    max_steps: int = 500_000             # integrator steps per segment
    max_interval: float | None = None    # longest segment between checks (default: output spacing)
    drift_bound: float | None = None     # default max(10 atol, 1e-10)
    repartition_cond: float = 10.0       # partitioning: re-partition when cond(G_v) grows by this factor
    force_index: bool = False            # skip the index guard (benchmarks only)

    @property
    def bound(self) -> float:
        return self.drift_bound if self.drift_bound is not None else max(10 * self.atol, 1e-10)


def parse_options(kw: dict) -> tuple[DaeOptions, dict]:
    """Split keyword options into DaeOptions and pass-through extras; unknown names are an error."""
    aliases = {"start_time": "t_start", "t0": "t_start", "tolerance": "rtol", "params": "p",
               "parameters": "p", "stop_time": None}
    known = {f.name for f in fields(DaeOptions)}
    clean, extra = {}, {}
    for k, v in kw.items():
        k2 = aliases.get(k, k)
        if k2 is None:
            continue
        if k2 in known:
            if v is not None or k2 in ("points", "outputs", "baumgarte", "max_interval", "drift_bound", "p"):
                clean[k2] = v
        elif k in _PASSTHROUGH:
            extra[k] = v
        else:
            raise UsageError(f"unknown option {k!r} for a constrained simulation; known: "
                             + ", ".join(sorted(known | set(_PASSTHROUGH))))
    o = DaeOptions(**clean)
    if "tolerance" in kw and "atol" not in kw:
        o.atol = float(kw["tolerance"])
    o.rtol, o.atol = float(o.rtol), float(o.atol)
    if not (o.rtol > 0 and o.atol > 0):
        raise UsageError("rtol and atol must be positive")
    f = (o.formulation or "auto").lower()
    if f == "auto":
        f = DEFAULT_FORMULATION
    if f == "index1":
        f = "baumgarte"
    if f not in FORMULATIONS:
        raise UsageError(f"unknown formulation {o.formulation!r}; choose one of: auto, " + ", ".join(FORMULATIONS))
    o.formulation = f
    meth = (o.method or "auto").lower()
    allowed = DAE_METHODS if f == "ggl" else ODE_METHODS
    if meth not in allowed:
        raise UsageError(f"method {o.method!r} does not apply to formulation {f!r}; choose one of: "
                         + ", ".join(allowed))
    o.method = meth
    if o.points is not None:
        o.points = int(o.points)
        if o.points < 2:
            raise UsageError("points must be at least 2")
    if isinstance(o.outputs, str):
        o.outputs = (o.outputs,)
    elif o.outputs is not None:
        o.outputs = tuple(o.outputs)
    return o, extra
