"""``mech check FILE...``: parse, analyze, derive and check the start state (mechdsl.eom.preflight);
print each model's formulation, or the diagnostics."""
from __future__ import annotations

import sys

from ..diagnostics import MechError
from ..diagnostics import format_diagnostics


def add_parser(sub):
    p = sub.add_parser("check", help="check models for errors and show how they will be compiled",
                       description="Parse and analyze .mech files; report errors, or each model's counts and "
                                   "the formulation mechdsl chooses for it.")
    p.add_argument("files", nargs="+", metavar="FILE")
    p.add_argument("--model", help="check only this model")
    p.add_argument("--scene", help="check only this scene")
    p.add_argument("--no-units", action="store_true", help="skip dimensional analysis")
    return p


def run(args) -> int:
    from ..api import Model
    from ..frontend.parser import parse_file
    from ..semantic import analyze

    status = 0
    out = args.out
    files = []
    if out.verbosity >= 1:          # -v: the cache folders, used or not and why (issue 25)
        from ..eom.cachefiles import describe

        describe()
    for path in args.files:
        record = {"file": str(path), "ok": False, "targets": []}
        files.append(record)
        try:
            program = analyze(parse_file(path), units=not args.no_units)
            if args.scene:
                targets = [("scene", args.scene)]
            elif args.model:
                targets = [("model", args.model)]
            else:
                targets = check_targets(program)
            lines = []
            parts = program.part_users()
            if not (args.scene or args.model):
                lines += [f"  {p}: a part of {', '.join(users)} (checked there)" for p, users in parts.items()]
            for kind, name in targets:
                m = Model._from_program(program, name if kind == "model" else None, name if kind == "scene" else None)
                problem = check_start_state(m)
                for w in m.warnings:
                    print(format_diagnostics([w]), file=sys.stderr)
                    out.diagnostic(w)
                entry = {"kind": kind, "name": name, "model": m.name}
                record["targets"].append(entry)
                if kind == "scene":
                    settings = ", ".join(f"{k} = {_fmt(v)}" for k, v in m.scene.settings)
                    lines.append(f"  scene {name} -> {m.name}" + (f" ({settings})" if settings else ""))
                    lines += [f"    {topic}: {text}" for topic, text in problem.plan]
                    entry.update(settings={k: v for k, v in m.scene.settings},
                                 plan={topic: text for topic, text in problem.plan})
                else:
                    entry["summary"] = m.summary(derive=True)
                    lines.append("  " + entry["summary"])
                    extra = _extra_lines(m)
                    entry["notes"] = [s.strip() for s in extra]
                    lines += extra
            record["ok"] = True
            if not (args.scene or args.model):
                record["parts"] = {p: list(users) for p, users in parts.items()}
            print(f"{path}: ok")
            print("\n".join(lines))
        except MechError as e:
            print(format_diagnostics(e.diagnostics), file=sys.stderr)
            for d in e.diagnostics:
                out.diagnostic(d)
            status = 1
    out.set(files=files)
    if status:
        out.fail("model", f"{sum(not f['ok'] for f in files)} of {len(files)} file(s) have errors")
    return status


def check_targets(program) -> list[tuple[str, str]]:
    """What ``mech check FILE`` checks: ("model", name) for every model that is not a part of
    another (a part may be incomplete alone, like a Modelica partial model: a link without its
    joint; it is checked inside the models that use it), then ("scene", name) for every scene."""
    parts = program.part_users()
    return [("model", n) for n in program.model_names() if n not in parts] + [("scene", n) for n in program.scene_names()]


def check_start_state(m):
    """The start-state checks of ``mech check`` (mechdsl.eom.preflight) on a loaded model; for a
    scene also the run's own validation (a scene value over a budget is E604).  Raises MechError;
    returns the scene's Problem (its plan), else None."""
    from ..eom.preflight import check_start

    # the run's own settings (argument > scene > default): its start time and drift bound
    given = m.scene_settings.get("stop_time") is not None     # else any end: the plan does not depend on it
    end = {} if given else {"t_end": float(m.scene_settings.get("start_time") or 0.0) + 1.0}
    run = m.settings(**end)
    check_start(m.eom, t=run.t_start, drift_bound=run.dae.bound(run.atol))
    return None if m.scene is None else m.problem(**end)


def _extra_lines(m) -> list[str]:
    from ..model.friction import friction_notes
    from ..simulation.monitors import MAX_INTEGRAL_SEARCH  # the search grows like n^3: simulate's bound holds here too

    """Lines other phases contribute (loops, first integrals, ...), each guarded: check never fails on them."""
    out = []
    for lp in m.model.loops:
        out.append(f"    {lp.name}: closed by joint {lp.joint}: {' -> '.join(lp.bodies)}")
    out += ["    " + s for s in friction_notes(m.model, m.parameters)]
    if m.model.loops or m.model.constraints:
        try:
            from ..dae.init import check_report

            out += ["    " + s for s in check_report(m.eom)]
        except MechError:
            pass
    if not m.model.loops and not m.model.constraints and len(m.model.coordinates) <= MAX_INTEGRAL_SEARCH:
        try:
            from ..analysis.integrals import describe_integrals

            note = " (between impacts)" if m.model.contacts else ""
            out += [f"    first integral{note} " + s for s in describe_integrals(m.eom)]
        except MechError:
            pass
    return out


def _fmt(v) -> str:
    if isinstance(v, tuple):
        return "{" + ", ".join(map(str, v)) + "}"
    if isinstance(v, str):
        return f'"{v}"'
    return f"{v:g}" if isinstance(v, float) else str(v)
