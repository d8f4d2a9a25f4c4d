"""``mech sweep FILE``: a parameter sweep or Monte Carlo ensemble -> .nc or .csv (+ a heat map).

    mech sweep models/double_pendulum.mech --grid "j1.phi.start=-3:3:64" --grid "j2.phi.start=-3:3:64" \\
        --t-end 10 -o flip.nc --plot flip.png --metric "flip:j1.phi+j2.phi"

Imports xarray/pandas (and Dask) only here, never for the other commands.
"""
from __future__ import annotations

import sys

from ..diagnostics import UsageError
from ._common import add_cache_arg, add_force_arg, add_set_arg, add_target_args, load_model

HELP = "run a model over a grid or a random sample of parameters and start values"
METRICS = "flip:EXPR (first time |EXPR| > pi), final:VAR, max:VAR (max |VAR|), or a status column " \
          "(failure_time, energy_drift, steps, cpu_time, ...)"


def add_parser(sub):
    from .simulate import _number_arg

    p = sub.add_parser("sweep", help=HELP, description=HELP)
    add_target_args(p, what="sweep")
    add_cache_arg(p)
    add_set_arg(p)
    p.add_argument("--grid", action="append", default=[], metavar="NAME=A:B:N",
                   help="sweep NAME over N values from A to B (or NAME=v1,v2,...); several --grid make a "
                        "Cartesian product; NAME a parameter, c.start or c.speed")
    p.add_argument("--uniform", action="append", default=[], metavar="NAME=LOW:HIGH",
                   help="Monte Carlo: NAME uniform in [LOW, HIGH) (with --samples)")
    p.add_argument("--normal", action="append", default=[], metavar="NAME=MEAN:SD",
                   help="Monte Carlo: NAME normal (with --samples)")
    p.add_argument("--sobol", action="append", default=[], metavar="NAME=LOW:HIGH",
                   help="quasi-random: NAME on scrambled Sobol' points in [LOW, HIGH) (with --samples; the "
                        "--sobol names jointly; balanced for a power of two)")
    p.add_argument("--latin-hypercube", action="append", default=[], metavar="NAME=LOW:HIGH",
                   help="NAME on a Latin hypercube in [LOW, HIGH) (with --samples; the --latin-hypercube names "
                        "jointly)")
    p.add_argument("--samples", type=int, metavar="N", help="Monte Carlo sample size")
    p.add_argument("--seed", type=int, default=0, metavar="S", help="sampling seed (default 0)")
    p.add_argument("--t-end", type=_number_arg, metavar="T", help="end time [s] (default: scene stop_time, else 10)")
    p.add_argument("--points", type=int, metavar="N", help="output points per run (default 501)")
    p.add_argument("--rtol", type=_number_arg, metavar="R", help="relative tolerance (default 1e-8)")
    p.add_argument("--atol", type=_number_arg, metavar="A", help="absolute tolerance (default 1e-10)")
    p.add_argument("--method", metavar="M", help="integration method (default auto, resolved once for the sweep)")
    p.add_argument("--scheduler", metavar="S",
                   help="vectorized, processes, dask (a local Dask cluster) or tcp://host:port (an existing "
                        "Dask scheduler); default: vectorized where it applies, else processes")
    p.add_argument("--workers", type=int, metavar="N", help="worker processes or threads (default: every core)")
    p.add_argument("-o", "--output", metavar="OUT", help="results: .nc (netCDF, streamed) or .csv (long table)")
    p.add_argument("--plot", metavar="PNG", help="heat map of --metric over the two --grid axes")
    p.add_argument("--metric", metavar="M", help=f"per-run value to plot: {METRICS}")
    p.add_argument("--error-estimate", choices=("off", "on"), default="off",
                   help="on: every run carries the error estimate of mech simulate (a companion run each; "
                        "the status column error_estimate); default off")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.add_argument("--resume", action="store_true",
                   help="continue the sweep -o holds (killed or interrupted): the runs it finished are kept, "
                        "after a check that model, settings and design are the same")
    add_force_arg(p)
    return p


