"""``mech simulate FILE``: integrate a model (or a scene) and write CSV, JSON and a plot."""
from __future__ import annotations

import os
import sys

from ..diagnostics import UsageError
from ..simulation.settings import DEFAULT_T_END
from ._common import add_cache_arg, add_set_arg, add_target_args, load_model, number, target_line

HELP = "simulate a model and write its results (CSV + JSON sidecar) and a plot"


def add_parser(sub):
    p = sub.add_parser("simulate", help=HELP, description=HELP)
    add_target_args(p, what="simulate")
    add_cache_arg(p)
    p.add_argument("--t-end", type=_number_arg, metavar="T", help="end time [s] (default: scene stop_time, else 10)")
    p.add_argument("--t-start", type=_number_arg, metavar="T0", help="start time [s] (default 0)")
    p.add_argument("--points", type=int, metavar="N", help="output points including both ends (default 501)")
    p.add_argument("--rtol", type=_number_arg, metavar="R", help="relative tolerance (default 1e-8)")
    p.add_argument("--atol", type=_number_arg, metavar="A", help="absolute tolerance (default 1e-10)")
    p.add_argument("--method", metavar="M", help="integration method (default auto; see docs/simulate.md)")
    p.add_argument("--dt", type=_number_arg, metavar="H", help="step size of the fixed-step methods")
    p.add_argument("--formulation", metavar="F",
                   help="constrained models: auto, projection, ggl, baumgarte or partitioning (docs/constraints.md)")
    p.add_argument("--reactions", action="store_true", help="constrained models: record every multiplier and reaction")
    p.add_argument("--output-events", action="store_true",
                   help="models with contacts: also record rows just before and just after every event")
    p.add_argument("--budget", type=int, metavar="N",
                   help="most output points a run may record (default 1000000; fixed steps: 10 N)")
    p.add_argument("--estimate-error", action="store_true",
                   help="run again at a 100 times tighter tolerance and report the difference per output")
    p.add_argument("--error-estimate", choices=("on", "off", "coordinates"), default=None,
                   help="the error estimate every run carries (default on: a companion run 10 times tighter on "
                        "a coarse grid, docs/simulate.md); off to skip it, coordinates for one per coordinate")
    add_set_arg(p)
    p.add_argument("--input", action="append", metavar="NAME=VALUE", dest="inputs",
                   help="drive an input: NAME=3.0 (constant) or NAME=file.csv (rows: time, value; "
                        "zero-order hold; NAME=file.csv:linear to interpolate); repeat for several")
    p.add_argument("-o", "--output", metavar="OUT.csv", help="write the results as CSV (+ OUT.json sidecar)")
    p.add_argument("--plot", metavar="OUT.png", help="plot coordinates and energy (.png, .svg or .pdf)")
    comp = p.add_mutually_exclusive_group()
    comp.add_argument("--compiled", action="store_true", help="generate C code and compile it (needs a C compiler)")
    comp.add_argument("--no-compile", action="store_true",
                      help="never compile automatically (method auto may otherwise pick the compiled dop853 loop)")
    p.add_argument("--no-progress", action="store_true", help="never show a progress bar")
    p.add_argument("--force", action="store_true", help="overwrite existing output files")
    return p


