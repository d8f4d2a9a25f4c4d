"""The simulation's own rules for the settings a scene gives, checked at analysis (E604).

The rules live in simulation/settings.py and simulation/registry.py (method and formulation
names, tolerances, counts); this module applies them to the values written in a scene and
reports each problem at its setting, so `mech check` finds what `mech simulate` would refuse
and `simulate` reports it as a located model error (exit 1), not as a usage error.
"""
from __future__ import annotations

from ..frontend import ast
from ..model import ir
from ..diagnostics import DiagnosticBag


def check_run_settings(s: ast.SceneDef, out: dict[str, object], model: ir.Model) -> None:
    """The simulation's own rules for the settings a scene gives (simulation/settings.py and
    registry.py), reported as E604 at the setting: `check` finds what `simulate` would refuse."""
    from ..diagnostics import UsageError
    from ..simulation import registry as R
    from ..simulation import settings as S

    spans = {it.name: it.value.span for it in s.items if isinstance(it, ast.Setting)}
    diags = DiagnosticBag()

    def bad(name, msg, help=None):
        diags.error("E604", f"'{name}' {msg}", spans[name], help)

    for name, check in (("method", R.check_method), ("formulation", R.check_formulation)):
        if isinstance(out.get(name), str):
            try:
                check(out[name].lower())
            except UsageError as e:
                diags.error("E604", str(e), spans[name], "see docs/simulate.md for the names")
    method = R.METHODS.get(str(out.get("method", "")).lower())
    if method is not None and method.family == "canonical" and (model.loops or model.constraints):
        if not method.constrained:
            bad("method", f"= \"{method.name}\" ignores the constraints of {model.name}",
                'use method = "rattle" (constrained Stormer-Verlet) or an adaptive method (docs/constraints.md)')
    _contact_rules(out, spans, diags, bool(model.contacts))
    for name in ("tolerance", "rtol", "atol"):
        v = out.get(name)
        if isinstance(v, float) and not 0 < v < 1:
            bad(name, f"must lie in (0, 1) (got {v:g})", f"e.g. {name} = 1e-8;")
        elif isinstance(v, float) and name != "atol" and v < S.MIN_RTOL:
            bad(name, f"= {v:g} is below what double precision can deliver", f"use at least {S.MIN_RTOL:g}")
    t0, t1 = out.get("start_time", 0.0), out.get("stop_time")
    if isinstance(t1, float) and isinstance(t0, float) and t1 <= t0 and "stop_time" in spans:
        bad("stop_time", f"must come after the start time {t0:g} (got {t1:g})", "e.g. stop_time = 10;")
    if isinstance(out.get("points"), int) and out["points"] < 2:
        bad("points", f"must be at least 2 (the start and the end; got {out['points']})", "e.g. points = 501;")
    diags.raise_if_errors()


def _contact_rules(out: dict[str, object], spans: dict, diags: DiagnosticBag, contacts: bool) -> None:
    """The contact back end's own rules (impacts/one_step.py, impacts/contact_run.py): rest_speed and
    impact_order for any model (a bad value is refused where it is written, with or without
    contacts), and for a model with contacts its method names (no `rk4`, no symplectic method)."""
    from ..diagnostics import UsageError
    from ..simulation.settings import ContactOptions
    from ..simulation.registry import events_method

    rules = ((("method", events_method),) if contacts else ()) + (
        ("rest_speed", lambda v: ContactOptions(rest_speed=v).validated()),
        ("impact_order", lambda v: ContactOptions(impact_order=v).validated()))
    for name, rule in rules:
        if out.get(name) is not None and name in spans:
            try:
                rule(out[name].lower() if isinstance(out[name], str) else out[name])
            except UsageError as e:
                diags.error("E604", f"{e}" + (" (this model has contacts)" if contacts else ""), spans[name],
                            "see docs/contacts.md")
