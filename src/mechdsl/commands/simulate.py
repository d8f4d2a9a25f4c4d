"""``mech simulate FILE``: integrate a model (or a scene) and write CSV, JSON and a plot."""
from __future__ import annotations

import sys

from ..diagnostics import UsageError
from ._common import add_set_arg, add_target_args, load_model, number, target_line

HELP = "simulate a model and write its results (CSV + JSON sidecar) and a plot"


def add_parser(sub):
    p = sub.add_parser("simulate", help=HELP, description=HELP)
    add_target_args(p, what="simulate")
    p.add_argument("--t-end", type=_number_arg, metavar="T", help="end time [s] (default: scene stop_time, else 10)")
    p.add_argument("--t-start", type=_number_arg, metavar="T0", help="start time [s] (default 0)")
    p.add_argument("--points", type=int, metavar="N", help="output points including both ends (default 501)")
    p.add_argument("--rtol", type=_number_arg, metavar="R", help="relative tolerance (default 1e-8)")
    p.add_argument("--atol", type=_number_arg, metavar="A", help="absolute tolerance (default 1e-10)")
    p.add_argument("--method", metavar="M", help="integration method (default auto; see docs/simulate.md)")
    p.add_argument("--dt", type=_number_arg, metavar="H", help="step size of the fixed-step methods")
    add_set_arg(p)
    p.add_argument("-o", "--output", metavar="OUT.csv", help="write the results as CSV (+ OUT.json sidecar)")
    p.add_argument("--plot", metavar="OUT.png", help="plot coordinates and energy (.png, .svg or .pdf)")
    p.add_argument("--compiled", action="store_true", help="generate C code and compile it (needs a C compiler)")
    p.add_argument("--no-progress", action="store_true", help="never show a progress bar")
    p.add_argument("--force", action="store_true", help="overwrite existing output files")
    return p


def run(args) -> int:
    from ..fileio import check_figure, check_writable
    from ..result import sidecar_path

    for path in (args.output, args.output and sidecar_path(args.output)):   # before any work is done
        if path:
            check_writable(path, overwrite=args.force)
    if args.plot:
        check_figure(args.plot, overwrite=args.force)
    model, x0 = load_model(args, starts_in_model=False)
    settings = model.scene_settings
    eom = model.eom
    t_end = args.t_end if args.t_end is not None else settings.get("stop_time")
    if t_end is None:
        t_end = 10.0
        print("mech: no --t-end and no scene stop_time: simulating 10 s", file=sys.stderr)
    tol = settings.get("tolerance")
    rtol = _first(args.rtol, settings.get("rtol"), tol, 1e-8)
    atol = _first(args.atol, settings.get("atol"), 1e-10)
    opts = {}
    if args.dt is not None or settings.get("dt") is not None:
        opts["dt"] = _first(args.dt, settings.get("dt"))
    if args.compiled:
        opts["compiled"] = True
    if eom.model is not None and eom.model.contacts:     # scene settings of contacts (docs/contacts.md)
        opts.update({k: settings[k] for k in ("rest_speed", "impact_order") if settings.get(k) is not None})
    from ..simulate import simulate

    progress = (not args.no_progress) and sys.stderr.isatty()
    r = simulate(eom, float(t_end), t_start=_first(args.t_start, settings.get("start_time"), 0.0),
                 rtol=rtol, atol=atol, method=_first(args.method, settings.get("method"), "auto"),
                 points=_first(args.points, settings.get("points")), outputs=settings.get("outputs"),
                 x0=x0 or None, p=model.parameter_values, progress=progress, **opts)
    r.metadata["source"] = str(args.file)
    r.source_model = model                       # units for the plot (mechdsl.plot.signal_units)
    r.metadata["target"] = target_line(args, model)
    if model.scene is not None:
        r.metadata["scene"] = model.scene.name
    written, lost = write_outputs(r, args.output, args.plot, args.force)
    print(summary(r, written))
    if r.events:
        from ..impacts import print_events

        print_events(r)
    for line in lost:
        print(f"mech: error: {line}", file=sys.stderr)
    return 0 if r.success and not lost else 1