def run(args) -> int:
    from ..output.fileio import check_figure, check_writable
    from ..sweep.spec import parse_range

    if args.output and not str(args.output).endswith((".nc", ".csv")):
        raise UsageError(f"-o {args.output}: the output must end in .nc or .csv")
    if args.resume and not args.output:
        raise UsageError("--resume continues the sweep an output file holds: give -o")
    if args.output:
        check_writable(args.output, overwrite=args.force or args.resume)
    if args.plot:
        check_figure(args.plot, overwrite=args.force)
        if not args.metric:
            raise UsageError(f"--plot needs --metric ({METRICS})")
    model, x0 = load_model(args, starts_in_model=False)
    unit_of = declared_units(model)
    grid = dict(parse_range(g, unit_of) for g in args.grid)
    params = grid or None
    sampler = _sampler(args, unit_of)
    if sampler is not None:
        if grid:
            raise UsageError("give either --grid or the samplers (--uniform, --normal, --sobol, --latin-hypercube), "
                             "not both")
        params = sampler
    elif args.samples is not None:
        raise UsageError("--samples needs --uniform, --normal, --sobol or --latin-hypercube")
    if params is None:
        raise UsageError("nothing to sweep: give --grid NAME=A:B:N (or a sampler such as --uniform with --samples)")
    if x0:
        raise UsageError("--set of start values is not available in a sweep: sweep them with --grid c.start=...")
    t_end = args.t_end
    if t_end is None and model.scene_settings.get("stop_time") is None:     # the layer's default end
        from ..simulation.settings import DEFAULT_T_END

        args.out.note(f"no --t-end and no scene stop_time: simulating {DEFAULT_T_END:g} s")
    ds = model.sweep(params=params, t_end=t_end, scheduler=args.scheduler, out=args.output, workers=args.workers,
                     progress=not (args.no_progress or args.out.quiet) and sys.stderr.isatty(), overwrite=True,
                     resume=args.resume, error_estimate=args.error_estimate,
                     rtol=args.rtol, atol=args.atol, method=args.method, points=args.points)
    written = [args.output] if args.output else []
    if args.output and args.output.endswith(".csv"):
        from ..output.result import sidecar_path

        written.append(sidecar_path(args.output))
    if args.plot:
        from ..sweep.plot import heat_map, metric

        written.append(str(heat_map(ds, metric(ds, args.metric), args.metric, args.plot)))
    print(summary(ds, written))
    out = args.out
    out.wrote(*written)
    out.set(**sweep_record(ds))
    if int(ds.attrs.get("n_warnings", 0)):
        out.warn(f"warnings in {ds.attrs['n_warnings']} runs; first: "
                 + str(ds.attrs.get("warnings", "")).splitlines()[0], echo=False)
    if int(ds.attrs["interrupted"]):
        print("mech: interrupted", file=sys.stderr)
        out.fail("interrupted", "interrupted: the finished runs are kept; the others are marked 'not run'")
        return 130
    if int(ds.attrs["n_failed"]):
        out.fail("simulation", f"{int(ds.attrs['n_failed'])} run(s) failed")
        return 1
    return 0


def sweep_record(ds) -> dict:
    """The sweep for ``--json`` (docs/json.md, "sweep"): its settings, counts and failures by cause."""
    import numpy as np

    a = ds.attrs
    ok = np.asarray(ds["success"].values, bool)
    causes: dict[str, int] = {}
    for c in np.asarray(ds["cause"].values)[~ok]:
        causes[str(c)] = causes.get(str(c), 0) + 1
    keep = ("model", "summary", "swept", "scheduler", "method", "method_note", "rtol", "atol", "t_start", "t_end",
            "wall_time",
            "n_runs", "n_failed", "n_warnings", "interrupted")
    rec = {k: a[k] for k in keep if k in a}
    rec.update(runs=int(ok.size), succeeded=int(ok.sum()), failed_by_cause=causes,
               interrupted=bool(int(a.get("interrupted", 0))))
    return rec


SAMPLERS = (("uniform", "uniform"), ("normal", "normal"), ("sobol", "sobol"), ("latin_hypercube", "latin_hypercube"))


