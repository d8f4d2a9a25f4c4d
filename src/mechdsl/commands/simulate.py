"""``mech simulate FILE``: integrate a model (or a scene) and write CSV, JSON and a plot."""
from __future__ import annotations

import ast
import math
import operator
import sys

from ..diagnostics import UsageError, did_you_mean

HELP = "simulate a model and write its results (CSV + JSON sidecar) and a plot"


def add_parser(sub):
    p = sub.add_parser("simulate", help=HELP, description=HELP)
    p.add_argument("file", metavar="FILE", help=".mech file")
    g = p.add_mutually_exclusive_group()
    g.add_argument("--model", metavar="M", help="model to simulate (default: the file's main model)")
    g.add_argument("--scene", metavar="S", help="scene to run (model, overrides and settings)")
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
    p.add_argument("--budget", type=int, metavar="N",
                   help="most output points and fixed steps a run may take (default 10000000)")
    p.add_argument("--estimate-error", action="store_true",
                   help="run again at a 100 times tighter tolerance and report the difference per output")
    p.add_argument("--set", action="append", default=[], metavar="NAME=VALUE",
                   help="override a parameter (m=2) or a start value (theta.start=pi/4, theta.speed=0)")
    p.add_argument("-o", "--output", metavar="OUT.csv", help="write the results as CSV (+ OUT.json sidecar)")
    p.add_argument("--plot", metavar="OUT.png", help="plot coordinates and energy (.png, .svg or .pdf)")
    p.add_argument("--compiled", action="store_true", help="generate C code and compile it (needs a C compiler)")
    p.add_argument("--no-progress", action="store_true", help="never show a progress bar")
    p.add_argument("--force", action="store_true", help="overwrite existing output files")
    return p


def run(args) -> int:
    """Parse, call mechdsl.Model, print and write: the settings resolve in Model.simulate
    exactly as for a Python caller (argument > scene > default)."""
    from ..api import load
    from ..fileio import check_writable

    params, starts = parse_sets(args.set)
    for path in (args.output, _sidecar(args.output), args.plot):
        if path:
            check_writable(path, overwrite=args.force)
    model = load(args.file, model=args.model, scene=args.scene)
    model = model.with_params(**params) if params else model
    x0 = _start_overrides(model.eom, starts)
    t_end = args.t_end
    if t_end is None and model.scene_settings.get("stop_time") is None:
        t_end = 10.0
        print("mech: no --t-end and no scene stop_time: simulating 10 s", file=sys.stderr)
    r = model.simulate(t_end, **cli_settings(args), x0=x0 or None,
                       progress=(not args.no_progress) and sys.stderr.isatty())
    r.metadata["source"] = str(args.file)
    if args.scene:
        r.metadata["scene"] = args.scene
    written = []
    if args.output:
        r.to_csv(args.output, overwrite=args.force)
        written += [args.output, _sidecar(args.output)]
    if args.plot:
        from ..plot import plot_result

        plot_result(r, args.plot, overwrite=args.force)
        written.append(args.plot)
    print(summary(r, written))
    if r.events:
        from ..impacts import print_events

        print_events(r)
    return 0 if r.success else 1


def cli_settings(args) -> dict:
    """The simulation settings given on the command line (None: not given)."""
    return {"t_start": args.t_start, "rtol": args.rtol, "atol": args.atol, "method": args.method,
            "points": args.points, "dt": args.dt, "formulation": args.formulation,
            "compiled": True if args.compiled else None, "reactions": True if args.reactions else None,
            "budget": args.budget, "estimate_error": True if args.estimate_error else None}


# --------------------------------------------------------------------------- pieces


def summary(r, written=()) -> str:
    m = r.metadata
    s = r.stats
    lines = [f"model {m.get('model', '?')}: t = {r.t[0]:g} .. {r.t[-1]:g} ({len(r.t)} points)"]
    lines.append(f"method: {m.get('method', '?')} ({m.get('method_reason', '')})")
    ran = m.get("run") or {}
    if ran:
        lines.append(f"ran: {ran.get('problem')} problem, formulation {ran.get('formulation')}, integrator "
                     f"{ran.get('integrator')}, rtol {ran.get('rtol'):g}, atol {ran.get('atol'):g}"
                     + (", compiled" if ran.get("compiled") else ""))
    parts = []
    for key, label in (("steps", "steps"), ("rhs_evals", "RHS evaluations"), ("jac_evals", "Jacobians"),
                       ("rejected_steps", "rejected steps"), ("events", "events")):
        if s.get(key) is not None:
            parts.append(f"{s[key]} {label}")
    if s.get("cpu_time") is not None:
        parts.append(f"{s['cpu_time']:.3g} s CPU")
    if s.get("wall_time") is not None:
        parts.append(f"{s['wall_time']:.3g} s")
    if parts:
        lines.append("statistics: " + ", ".join(parts))
    if s.get("energy_drift") is not None:
        cons = m.get("conservative")
        kind = {True: "drift", False: "change (the model is not conservative)"}.get(cons, "change")
        lines.append(f"energy {kind}: max |E - E(0)| = {s['energy_drift']:.3g} "
                     f"(relative {s['energy_drift_relative']:.3g})")
    inv = {k: v for k, v in (s.get("invariant_drift") or {}).items() if k != "energy"}
    if inv:
        lines.append("invariant drift: " + ", ".join(f"{k} {v:.3g}" for k, v in inv.items()))
    if s.get("constraint_drift") is not None:
        lines.append(f"constraint drift: max ||g|| = {s['constraint_drift']:.3g}")
    est = m.get("error_estimate")
    if est:
        diffs = est["max_abs_difference"]
        lines.append(f"error estimate (difference to a run at {est['reference']}):")
        for k, v in diffs.items():
            lines.append(f"  {k}: {v:.3g}")
    for w in m.get("warnings", []):
        lines.append(f"warning: {w}")
    for n in m.get("notes", []):
        lines.append(f"note: {n}")
    if r.failure is not None:
        f = r.failure
        lines.append(f"FAILED at t = {f.time:.10g}: {f.cause}" + (f" ({f.detail})" if f.detail else ""))
        lines.append(f"results kept up to t = {r.t[-1]:.10g}")
    for w in written:
        lines.append(f"wrote {w}")
    return "\n".join(lines)


