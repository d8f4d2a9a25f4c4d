"""``mech linearize FILE``: the linear model M, C, K (A, B) about an equilibrium or a state,
and its modes (frequencies in rad/s and Hz, damping ratios, shapes); JSON, CSV and a plot."""
from __future__ import annotations

import re

from ..model.names import split_state
from ._common import (
    add_cache_arg,
    add_force_arg,
    add_guess_arg,
    add_set_arg,
    add_target_args,
    assignments,
    load_model,
    target_line,
)


def add_parser(sub):
    p = sub.add_parser("linearize", help="linear model and modes about an equilibrium or a state",
                       description="Linearize the equations of motion: M dq'' + C dq' + K dq = B du; print "
                                   "M, C, K, the first-order A (and B for inputs) and the modes.")
    add_target_args(p, what="analyse")
    add_cache_arg(p)
    p.add_argument("--at", default="equilibrium",
                   help="'equilibrium' (nearest to the start values; steer with --guess), 't=T' (the state "
                        "reached at time T from the start values), 'start', or NAME=VALUE,... (a state; "
                        "der(NAME)=V for speeds)")
    add_guess_arg(p, "starting guess for --at equilibrium, e.g. theta=1.1 or x=1,phi=0.5 (the equilibrium "
                     "nearest to it is linearized)")
    p.add_argument("--inputs", nargs="+", metavar="NAME",
                   help="parameters (or coordinates: a generalized force on them) treated as inputs u; "
                        "default: the model's `input` parameters")
    add_set_arg(p)
    p.add_argument("--symbolic", action="store_true", help="also print M, C, K derived exactly by sympy")
    p.add_argument("-o", "--output", metavar="OUT.json", help="write the linear model and modes as JSON")
    p.add_argument("--csv", metavar="OUT.csv", help="write the modes as CSV")
    p.add_argument("--plot", metavar="OUT.png", help="draw the mode shapes")
    p.add_argument("--no-units", action="store_true", help="skip dimensional analysis")
    add_force_arg(p)
    return p


def run(args) -> int:
    from ..analysis.linearize import linearize
    from ..model.units import si_unit
    from ..output.fileio import check_figure, check_writable, write_atomic

    for out in (args.output, args.csv):
        if out:
            check_writable(out, args.force)
    if args.plot:
        check_figure(args.plot, args.force)
    m = load_model(args)
    print(target_line(args, m))
    at = args.at.strip()
    if "=" in at and not re.fullmatch(r"t\s*=.*", at):
        at = _state(at)
    guesses = [assignments([g], "--guess") for g in args.guess] or None
    inputs = None
    if args.inputs:
        inputs = [s for item in args.inputs for s in item.split(",") if s.strip()]
    lin = linearize(m.eom, at=at, inputs=inputs, guesses=guesses)
    print(format_linearization(m.name, lin, units={c.name: si_unit(c.unit) for c in m.model.coordinates if c.unit}))
    out = args.out
    out.set(target=target_line(args, m), model=m.name, **lin.to_dict())
    if args.symbolic:
        print(format_symbolic(lin))
    for path, write in ((args.output, lambda p: write_atomic(p, lin.to_json(), overwrite=args.force)),
                        (args.csv, lambda p: lin.modes().write_csv(p, overwrite=args.force)),
                        (args.plot, lambda p: lin.modes().plot(p, title=f"{m.name}: mode shapes",
                                                               overwrite=args.force))):
        if path:
            write(path)
            print(f"wrote {path}")
            out.wrote(path)
    return 0


def _state(text: str) -> dict:
    return assignments([text], "--at")