def run(args) -> int:
    from ..interrupts import held_interrupt
    from ..output.fileio import check_figure, check_writable
    from ..output.result import sidecar_path

    for path in (args.output, args.output and sidecar_path(args.output)):   # before any work is done
        if path:
            check_writable(path, overwrite=args.force)
    if args.plot:
        check_figure(args.plot, overwrite=args.force)
    progress = not (args.no_progress or args.out.quiet) and sys.stderr.isatty()
    warm = warm_key(args)       # (a prepared run took under 0.5 s: the bar, shown after 0.5 s, would not show)
    r = _replay(warm, args.out) if warm is not None else None
    interrupted = False
    if r is None:
        model, x0 = load_model(args, starts_in_model=False)
        t_end = args.t_end
        notes = []
        if t_end is None and model.scene_settings.get("stop_time") is None:     # the layer's default end
            notes.append(f"no --t-end and no scene stop_time: simulating {DEFAULT_T_END:g} s")
            args.out.note(notes[-1])
        # thin over mechdsl.Model: the settings resolve in Model.simulate exactly as for a Python
        # caller (argument > scene > default), so CLI and API give the same run for the same scene
        settings = dict(cli_settings(args), x0=x0 or None)
        try:
            r = model.simulate(t_end, **settings, progress=progress)
        except KeyboardInterrupt as e:
            # Ctrl-C: a back end that kept its results up to there (mechdsl.dae.RunInterrupted)
            # hands them over; they are written like a failed run's, and the exit code is 130
            r = getattr(e, "result", None)
            if r is None:
                raise
            interrupted = True
        r.metadata["source"] = str(args.file)
        r.metadata["target"] = target_line(args, model)
        if model.scene is not None:
            r.metadata["scene"] = model.scene.name
        if warm is not None and not interrupted:
            _prepare_warm(warm, model, t_end, settings, r, notes)
    with held_interrupt() as held:          # a Ctrl-C now waits for the files to be written
        written, lost = write_outputs(r, args.output, args.plot, args.force)
    if held.seen and not interrupted:
        r.metadata["interrupted_during"] = "the writing of the results (all written)"
        interrupted = True
    print(summary(r, written))
    if r.events:
        from ..impacts import events_table

        sys.stdout.write(events_table(r.events))
    out = args.out
    out.set(**run_record(r))
    out.wrote(*written)
    for w in r.metadata.get("warnings", []):
        out.warn(w, echo=False)                   # (the summary above shows them)
    for line in lost:
        print(f"mech: error: {line}", file=sys.stderr)
        out.fail("output", line)
    if interrupted:
        print("mech: interrupted", file=sys.stderr)
        during = r.metadata.get("interrupted_during")
        out.fail("interrupted", f"interrupted during {during}" if during else
                 f"interrupted at t = {r.t[-1]:.10g}" if len(r.t) else "interrupted")
        return 130
    if r.failure is not None:
        out.fail("simulation", str(r.failure))
    return 0 if r.success and not lost else 1


# --------------------------------------------------------------------------- prepared warm runs
# (simulation/warm_run.py): a second run of the same command neither loads the model nor imports CasADi

OUTPUT_ONLY = {"output", "plot", "force", "no_progress", "json", "quiet", "verbose", "out", "_run", "_where",
               "command"}


def warm_key(args) -> tuple | None:
    """(key, text) of this command's prepared warm run, or None when it cannot have one (inputs,
    --estimate-error, --plot, --no-cache, an option that is not plain data)."""
    if args.inputs or args.estimate_error or args.plot or getattr(args, "no_cache", False):
        return None
    opts = []
    for k, v in sorted(vars(args).items()):
        if k in OUTPUT_ONLY:
            continue
        if not _plain(v):
            return None
        opts.append((k, v))
    try:
        with open(args.file, "rb") as fh:
            text = fh.read()
    except OSError:
        return None              # (the normal path says why)
    from ..simulation import warm_run

    return warm_run.key(str(args.file), text, tuple(opts)), str(args.file)


def _plain(v) -> bool:
    if v is None or isinstance(v, (str, int, float, bool)):
        return True
    return isinstance(v, (list, tuple)) and all(_plain(x) for x in v)


def _replay(warm, out):
    """The prepared run's Result (None: the normal path runs), the command's notes said as the
    normal path says them."""
    from ..simulation import warm_run

    data = warm_run.read(warm[0])
    if data is None:
        return None
    r = warm_run.replay(data)
    if r is not None:
        r.metadata.update(data["command"])
        for note in data.get("command_notes", ()):
            out.note(note)
    return r


def _prepare_warm(warm, model, t_end, settings, r, notes=()) -> None:
    """Store the prepared warm run of this command (simulation/warm_capture.py), if it can have one."""
    from ..numbers import si_unit
    from ..simulation import warm_capture, warm_run

    ir = model.model
    units = {"coordinates": {c.name: c.unit for c in ir.coordinates}, "outputs": {o.name: o.unit for o in ir.outputs},
             "si": {c.name: si_unit(c.unit) for c in ir.coordinates}}
    data, _why = warm_capture.payload(model.prepared_run(t_end, **settings), r, units)
    if data is not None:
        data["command"] = {k: r.metadata[k] for k in ("source", "target", "scene") if k in r.metadata}
        data["command_notes"] = list(notes)
        warm_run.write(warm[0], data)


