"""``mech bench FILE``: work-precision benchmark of a model (docs/performance.md)."""
from __future__ import annotations

import sys

from ..diagnostics import UsageError

HELP = "speed against accuracy: run methods over a tolerance sweep, measure errors and CPU time, draw the chart"


def add_parser(sub):
    from ..bench.plan import RUN_BUDGET, SWEEP_BUDGET
    from ..bench.runner import DEFAULT_BUDGET
    from ._common import add_cache_arg, add_set_arg, add_target_args
    from .simulate import _number_arg

    p = sub.add_parser("bench", help=HELP, description=HELP)
    add_target_args(p, what="benchmark")
    add_cache_arg(p)
    p.add_argument("--methods", action="append", default=[], metavar="LIST",
                   help="comma-separated method specifications: erk, cvodes-bdf, scipy-dop853, stormer-verlet, "
                        "rk[dt=0.01]; for constrained models FORMULATION+METHOD, e.g. projection+cvodes-bdf "
                        "(default: a set that fits the model)")
    p.add_argument("--formulations", action="append", default=[], metavar="LIST",
                   help="formulations (constrained models) combined with every method that names none")
    p.add_argument("--tolerances", metavar="SPEC", default=None,
                   help="'1e-2,1e-4', '1e-2..1e-12' (half decades) or '1e-2..1e-12/4' (default: one a decade from "
                        "1e-2 or 1e-3 down to 1e-8 .. 1e-10 by the model's cost, see docs/performance.md); "
                        "rtol = atol = tolerance")
    p.add_argument("--reference", metavar="auto|FILE", default="auto",
                   help="reference solution: a CSV in the format of mech simulate -o, or auto (two high-accuracy "
                        "runs with different methods; their difference estimates its accuracy)")
    p.add_argument("--reference-methods", metavar="A,B", help="methods of the automatic reference and its check")
    p.add_argument("--compare", metavar="WHAT", default="positions",
                   help="compared columns: positions (coordinates, default), states (and speeds) or a list of names")
    p.add_argument("--repeats", type=int, default=None, metavar="K",
                   help="timed runs after the warm-up (default 3; 1 for a costly model)")
    p.add_argument("--budget", type=_number_arg, default=None, metavar="S",
                   help=f"CPU seconds: a run longer than this ends its method's sweep (default {DEFAULT_BUDGET:g} "
                        f"with given tolerances and end time, else {RUN_BUDGET:g}, with {SWEEP_BUDGET:g} s for the "
                        "whole sweep)")
    p.add_argument("--t-end", type=_number_arg, metavar="T",
                   help="end time [s] (default: scene stop_time, else 10; shortened for a costly model)")
    p.add_argument("--points", type=int, metavar="N", help="output points (default: scene points, else 101)")
    add_set_arg(p)
    p.add_argument("--compiled", action="store_true", help="generated and compiled C code for every method")
    p.add_argument("-o", "--output", metavar="DIR", help="write bench.csv, bench.json, work_precision.png/.svg here")
    p.add_argument("--no-chart", action="store_true", help="write no chart")
    p.add_argument("--force", action="store_true", help="overwrite existing output files")
    return p


def default_methods(kind: str) -> list[str]:
    from ..bench.spec import DEFAULT_ODE_METHODS

    if kind == "stiff":
        return ["auto", "cvodes-bdf", "rosenbrock", "scipy-radau", "erk"]
    if kind == "dae":
        try:
            from ..dae.dae_run import FORMULATIONS
        except ImportError:
            FORMULATIONS = ("projection", "ggl", "baumgarte", "partitioning")
        return [f"{f}+auto" for f in FORMULATIONS]
    return list(DEFAULT_ODE_METHODS)


