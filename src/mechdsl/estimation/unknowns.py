"""What a sensitivity study or a fit varies: parameters and start values, by name, in their units.

``unknowns(model, eom, params, starts) -> Unknowns`` checks the names once against the model
(a Real parameter without a binding; a coordinate ``c`` / ``c.start`` or its speed ``der(c)`` /
``c.speed``) and keeps for each its declared unit and the factor from that unit to SI: the
CasADi Functions work in SI, what a person reads (derivatives, estimates, standard errors) is
in the declared units (per degree for an angle declared in degrees).  ``Unknowns.seeds`` are
the directions of the derivatives: how the run's parameter vector and start move per unit
of each unknown (dependent parameters recomputed through the model's ``parameters``
Function, start values written as expressions of parameters through ``start``, and a
constrained model's consistent initialization through its linearization).
"""
from __future__ import annotations

import casadi as ca
import numpy as np

from ..diagnostics import UsageError, did_you_mean
from ..eom.codegen import casadi_functions, free_parameters
from ..eom.start import state_key
from ..model.names import split_state, state_name
from ..model.records import record
from ..model.units import parse_unit


@record
class Unknown:
    name: str                  # as reported: a parameter's name, a coordinate "c" or "der(c)"
    kind: str                  # "parameter" | "start"
    index: int                 # parameter: its index in p; start: its index in [q; qd]
    unit: str                  # the declared unit ("" when none is declared)
    factor: float              # SI value per declared unit
    lower: float | None = None     # bounds (SI): a parameter's declared min / max
    upper: float | None = None


@record
class Unknowns:
    items: tuple[Unknown, ...]

    @property
    def names(self) -> tuple[str, ...]:
        return tuple(u.name for u in self.items)

    @property
    def factors(self) -> np.ndarray:
        return np.array([u.factor for u in self.items], float)

    def __len__(self) -> int:
        return len(self.items)

    def values(self, pv, x) -> np.ndarray:
        """The unknowns' SI values in the parameter vector ``pv`` and the start ``x``."""
        return np.array([pv[u.index] if u.kind == "parameter" else x[u.index] for u in self.items], float)

    def seeds(self, eom, pv, dx_dp, dx_dx) -> tuple[np.ndarray, np.ndarray]:
        """(DX (nx, k), DP (np, k)): the change of the start and of the parameter vector per SI
        unit of each unknown; ``dx_dp``, ``dx_dx``: the start's derivatives (Trajectory.start)."""
        k = len(self.items)
        DP = np.zeros((eom.p.numel(), k))
        DX = np.zeros((2 * eom.n, k))
        dpar = parameter_jacobian(eom, pv)
        free = list(free_parameters(eom))
        for j, u in enumerate(self.items):
            if u.kind == "parameter":
                DP[:, j] = dpar[:, free.index(eom.params[u.index])]
                DX[:, j] = dx_dp @ DP[:, j]
            else:
                DX[:, j] = dx_dx[:, u.index]
        return DX, DP

    def parameter_values(self, eom, pv, theta) -> np.ndarray:
        """The full parameter vector with the parameter unknowns at ``theta`` (SI), dependent
        parameters recomputed from their bindings."""
        free = list(free_parameters(eom))
        values = {n: float(pv[eom.params.index(n)]) for n in free}
        for u, v in zip(self.items, theta):
            if u.kind == "parameter":
                values[eom.params[u.index]] = float(v)
        f = casadi_functions(eom, names=("parameters",))["parameters"]
        return np.array(f([values[n] for n in free]), float).ravel() if free else np.asarray(pv, float)

    def start_overrides(self, eom, base, theta) -> dict | None:
        """The settings' start overrides ``base`` with the start unknowns at ``theta`` (SI)."""
        starts = {u.name: float(v) for u, v in zip(self.items, theta) if u.kind == "start"}
        if not starts:
            return base
        out: dict = {}
        if isinstance(base, dict):
            out.update(base)
        elif base is not None:
            names = list(eom.coords) + [f"der({c})" for c in eom.coords]
            out.update(zip(names, np.asarray(base, float).ravel()))
        for k in list(out):       # one key per state
            i = state_key(eom, str(k))
            if any(u.kind == "start" and u.index == i for u in self.items):
                del out[k]
        out.update(starts)
        return out


