"""FMI export: a mechdsl model as a Functional Mock-up Unit (FMI 2.0 or 3.0).

    from mechdsl.export import export_fmu
    info = export_fmu(model, "pendulum.fmu", fmi_version=2, fmi_type="both")
    model.export_fmu("pendulum.fmu")                       # the same, from mechdsl.Model
    mech export models/pendulum.mech --fmu pendulum.fmu    # the same, from the shell

The FMU is self-contained for the platform it is built on: modelDescription.xml, the C
sources and the compiled binary; running it needs neither Python nor CasADi nor mechdsl.
Model exchange exposes the formulated ODE (minimal coordinates; a constrained model's
index-1 ODE, its drift projected away at step events) with directional derivatives from
CasADi; co-simulation steps itself with the compiled Runge-Kutta loop of ``mech simulate``
and handles contacts and impacts inside the step.  See docs/export.md for what is
exported and how to load an FMU in OpenModelica, Simulink and fmpy; the design is in
docs/internals/export.md.
"""
from __future__ import annotations

import re
from dataclasses import dataclass, field

from ..diagnostics import UsageError

FMI_VERSIONS = (2, 3)
FMI_TYPES = ("me", "cs", "both")


@dataclass
class ExportInfo:
    """What ``export_fmu`` wrote."""
    path: str
    identifier: str
    fmi_version: int
    interfaces: tuple[str, ...]          # ("model exchange", "co-simulation")
    size: int                            # bytes of the .fmu
    variables: int
    notes: list[str] = field(default_factory=list)


def identifier_of(name: str) -> str:
    """A C identifier for the model (the FMU's modelIdentifier and binary name)."""
    ident = re.sub(r"[^A-Za-z0-9_]", "_", name) or "model"
    return ident if not ident[0].isdigit() else "_" + ident


def _interfaces(fmi_type: str | None) -> tuple[bool, bool, list[str]]:
    """(model exchange, co-simulation, notes) for the requested type.  Every model has both:
    contacts and fixations are event indicators and time events in model exchange, their
    impacts applied by the FMU's own impact map at the importer's events (docs/export.md)."""
    if fmi_type is not None and fmi_type not in FMI_TYPES:
        raise UsageError(f"--fmi-type must be one of {', '.join(FMI_TYPES)} (got {fmi_type!r})")
    return fmi_type in (None, "me", "both"), fmi_type in (None, "cs", "both"), []


def _defaults(model, s, plan, kind: str) -> dict:
    """The mechdsl.* settings' start values, from the run's settings and the simulation layer's
    own rules (export/problem.py); those of contacts only for a model with contacts (the others
    get placeholders the runtime never reads, and no variable: ``variables.table``)."""
    from ..simulation.settings import DEFAULT_POINTS
    from . import problem

    contacts = bool(plan.k or plan.nfix)
    c = problem.contact_defaults(s) if contacts else \
        {"rest_speed": 0.0, "impact_order": 0, "max_events": 0, "acc_tol": 0.0, "samples": 1}
    span = float(s.t_end) - float(s.t_start)
    points = int(s.points or DEFAULT_POINTS)
    return {"mechdsl.rtol": float(s.rtol), "mechdsl.atol": float(s.atol), "mechdsl.rest_speed": c["rest_speed"],
            "mechdsl.drift_bound": 0.0,
            "mechdsl.projection_interval": span / 60.0 if (plan.m or plan.k or plan.nfix) else 0.0,
            "mechdsl.method": 1 if problem.stepper(model, s, kind) == "dopri5" else 2,
            "mechdsl.impact_order": c["impact_order"],
            "mechdsl.max_steps": problem.max_steps(s, points), "mechdsl.max_events": c["max_events"],
            "_acc_tol": c["acc_tol"], "_samples": c["samples"], "_points": points}


