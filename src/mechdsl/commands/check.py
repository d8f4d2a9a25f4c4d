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
    p.add_argument("-q", "--quiet", action="store_true", help="print only errors")
    p.add_argument("-v", "--verbose", action="store_true",
                   help="also print debugging notes (why each cache entry was or was not used)")
    p.add_argument("--no-units", action="store_true", help="skip dimensional analysis")
    return p


def run(args) -> int:
    from ..api import Model
    from ..frontend.parser import parse_file
    from ..eom.preflight import check_start
    from ..semantic import analyze

    status = 0
    if getattr(args, "verbose", False):
        from ..eom.cachefiles import describe

        describe()
    for path in args.files:
        try:
            program = analyze(parse_file(path), units=not args.no_units)
            targets = []
            if args.scene:
                targets = [("scene", args.scene)]
            elif args.model:
                targets = [("model", args.model)]
            else:
                # a model used as a part of others is checked inside them (alone it may be
                # incomplete, like a Modelica partial model: a link without its joint)
                parts = program.part_users()
                targets = [("model", n) for n in program.model_names() if n not in parts]
                targets += [("scene", n) for n in program.scene_names()]
            lines = []
            if not (args.scene or args.model):
                lines += [f"  {p}: a part of {', '.join(users)} (checked there)" for p, users in parts.items()]
            for kind, name in targets:
                m = Model._from_program(program, name if kind == "model" else None, name if kind == "scene" else None)
                settings = m.scene_settings
                atol = settings.get("atol", 1e-10)
                check_start(m.eom, t=float(settings.get("start_time", 0.0)),
                            drift_bound=settings.get("drift_bound") or max(10 * float(atol), 1e-10))
                for w in m.warnings:
                    print(format_diagnostics([w]), file=sys.stderr)
                if kind == "scene":
                    # the run's own validation (a scene value over a budget is E604) and its plan
                    given = m.scene_settings.get("stop_time") is not None     # else any end: the plan does not depend on it
                    problem = m.problem(**({} if given else {"t_end": float(m.scene_settings.get("start_time") or 0.0) + 1.0}))
                    settings = ", ".join(f"{k} = {_fmt(v)}" for k, v in m.scene.settings)
                    lines.append(f"  scene {name} -> {m.name}" + (f" ({settings})" if settings else ""))
                    lines += [f"    {topic}: {text}" for topic, text in problem.plan]
                else:
                    lines.append("  " + m.summary(derive=True))
                    lines += _extra_lines(m)
            if not args.quiet:
                print(f"{path}: ok")
                print("\n".join(lines))
        except MechError as e:
            print(format_diagnostics(e.diagnostics), file=sys.stderr)
            status = 1
    return status


def _extra_lines(m) -> list[str]:
    from ..model.friction import friction_notes
    from ..simulate import MAX_INTEGRAL_SEARCH  # the search grows like n^3: simulate's bound holds here too

    """Lines other phases contribute (loops, first integrals, ...), each guarded: check never fails on them."""
    out = []
    for lp in m.model.loops:
        out.append(f"    {lp.name}: closed by joint {lp.joint}: {' -> '.join(lp.bodies)}")
    out += ["    " + s for s in friction_notes(m.model, m.parameters)]
    if m.model.loops or m.model.constraints:
        try:
            from ..dae import check_report

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