def _sampler(args, unit_of):
    """The --uniform/--normal/--sobol/--latin-hypercube options as one sampler (or None)."""
    from .. import sample
    from ..numbers import in_declared_unit

    sampler = None
    for option, fn in SAMPLERS:
        texts = getattr(args, option)
        if not texts:
            continue
        if args.samples is None:
            raise UsageError(f"--{option.replace('_', '-')} needs --samples N")
        ranges = {}
        for text in texts:
            name, _, rhs = text.partition("=")
            parts = rhs.split(":")
            if len(parts) != 2 or not name.strip():
                raise UsageError(f"{text!r}: expected NAME=A:B")
            name = name.strip()     # a bare number means the parameter's declared unit (issue 23)
            ranges[name] = tuple(in_declared_unit(v.strip(), unit_of(name), text) for v in parts)
        # one call per option: the --sobol (or --latin-hypercube) names are drawn jointly
        s = getattr(sample, fn)(ranges, n=args.samples, seed=args.seed)
        sampler = s if sampler is None else sampler & s
    return sampler


def summary(ds, written=()) -> str:
    import numpy as np

    a = ds.attrs
    lines = [f"model {a['model']}: {a['summary']}",
             f"swept: {a['swept']}; scheduler {a['scheduler']}, method {a['method']}, rtol {a['rtol']:g}, "
             f"atol {a['atol']:g}, {a['wall_time']:.3g} s"]
    if a.get("method_note"):
        lines.append(f"method: {a['method_note']}")
    ok = np.asarray(ds["success"].values, bool)
    if (~ok).any():
        causes: dict[str, int] = {}
        for c in np.asarray(ds["cause"].values)[~ok]:
            causes[str(c)] = causes.get(str(c), 0) + 1
        lines.append("failed runs by cause: " + ", ".join(f"{c} ({k})" for c, k in sorted(causes.items())))
        first = int(np.flatnonzero(~ok)[0])
        ft = float(ds["failure_time"].values[first])
        lines.append(f"first failed run: {first} ({_values(ds, first)}): {ds['cause'].values[first]}"
                     + (f" at t = {ft:.6g}" if np.isfinite(ft) else "")
                     + (f" ({ds['detail'].values[first]})" if str(ds['detail'].values[first]) else ""))
    est = np.asarray(ds["error_estimate"].values, float) if "error_estimate" in ds else np.zeros(0)
    if np.isfinite(est).any():
        worst = int(np.nanargmax(est))
        lines.append(f"error estimate: largest {est[worst]:.2g} (run {worst}: {_values(ds, worst)}), in the "
                     "coordinates' units (the status column error_estimate)")
    if int(a.get("n_warnings", 0)):
        lines.append(f"warnings: {a['n_warnings']}; first: " + str(a.get("warnings", "")).splitlines()[0])
    if int(a.get("interrupted", 0)):
        lines.append("interrupted: the finished runs are kept; the others are marked 'not run' "
                     "(--resume continues the sweep)")
    for w in written:
        lines.append(f"wrote {w}")
    return "\n".join(lines)


def _values(ds, i: int) -> str:
    names = [n for n in str(ds.attrs.get("swept", "")).split(",") if n]
    return ", ".join(f"{n} = {float(ds[n].values[i]):.6g}" for n in names)


def declared_units(model):
    """name -> the unit a swept value is declared in (parameters; c.start, c.speed and der(c) of
    coordinates), so that ``30 deg`` on the command line becomes a number in that unit."""
    from ..model.names import split_state

    params = {p.name: p.unit for p in model.model.parameters}
    coords = {c.name: c.unit for c in model.model.coordinates}

    def unit_of(name: str):
        if name in params:
            return params[name]
        base, speed = split_state(name)
        for suffix, is_speed in ((".start", False), (".speed", True)):
            if name.endswith(suffix):
                base, speed = name[: -len(suffix)], is_speed
        unit = coords.get(base)
        if unit and speed:
            return f"{unit}/s" if "/" not in unit else f"({unit})/s"
        return unit
    return unit_of