def run(args) -> int:
    from ..bench import Setup, parse_tolerances, parse_variants, run_bench
    from ..bench.runner import classify_setup
    from ._common import load_model, target_line

    if args.repeats is not None and args.repeats < 1:
        raise UsageError("--repeats must be at least 1")
    tolerances = parse_tolerances(args.tolerances)
    out = _checked_output(args)
    model, x0 = load_model(args, starts_in_model=False)
    x0 = x0 or None
    print(target_line(args, model))
    setup = Setup.from_model(model, t_end=args.t_end, points=args.points, x0=x0, compiled=args.compiled,
                             source=str(args.file))
    kind = classify_setup(setup)
    ref_methods = None
    if args.reference_methods:
        from ..bench.spec import split_top

        ref_methods = split_top(args.reference_methods)
    log = None if args.out.quiet else (lambda s: print(s, file=sys.stderr, flush=True))
    plan = _plan(args, setup, kind, log, tolerances)
    variants = parse_variants(plan["methods"], args.formulations or None)
    if not args.methods:
        setup.notes.append(f"methods: the default set for a{'n' if kind == 'ode' else ''} {kind} model "
                           f"({', '.join(v.label for v in variants)}); give --methods for others")
    for n in setup.notes:
        if log:
            log(f"plan: {n}")
    res = run_bench(setup, variants=variants, tolerances=plan["tolerances"],
                    reference=args.reference, reference_methods=ref_methods, compare=args.compare,
                    repeats=plan["repeats"], budget=plan["budget"], sweep_budget=plan["sweep_budget"],
                    stop_after=plan["stop_after"], log=log)
    return _report(args, res, out, target_line(args, model))


def _checked_output(args):
    """The output folder (None: none asked for), its files checked writable before any work."""
    from ..output.fileio import check_writable, output_folder

    out = output_folder(args.output) if args.output else None
    if out is not None:
        names = ["bench.json", "bench.csv"] + ([] if args.no_chart else ["work_precision.png", "work_precision.svg"])
        for n in names:
            check_writable(out / n, overwrite=args.force)
    return out


def _plan(args, setup, kind: str, log, tolerances: list[float]) -> dict:
    """Methods, tolerances, repeats and budgets of the bench: the options given, the defaults,
    and (``--reference auto``) the plan of bench/plan.py, which also sets the horizon and notes."""
    from ..bench import parse_tolerances
    from ..bench.runner import DEFAULT_BUDGET

    plan = {"methods": args.methods or default_methods(kind), "tolerances": tolerances,
            "repeats": args.repeats or 3, "budget": DEFAULT_BUDGET if args.budget is None else args.budget,
            "sweep_budget": None, "stop_after": None}
    if args.reference == "auto":           # a file reference fixes the horizon and costs nothing to make
        from ..bench.plan import default_plan, plan_methods

        p = default_plan(setup, t_end_given=args.t_end is not None, tolerances_given=args.tolerances is not None,
                         repeats_given=args.repeats is not None, budget_given=args.budget is not None, log=log)
        if not args.methods:
            plan["methods"] = plan_methods(p, plan["methods"])
        setup.t_end = p.t_end
        setup.notes += p.notes
        if p.tolerances is not None:
            plan["tolerances"] = parse_tolerances(p.tolerances)
        plan["repeats"] = p.repeats or plan["repeats"]
        plan["budget"] = p.budget if p.budget is not None else plan["budget"]
        plan["sweep_budget"], plan["stop_after"] = p.sweep_budget, p.stop_after
    return plan


def _report(args, res, out, target: str) -> int:
    """Print the table and the fastest lines, write the files asked for; 130 if interrupted."""
    import json

    from ..bench import format_table, write_chart, write_tables
    from ..bench.report import fastest_lines, to_json_text

    print(format_table(res))
    print()
    print("\n".join(fastest_lines(res)))
    args.out.set(target=target, **json.loads(to_json_text(res, None)))
    if out is not None:
        written = write_tables(res, out, overwrite=args.force)
        if not args.no_chart:
            written += write_chart(res, out, overwrite=args.force)
        for w in written:
            print(f"wrote {w}")
        args.out.wrote(*written)
    if res.interrupted:
        print("mech: interrupted: the rows measured are kept (the others are 'skipped')", file=sys.stderr)
        args.out.fail("interrupted", "interrupted: the rows measured are kept (the others are 'skipped')")
        return 130
    return 0