def write_outputs(r, csv_path, plot_path, force) -> tuple[list[str], list[str]]:
    """Write the results; a file that cannot be written (a full disk, a folder made read-only
    during the run) is written to a fresh folder under the temporary directory instead, and
    said so, so a long run is never lost.  Returns (written paths, problems)."""
    import os
    import tempfile
    from pathlib import Path

    written: list[str] = []
    lost: list[str] = []
    rescue = None

    def attempt(write, path):
        nonlocal rescue
        try:
            return write(path, force)
        except OSError as e:
            if rescue is None:
                rescue = tempfile.mkdtemp(prefix="mechdsl-results-")
            alt = os.path.join(rescue, Path(path).name)
            lost.append(f"could not write {path} ({e.strerror or e}); wrote {alt} instead")
            return write(alt, True)

    if csv_path:
        written += attempt(lambda p, f: r.to_csv(p, overwrite=f), csv_path)
    if plot_path:
        from ..plot import plot_result

        written.append(str(attempt(lambda p, f: plot_result(r, p, overwrite=f), plot_path)))
    return written, lost


# --------------------------------------------------------------------------- pieces


def summary(r, written=()) -> str:
    m = r.metadata
    s = r.stats
    lines = [m["target"]] if m.get("target") else []
    if r.failure is not None and len(r.t) <= 1:
        t0 = r.t[0] if len(r.t) else m.get("options", {}).get("t_start", r.failure.time)
        lines.append(f"model {m.get('model', '?')}: no output point after the start t = {t0:g} was reached")
    else:
        lines.append(f"model {m.get('model', '?')}: t = {r.t[0]:g} .. {r.t[-1]:g} ({len(r.t)} points)")
    lines.append(f"method: {m.get('method', '?')} ({m.get('method_reason', '')})")
    parts = []
    for key, label in (("steps", "steps"), ("rhs_evals", "RHS evaluations"), ("jac_evals", "Jacobians")):
        if s.get(key) is not None:
            parts.append(f"{s[key]} {label}")
    if s.get("wall_time") is not None:
        parts.append(f"{s['wall_time']:.3g} s")
    if parts:
        lines.append("statistics: " + ", ".join(parts))
    if "energy_drift" in s:
        cons = m.get("conservative")
        kind = {True: "drift", False: "change (the model is not conservative)"}.get(cons, "change")
        lines.append(f"energy {kind}: max |E - E(0)| = {s['energy_drift']:.3g} "
                     f"(relative {s['energy_drift_relative']:.3g})")
    for w in m.get("warnings", []):
        lines.append(f"warning: {w}")
    for n in m.get("notes", []):
        lines.append(f"note: {n}")
    if r.failure is not None:
        f = r.failure
        lines.append(f"FAILED at t = {f.time:.10g}: {f.cause}" + (f" ({f.detail})" if f.detail else ""))
        if len(r.t):
            lines.append(f"results kept up to t = {r.t[-1]:.10g}; last good state there: " + _state_text(r))
        else:
            lines.append("no results to keep: the run failed at its start")
    for w in written:
        lines.append(f"wrote {w}")
    return "\n".join(lines)


def _state_text(r, limit: int = 8) -> str:
    if not len(r.t):
        return "none"
    pairs = [(c, r.q[-1, i]) for i, c in enumerate(r.coordinates)]
    pairs += [(f"der({c})", r.qd[-1, i]) for i, c in enumerate(r.coordinates)]
    text = ", ".join(f"{n} = {v:.6g}" for n, v in pairs[:limit])
    return text + (f", ... ({len(pairs) - limit} more in the CSV)" if len(pairs) > limit else "")


def _first(*vals):
    for v in vals:
        if v is not None:
            return v
    return None


def _number_arg(text: str) -> float:
    import argparse

    try:
        return number(text)
    except UsageError as e:
        raise argparse.ArgumentTypeError(str(e)) from None