def _sidecar(path):
    if not path:
        return None
    return path[:-4] + ".json" if path.endswith(".csv") else path + ".json"


def parse_sets(items) -> tuple[dict[str, float], dict[str, float]]:
    """NAME=VALUE pairs -> (parameters, start values); start keys are 'c' or 'der(c)'."""
    params: dict[str, float] = {}
    starts: dict[str, float] = {}
    for item in items:
        if "=" not in item:
            raise UsageError(f"--set expects NAME=VALUE (got {item!r})")
        name, text = (s.strip() for s in item.split("=", 1))
        value = eval_number(text, what=f"--set {name}")
        if name.endswith(".start"):
            starts[name[: -len(".start")]] = value
        elif name.endswith(".speed"):
            starts[f"der({name[: -len('.speed')]})"] = value
        elif not name:
            raise UsageError(f"--set expects NAME=VALUE (got {item!r})")
        else:
            params[name] = value
    return params, starts


def _start_overrides(eom, starts):
    out = {}
    for key, v in starts.items():
        name = key[4:-1] if key.startswith("der(") else key
        if name not in eom.coords:
            hint = did_you_mean(name, eom.coords)
            raise UsageError(f"--set {name}.start/.speed: '{name}' is not a coordinate of {eom.name}"
                             + (f"; {hint}" if hint else f" (coordinates: {', '.join(eom.coords)})"))
        out[key] = v
    return out


_OPS = {ast.Add: operator.add, ast.Sub: operator.sub, ast.Mult: operator.mul, ast.Div: operator.truediv,
        ast.Pow: operator.pow, ast.USub: operator.neg, ast.UAdd: operator.pos}
_NAMES = {"pi": math.pi, "e": math.e, "inf": math.inf}
_FUNCS = {"sin": math.sin, "cos": math.cos, "tan": math.tan, "sqrt": math.sqrt, "exp": math.exp,
          "log": math.log, "deg": math.radians}


def eval_number(text: str, what: str = "value") -> float:
    """A number or a small arithmetic expression: 1.5, 2e-3, pi/4, 2*pi, deg(30), sqrt(2)."""
    try:
        tree = ast.parse(text.replace("^", "**"), mode="eval")
        return float(_ev(tree.body))
    except (SyntaxError, ValueError, TypeError, ZeroDivisionError, OverflowError, KeyError):
        raise UsageError(f"{what}: cannot read {text!r} as a number "
                         "(use e.g. 1.5, 2e-3, pi/4, deg(30))") from None


def _ev(n):
    if isinstance(n, ast.Constant) and isinstance(n.value, (int, float)) and not isinstance(n.value, bool):
        return n.value
    if isinstance(n, ast.BinOp) and type(n.op) in _OPS:
        return _OPS[type(n.op)](_ev(n.left), _ev(n.right))
    if isinstance(n, ast.UnaryOp) and type(n.op) in _OPS:
        return _OPS[type(n.op)](_ev(n.operand))
    if isinstance(n, ast.Name):
        return _NAMES[n.id]
    if isinstance(n, ast.Call) and isinstance(n.func, ast.Name) and n.func.id in _FUNCS and len(n.args) == 1 \
            and not n.keywords:
        return _FUNCS[n.func.id](_ev(n.args[0]))
    raise ValueError("not an arithmetic expression")


def _number_arg(text: str) -> float:
    import argparse

    try:
        return eval_number(text)
    except UsageError as e:
        raise argparse.ArgumentTypeError(str(e)) from None


def _apply_params(model, params):
    """(model with the parameters set, {}) (kept for commands/bench.py)."""
    return (model.with_params(**params) if params else model), {}
