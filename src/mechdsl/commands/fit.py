"""``mech fit FILE --data DATA.csv --fit NAME[,NAME...]``: parameters and start values from
measured motion (Model.fit, docs/fitting.md): the estimates with standard errors and units,
the combinations the data cannot determine, the residual; JSON and a plot of data and model."""
from __future__ import annotations

from pathlib import Path

from ._common import (
    add_cache_arg,
    add_force_arg,
    add_set_arg,
    add_target_args,
    assignments,
    load_model,
    split_starts,
    target_line,
)


def add_parser(sub):
    p = sub.add_parser("fit", help="estimate parameters and start values from measured motion (least squares)",
                       description="Fit parameters and start values to measured data: Gauss-Newton / "
                                   "Levenberg-Marquardt with exact sensitivities; prints estimates, standard "
                                   "errors, what the data cannot determine and the residual.")
    add_target_args(p, what="fit")
    add_cache_arg(p)
    p.add_argument("--data", action="append", required=True, metavar="DATA.csv",
                   help="measured samples: a header line (time, then columns named like recorded signals: "
                        "coordinates, der(c), outputs, energies), rows of numbers; repeat for several "
                        "experiments")
    p.add_argument("--fit", action="append", required=True, metavar="NAME[,NAME...]",
                   help="what to estimate: parameters (L), start values (theta.start) and speeds (theta.speed)")
    p.add_argument("--start", action="append", default=[], metavar="NAME=VALUE[,...]",
                   help="the value the fit starts NAME from (default: the model's); a start value or speed "
                        "not fitted is held at it")
    p.add_argument("--weight", action="append", default=[], metavar="COLUMN=W[,...]",
                   help="weight of a measured column (default 1; 1/noise for columns of unlike noise or unit)")
    add_set_arg(p)
    p.add_argument("--t-end", type=float, default=None, metavar="T",
                   help="end of the run (default: the last sample)")
    p.add_argument("--rtol", type=float, default=None, help="relative tolerance of the runs (default: the scene's)")
    p.add_argument("--atol", type=float, default=None, help="absolute tolerance of the runs")
    p.add_argument("--integrator", default=None, metavar="METHOD",
                   help="integration method (a CasADi one: cvodes-bdf, cvodes-adams, idas, erk, rosenbrock, "
                        "rk, collocation; default auto)")
    p.add_argument("--max-iterations", type=int, default=100, metavar="N", help="Levenberg-Marquardt iterations")
    p.add_argument("-o", "--output", metavar="OUT.json", help="write the fit (estimates, errors, correlations, ...)")
    p.add_argument("--plot", nargs="?", const="", metavar="OUT.png",
                   help="draw the data and the fitted model (.png, .svg or .pdf; bare --plot: next to -o OUT.json "
                        "as OUT.png, else fit.png)")
    add_force_arg(p)
    return p


def run(args) -> int:
    from ..diagnostics import UsageError
    from ..output.fileio import check_figure, check_writable, write_atomic
    from ._output import jsonable

    if args.plot == "":                 # bare --plot
        args.plot = str(Path(args.output).with_suffix(".png")) if args.output else "fit.png"
    if args.output:
        check_writable(args.output, args.force)
    if args.plot:
        check_figure(args.plot, args.force)
    names = [s.strip() for item in args.fit for s in item.split(",") if s.strip()]
    if not names:
        raise UsageError("--fit: name at least one parameter or start value")
    m, x0 = load_model(args, starts_in_model=False)
    params, starts = _classify(m, names)
    guess_p, guess_x = split_starts(assignments(args.start, "--start"))
    if guess_p:
        m = m.with_params(**guess_p)
    x0 = {**x0, **guess_x}
    weights = assignments(args.weight, "--weight") or None
    print(target_line(args, m))
    settings = {k: v for k, v in (("rtol", args.rtol), ("atol", args.atol), ("integrator", args.integrator))
                if v is not None}
    experiments = [{"x0": x0}] * len(args.data) if x0 else None
    r = m.fit(args.data if len(args.data) > 1 else args.data[0], params=params, starts=starts, weights=weights,
              experiments=experiments, max_iterations=args.max_iterations, t_end=args.t_end, **settings)
    print(r.table())
    out = args.out
    out.set(target=target_line(args, m), **r.to_dict())
    if not r.success:
        out.warn(f"the fit did not converge: {r.message}")
    if args.output:
        import json

        doc = {"generator": "mechdsl", **jsonable(r.to_dict())}      # the marker: a rerun may replace it
        write_atomic(args.output, json.dumps(doc, indent=2) + "\n", overwrite=args.force)
        print(f"wrote {args.output}")
        out.wrote(args.output)
    if args.plot:
        r.plot(args.plot, overwrite=args.force)
        print(f"wrote {args.plot}")
        out.wrote(args.plot)
    return 0


def _classify(m, names):
    """--fit names -> (parameters, start values): the name of a parameter is a parameter, a
    coordinate's (c.start, c.speed, c, der(c)) a start value; Model.fit checks both further."""
    from ..diagnostics import UsageError, did_you_mean
    from ..model.names import split_state

    by_name = {p.name for p in m.model.parameters}
    coords = list(m.coordinates)
    params, starts = [], []
    for n in names:
        if n in by_name:
            params.append(n)
            continue
        base = n[: -len(".start")] if n.endswith(".start") else n[: -len(".speed")] if n.endswith(".speed") else \
            split_state(n)[0]
        if base not in coords:
            known = sorted(by_name) + [f"{c}.start" for c in coords] + [f"{c}.speed" for c in coords]
            hint = did_you_mean(n, known)
            raise UsageError(f"--fit: '{n}' is neither a parameter nor a start value of {m.name}"
                             + (f"; {hint}" if hint else f" (parameters: {', '.join(sorted(by_name))}; start values: "
                                f"{', '.join(c + '.start' for c in coords)})"))
        starts.append(n)
    return params, starts