def format_linearization(name: str, lin, units=None) -> str:
    """The text of `mech linearize`; ``units``: each coordinate's unit (values, matrices)."""
    from ..analysis.tables import matrix, num, table
    from ..model.units import matrix_units

    units = units or {}

    def val(k, v, per_s=""):
        u = units.get(k, "")
        return f"{num(v)} {u}{per_s}" if u else num(v)

    c = list(lin.matrix_coords)
    mu = matrix_units([units.get(k, "") for k in c])
    where = {"equilibrium": "about the equilibrium", "accelerated-reference":
             "about the relative equilibrium of the accelerated reference motion",
             "state": f"about the state at t = {num(lin.t)} s"}[lin.kind]
    lines = [f"{name}: linear model {where}",
             "  " + ", ".join(f"{k} = {val(k, v)}" for k, v in lin.values.items())
             + ("" if not any(lin.qd) else "; " + ", ".join(f"der({k}) = {val(k, v, '/s')}"
                                                            for k, v in zip(c, lin.qd)))]
    if lin.multipliers is not None:
        units = lin.lambda_units
        lines.append("  constraint multipliers: " + ", ".join(
            f"lambda[{k}] = {num(lin.lambdas[k])}" + (f" {units[k]}" if units.get(k) else "")
            for k in lin.active_constraints))
        lines.append(f"  on the constraint manifold: {len(c)} independent coordinate(s) dz = ({', '.join(c)}), "
                     "dq = Z dz; K includes the geometric stiffness sum lambda_l d2g_l/dq2")
    elif lin.constrained:
        lines.append(f"  in {len(c)} coordinate(s) dz = ({', '.join(c)}) of the tangent space, dq = Z dz")
    if lin.constrained:
        lines.append(matrix("Z (basis of the tangent space)", lin.basis, list(lin.coords), c))
    if lin.equilibrium is not None:
        lines.append(f"  stability: {lin.equilibrium.stability} ({lin.equilibrium.reason})")
    for note in lin.notes:
        lines.append(f"  note: {note}")
    lines.append("  M dq'' + C dq' + K dq = B du")
    if units and not mu:
        lines.append("  units: the coordinates' units differ, so each entry has its own: M[i,j] in "
                     "J.s2/(unit_i.unit_j), C[i,j] in J.s/(unit_i.unit_j), K[i,j] in J/(unit_i.unit_j)")
    lines.append(matrix("M (mass)" + (f" [{mu['M']}]" if mu else ""), lin.M, c, c))
    lines.append(matrix("C (damping + gyroscopic)" + (f" [{mu['C']}]" if mu else ""), lin.C, c, c))
    lines.append(matrix("K (stiffness)" + (f" [{mu['K']}]" if mu else ""), lin.K, c, c))
    if lin.inputs:
        lines.append(matrix("B (second order, per input)", lin.Bq, c, lin.inputs))
    x = c + [f"der({k})" for k in c]
    if len(x) <= 12:
        lines.append(matrix("A (first order, x = (dq, dq'))", lin.A, x, x))
        if lin.inputs:
            lines.append(matrix("B (first order)", lin.B, x, lin.inputs))
    md = lin.modes()
    rows = []
    for j in range(len(md)):
        s = md.shapes[:, j]
        rows.append([str(j + 1), md.kinds[j], num(md.frequencies[j]), num(md.hz[j]), num(md.damping_ratios[j]),
                     num(md.mode_eigenvalues[j])] + [num(v) for v in s])
    lines.append("  modes:" + (" (shapes in the original coordinates)" if lin.constrained else ""))
    lines.append(table(["mode", "kind", "w (rad/s)", "f (Hz)", "zeta", "eigenvalue (1/s)"] + list(md.coords), rows, "    "))
    return "\n".join(lines)


def format_symbolic(lin) -> str:
    from ..analysis.symbolic import text

    s = lin.symbolic()
    out = [f"  symbolic (sympy, from T, V, D, Q via the {s.route} route), at "
           + ", ".join(f"{k} = {text(v)}" for k, v in s.state.items() if not split_state(str(k))[1]
                       and str(k) != "time")]
    for name, Mx in (("M", s.M), ("C", s.C), ("K", s.K)):
        out.append(f"    {name} = [" + "; ".join(", ".join(text(Mx[i, j]) for j in range(Mx.shape[1]))
                                          for i in range(Mx.shape[0])) + "]")
    return "\n".join(out)