def run_record(r) -> dict:
    """The run for ``--json`` (docs/json.md, "simulate"): what ran, its statistics, its accuracy."""
    m = r.metadata
    accuracy = dict(m.get("accuracy") or {})
    for key in ("energy_drift", "energy_drift_relative", "constraint_drift", "invariant_drift"):
        if r.stats.get(key) is not None:
            accuracy[key] = r.stats[key]
    if m.get("error_estimate"):               # the thorough check (--estimate-error), beside the default one
        accuracy["estimate_error"] = m["error_estimate"]
    return {"target": m.get("target"), "model": m.get("model"), "scene": m.get("scene"),
            "source": m.get("source"), "success": bool(r.success),
            "failure": None if r.failure is None else {"time": r.failure.time, "cause": r.failure.cause,
                                                       "detail": r.failure.detail},
            "t_start": float(r.t[0]) if len(r.t) else None, "t_end": float(r.t[-1]) if len(r.t) else None,
            "points": int(len(r.t)), "method": m.get("method"), "method_reason": m.get("method_reason"),
            "run": m.get("run") or {}, "statistics": dict(r.stats), "accuracy": accuracy,
            "notes": list(m.get("notes", [])), "columns": list(r.columns), "units": r.column_units(),
            "events": list(r.events)}


def cli_settings(args) -> dict:
    """The simulation settings given on the command line (None: not given)."""
    return {"t_start": args.t_start, "rtol": args.rtol, "atol": args.atol, "method": args.method,
            "points": args.points, "dt": args.dt, "formulation": args.formulation,
            "compiled": True if args.compiled else (False if getattr(args, "no_compile", False) else None),
            "reactions": True if args.reactions else None,
            "budget": args.budget, "estimate_error": True if args.estimate_error else None,
            "error_estimate": getattr(args, "error_estimate", None),
            "warn": False,                      # the summary prints each warning once
            "output_events": True if getattr(args, "output_events", False) else None,
            "inputs": parse_inputs(getattr(args, "inputs", None))}


def parse_inputs(items) -> dict | None:
    """``--input NAME=VALUE`` options -> {name: number | Table} (None: none given)."""
    if not items:
        return None
    from ..diagnostics import UsageError
    from ..simulation.drive import read_table

    out: dict = {}
    for item in items:
        name, sep, value = item.partition("=")
        name, value = name.strip(), value.strip()
        if not sep or not name or not value:
            raise UsageError(f"--input {item!r}: write NAME=VALUE (a number or a CSV file of time, value rows)")
        if name in out:
            raise UsageError(f"--input {name} is given twice")
        try:
            out[name] = float(value)
        except ValueError:
            path, hold = value, "zoh"
            for h in ("linear", "zoh"):
                if value.endswith(":" + h):
                    path, hold = value[: -len(h) - 1], h
            head, colon, tail = value.rpartition(":")
            if colon and hold == "zoh" and tail.isalpha() and not os.path.exists(value) and os.path.exists(head):
                raise UsageError(f"--input {name}: unknown hold ':{tail}' after {head} (use :zoh or :linear)")
            out[name] = read_table(path, hold, what=f"--input {name}")
    return out


def write_outputs(r, csv_path, plot_path, force) -> tuple[list[str], list[str]]:
    """Write the results; a file that cannot be written (a full disk, a folder made read-only
    during the run) is written to a fresh folder under the temporary directory instead, and
    said so, so a long run is never lost.  Returns (written paths, problems)."""
    import os
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
                import tempfile      # (tempfile and shutil: 3-20 ms to import; only on a failed write)

                rescue = tempfile.mkdtemp(prefix="mechdsl-results-")
            alt = os.path.join(rescue, Path(path).name)
            lost.append(f"could not write {path} ({e.strerror or e}); wrote {alt} instead")
            return write(alt, True)

    if csv_path:
        written += attempt(lambda p, f: r.to_csv(p, overwrite=f), csv_path)
    if plot_path:
        from ..output.plot import plot_result

        written.append(str(attempt(lambda p, f: plot_result(r, p, overwrite=f), plot_path)))
    return written, lost


# --------------------------------------------------------------------------- pieces