def export_fmu(model, path, *, fmi_version: int = 2, fmi_type: str | None = None,
               overwrite: bool = False) -> ExportInfo:
    """Write ``model`` (a mechdsl.Model) as an FMU to ``path``.

    fmi_version: 2 or 3; fmi_type: "me" (model exchange), "cs" (co-simulation), "both", or
    None (both).
    overwrite: replace an existing file that mechdsl did not write.  Nothing is written
    unless the whole FMU was built (atomic replace)."""
    from ..output.fileio import check_writable, write_atomic
    from . import build, functions, problem, variables, xml

    try:
        fmi_version = int(fmi_version)
    except (TypeError, ValueError):
        raise UsageError(f"the FMI version must be 2 or 3 (got {fmi_version!r})") from None
    if fmi_version not in FMI_VERSIONS:
        raise UsageError(f"the FMI version must be 2 or 3 (got {fmi_version})")
    if not str(path).endswith(".fmu"):
        raise UsageError(f"an FMU's file name ends in .fmu (got {str(path)!r})")
    check_writable(path, overwrite)
    want_me, want_cs, notes = _interfaces(fmi_type)
    folder, suffix = build.platform_folder(fmi_version)
    s = problem.run_settings(model)
    plan = functions.build(model, problem.functions(model))
    kind = "hybrid" if plan.k or plan.nfix else ("dae" if plan.m else "ode")
    defaults = _defaults(model, s, plan, kind)
    start_calc = problem.start_depends_on_parameters(model.eom)
    indicators = plan.k if want_me and (plan.k or plan.nfix) else 0
    table = variables.table(model, plan, defaults, start_calc, fmi_version, indicators)
    ident = identifier_of(model.name)
    eom = model.eom
    from ..eom.codegen import free_parameters

    free = free_parameters(eom)
    n = eom.n
    meta = {
        "model": model.name, "token": xml.TOKEN, "me": want_me, "cs": want_cs,
        "free_index": [list(eom.params).index(f) for f in free],
        "p_default": [float(v) for v in eom.param_values],
        "u_default": [float(v) for v in eom.input_defaults],
        "start_calculated": list(start_calc),
        "fixed_q": list(eom.fixed_q) if len(eom.fixed_q) == n else [True] * n,
        "fixed_qd": list(eom.fixed_qd) if len(eom.fixed_qd) == n else [True] * n,
        "int_values": [v.start for v in table if v.kind == "constant"],
        "params": list(eom.params), "coords": list(eom.coords),
        "rows": list(eom.constraint_names) + [g.name for g in plan.gaps]
                + [f"{f.label}.{a}" for f in plan.fixations for a in "xyz"],
        "real_settings": [defaults[k] for k, _, _ in variables.REAL_SETTINGS],
        "int_settings": [defaults[k] for k, _, _, _ in variables.INT_SETTINGS],
        "acc_tol": defaults["_acc_tol"], "samples": defaults["_samples"],
        "rules": problem.rules(s, bool(plan.m), bool(plan.k or plan.nfix)),
    }
    srcs = build.sources(meta, plan, fmi_version)
    from .. import __version__

    step = (float(s.t_end) - float(s.t_start)) / (defaults["_points"] - 1)
    info = {"identifier": ident, "model": model.name, "description": getattr(model.model, "doc", "") or "",
            "tool": f"mechdsl {__version__}", "me": want_me, "cs": want_cs, "constrained": bool(plan.m),
            "contacts": bool(plan.k or plan.nfix), "sources": build.c_files(srcs),
            "event_indicators": indicators,
            "experiment": {"start": float(s.t_start), "stop": float(s.t_end), "tolerance": float(s.rtol),
                           "step": step}}
    md = (xml.model_description_2 if fmi_version == 2 else xml.model_description_3)(info, table)
    token = build.token_of([md, *(srcs[k] for k in sorted(srcs))])
    md = md.replace(xml.TOKEN, token)
    srcs["model_data.c"] = srcs["model_data.c"].replace(xml.TOKEN, token)
    binary = build.compile_library(srcs, ident, suffix)
    files = {"modelDescription.xml": md.encode(), f"binaries/{folder}/{ident}{suffix}": binary}
    for name, text in srcs.items():
        files[f"sources/{name}"] = text.encode()
    if fmi_version == 3:
        files["sources/buildDescription.xml"] = xml.build_description(ident, build.c_files(srcs)).encode()
    lic = (build.HERE / "fmi" / "LICENSE.txt").read_bytes()
    files["documentation/licenses/fmi-headers.txt"] = lic
    files["sources/LICENSE-fmi-headers.txt"] = lic
    data = build.zip_bytes(files)
    write_atomic(path, data, overwrite=overwrite)
    kinds = tuple(k for k, on in (("model exchange", want_me), ("co-simulation", want_cs)) if on)
    return ExportInfo(path=str(path), identifier=ident, fmi_version=fmi_version, interfaces=kinds, size=len(data),
                      variables=len(table), notes=notes)


__all__ = ["export_fmu", "ExportInfo", "FMI_VERSIONS", "FMI_TYPES"]