def parameter_jacobian(eom, pv) -> np.ndarray:
    """d p / d free: the parameter vector per free parameter (dependent ones recomputed)."""
    free = list(free_parameters(eom))
    if not free:
        return np.zeros((eom.p.numel(), 0))
    f = casadi_functions(eom, names=("parameters",))["parameters"]
    J = eom.workspace.memo(("parameters_jacobian", id(f)), lambda: _jacobian(f))
    values = [float(pv[eom.params.index(n)]) for n in free]
    return np.array(J(values), float).reshape(eom.p.numel(), len(free))


def _jacobian(f):
    x = ca.SX.sym("free", f.size1_in(0))
    return ca.Function("dparameters", [x], [ca.jacobian(f(x), x)])


def factor(unit: str | None) -> float:
    """SI per declared unit (1 when none is declared or the unit is not known)."""
    if not unit:
        return 1.0
    try:
        return float(parse_unit(str(unit).strip())[0])
    except ValueError:
        return 1.0


def unknowns(model, eom, params=(), starts=()) -> Unknowns:
    """Check ``params`` (Real parameters without a binding) and ``starts`` (start values and
    speeds) against the model: a UsageError with did-you-mean for a name that is not one."""
    params, starts = _names(params, "params"), _names(starts, "starts")
    by_name = {p.name: p for p in model.model.parameters}
    coords = list(eom.coords)
    items: list[Unknown] = []
    for name in params:
        p = by_name.get(name)
        if p is None or p.input or p.integer or p.binding is not None or name not in eom.params:
            raise UsageError(_not_a_parameter(model, name, p, coords))
        items.append(Unknown(name, "parameter", list(eom.params).index(name), p.unit or "", factor(p.unit),
                             p.min, p.max))
    for name in starts:
        key = _start_key(name, coords)
        if key is None:
            hint = did_you_mean(name, coords + [f"der({c})" for c in coords])
            raise UsageError(f"starts: '{name}' is not a coordinate of {model.name} (a start value is 'c' or "
                             f"'c.start', a start speed 'der(c)' or 'c.speed')" + (f"; {hint}" if hint else
                             f"; coordinates: {', '.join(coords) or 'none'}"))
        coord, speed = split_state(key)
        unit = model.model.coordinate(coord).unit or ""
        items.append(Unknown(key, "start", state_key(eom, key), f"{unit}/s" if speed and unit else
                             ("1/s" if speed else unit), factor(unit)))
    names = [u.name for u in items]
    twice = sorted({n for n in names if names.count(n) > 1})
    if twice:
        raise UsageError(f"{', '.join(repr(n) for n in twice)} named twice")
    if not items:
        raise UsageError("name at least one parameter (params=[...]) or start value (starts=[...])")
    return Unknowns(tuple(items))


def _names(v, what) -> list[str]:
    if v is None:
        return []
    if isinstance(v, str):
        v = [s for s in v.split(",")]
    out = []
    for s in v:
        if not isinstance(s, str) or not s.strip():
            raise UsageError(f"{what}: names are non-empty strings (got {s!r})")
        out.append(s.strip())
    return out


def _start_key(name: str, coords) -> str | None:
    coord, speed = split_state(name)
    if coord in coords:
        return state_name(coord, speed)
    for suffix, speed in ((".start", False), (".speed", True)):
        if name.endswith(suffix) and name[: -len(suffix)] in coords:
            return state_name(name[: -len(suffix)], speed)
    return None


def _not_a_parameter(model, name, p, coords) -> str:
    if p is None:
        real = [q.name for q in model.model.real_parameters if q.binding is None]
        hint = did_you_mean(name, real + coords)
        if name in coords or _start_key(name, coords):
            return (f"params: '{name}' is a coordinate of {model.name}, not a parameter: name its start value "
                    f"in starts=[...] (mech fit: --fit {name}.start)")
        return (f"params: '{name}' is not a parameter of {model.name}" + (f"; {hint}" if hint else
                f" (parameters: {', '.join(real) or 'none'})"))
    if p.input:
        return f"params: '{name}' is an input of {model.name}, not a parameter (it is driven, not estimated)"
    if p.integer:
        return f"params: '{name}' is an Integer/Boolean parameter: structural, it has no derivative"
    if p.binding is not None:
        from ..model.exprs import to_text

        return (f"params: '{name}' is a dependent parameter of {model.name} ({name} = {to_text(p.binding)}): name "
                "the parameters it is computed from")
    return f"params: '{name}' does not enter the equations of {model.name}"