def summary(r, written=()) -> str:
    m = r.metadata
    s = r.stats
    lines = [m["target"]] if m.get("target") else []
    if r.failure is not None and len(r.t) <= 1:
        t0 = r.t[0] if len(r.t) else m.get("options", {}).get("t_start", r.failure.time)
        lines.append(f"model {m.get('model', '?')}: no output point after the start t = {t0:g} s was reached")
    else:
        lines.append(f"model {m.get('model', '?')}: t = {r.t[0]:g} .. {r.t[-1]:g} s ({len(r.t)} point{'s' * (len(r.t) != 1)})")
    lines.append(f"method: {m.get('method', '?')} ({m.get('method_reason', '')})")
    ran = m.get("run") or {}
    if ran:
        dt = ((ran.get("settings") or {}).get("fixed_step") or {}).get("dt")
        # a fixed-step method takes no tolerances: its step is what sets the accuracy
        accuracy = (f"step dt {dt:g} s" if ran.get("backend") == "fixed-step" and dt is not None
                    else f"rtol {ran.get('rtol'):g}, atol {ran.get('atol'):g}")
        lines.append(f"ran: {ran.get('problem')} problem, formulation {ran.get('formulation')}, integrator "
                     f"{ran.get('integrator')}, {accuracy}" + (", compiled" if ran.get("compiled") else ""))
    parts = []
    for key, label in (("steps", "steps"), ("rhs_evals", "RHS evaluations"), ("jac_evals", "Jacobians"),
                       ("rejected_steps", "rejected steps"), ("events", "events")):
        if s.get(key) is not None:
            parts.append(f"{s[key]} {label}")
    if s.get("cpu_time") is not None:
        parts.append(f"{s['cpu_time']:.3g} s CPU")
    if s.get("wall_time") is not None:
        parts.append(f"{s['wall_time']:.3g} s wall")
    if parts:
        lines.append("statistics: " + ", ".join(parts))
    if s.get("energy_drift") is not None:
        cons = m.get("conservative")
        kind = {True: "drift", False: "change (the model is not conservative)"}.get(cons, "change")
        unit = r.column_units().get("energy", "")
        lines.append(f"energy {kind}: max |E - E(0)| = {s['energy_drift']:.3g}{' ' + unit if unit else ''} "
                     f"(relative {s['energy_drift_relative']:.3g})")
    inv = {k: v for k, v in (s.get("invariant_drift") or {}).items() if k != "energy"}
    if inv:
        lines.append("invariant drift: " + ", ".join(f"{k} {v:.3g}" for k, v in inv.items()))
    if s.get("constraint_drift") is not None:
        lines.append(f"constraint drift: max ||g|| = {s['constraint_drift']:.3g}")
    lines += accuracy_lines(m.get("accuracy") or {})
    est = m.get("error_estimate")
    if est and est.get("unavailable"):
        lines.append(f"error estimate unavailable: {est['unavailable']}")
    elif est:
        lines.append(f"error estimate (max difference to a run at {est['reference']}):")
        for k, v in est["max_abs_difference"].items():
            lines.append(f"  {k}: {v:.3g}")
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


def accuracy_lines(acc: dict) -> list[str]:
    """The error estimate on the summary: the largest over the coordinates, where, and its ratio to
    the tolerance class (per coordinate with --error-estimate coordinates)."""
    if acc.get("error_estimate") is None:
        why = acc.get("error_estimate_unavailable")
        return [f"error estimate: none ({why})"] if why and not why.startswith("turned off") else []
    unit = f" {acc['error_estimate_unit']}" if acc.get("error_estimate_unit") else ""
    line = (f"error estimate: {acc['error_estimate']:.2g}{unit} (largest over the coordinates: "
            f"{acc['error_estimate_coordinate']} at t = {acc['error_estimate_time']:.6g}; "
            f"{acc['error_estimate_ratio']:.2g} x its tolerance class rtol |q|max + atol), from "
            f"{acc.get('error_estimate_method', 'a companion run')}")
    out = [line]
    if acc.get("error_estimate_note"):
        out.append(f"  note: {acc['error_estimate_note']}")
    for c, v in (acc.get("error_estimate_by_coordinate") or {}).items():
        out.append(f"  {c}: {v:.3g} ({v / acc['tolerance_class'][c]:.2g} x tolerance class)")
    return out


def _state_text(r, limit: int = 8) -> str:
    if not len(r.t):
        return "none"
    pairs = [(c, r.q[-1, i]) for i, c in enumerate(r.coordinates)]
    pairs += [(f"der({c})", r.qd[-1, i]) for i, c in enumerate(r.coordinates)]
    text = ", ".join(f"{n} = {v:.6g}" for n, v in pairs[:limit])
    return text + (f", ... ({len(pairs) - limit} more in the CSV)" if len(pairs) > limit else "")


def _number_arg(text: str) -> float:
    import argparse

    try:
        return number(text)
    except UsageError as e:
        raise argparse.ArgumentTypeError(str(e)) from None
