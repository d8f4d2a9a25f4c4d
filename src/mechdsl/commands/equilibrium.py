"""``mech equilibrium FILE``: equilibria (static, relative, about an accelerated reference)
with their stability, as a table; ``-o OUT.json`` writes them."""
from __future__ import annotations

import json

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
    p = sub.add_parser("equilibrium", help="find equilibria and classify their stability",
                       description="Find the equilibria of a model from several starting guesses (yours and a "
                                   "spread over each coordinate's range) and classify each: stable "
                                   "(Lagrange-Dirichlet), unstable, or undetermined, with the eigenvalues "
                                   "that decide.")
    add_target_args(p, what="analyse")
    add_cache_arg(p)
    add_guess_arg(p, "a starting guess, e.g. theta=pi/2 or x=1,phi=0.5 (coordinates not named keep "
                     "their start values); repeat --guess for several guesses")
    add_set_arg(p)
    p.add_argument("--time", type=float, default=0.0, help="time at which to evaluate time-dependent models")
    p.add_argument("--steady", action="append", default=[], metavar="PIN=VALUE",
                   help="steady motions instead (ignorable coordinates turning at constant speed, the others at "
                        "rest), one pin per ignorable coordinate: a coordinate (tip.theta=0.6), an ignorable "
                        "speed (der(tip.psi)=20) or momentum (p_tip.psi=4); docs/analysis.md#steady-motions"),
    p.add_argument("-o", "--output", metavar="OUT.json", help="write the equilibria as JSON")
    p.add_argument("--no-units", action="store_true", help="skip dimensional analysis")
    add_force_arg(p)
    return p


def run(args) -> int:
    from ..analysis.equilibrium import equilibria
    from ..model.units import matrix_units
    from ..output.fileio import check_writable, write_atomic

    if args.output:
        check_writable(args.output, args.force)
    m = load_model(args)
    print(target_line(args, m))
    guesses = [assignments([g], "--guess") for g in args.guess]
    if args.steady:
        return _steady(args, m, guesses)
    eqs = equilibria(m.eom, guesses or None, t=args.time)
    units = _si_units(m)
    print(format_equilibria(m.name, m.eom.coords, eqs, units))
    data = {"model": m.name, "coordinates": list(m.eom.coords), "count": len(eqs),
            "units": {c: units.get(c, "") for c in m.eom.coords},
            "hessian_unit": matrix_units([units.get(c, "") for c in m.eom.coords]).get("K", ""),
            "equilibria": [e.to_dict() for e in eqs]}
    args.out.set(target=target_line(args, m), **data)
    if args.output:
        write_atomic(args.output, json.dumps({"generator": "mechdsl", **data}, indent=2) + "\n",
                     overwrite=args.force)
        print(f"wrote {args.output}")
        args.out.wrote(args.output)
    return 0


def _steady(args, m, guesses) -> int:
    from ..analysis.steady import steady_motions
    from ..output.fileio import write_atomic

    pins = assignments(args.steady, "--steady")
    found = steady_motions(m.eom, pins, guesses=guesses or None, t=args.time)
    units = _si_units(m)
    print(format_steady(m.name, pins, found, units))
    cols, ku = steady_units(found, units)
    data = {"model": m.name, "pins": pins, "count": len(found), "steady_motions": [s.to_dict() for s in found],
            "units": cols, "hessian_unit": ku}
    args.out.set(target=target_line(args, m), **data)
    if args.output:
        write_atomic(args.output, json.dumps({"generator": "mechdsl", **data}, indent=2) + "\n",
                     overwrite=args.force)
        print(f"wrote {args.output}")
        args.out.wrote(args.output)
    return 0


def steady_units(found, units: dict) -> tuple[dict, str]:
    """({column: unit} for the steady-motion columns, the Hessian of V_R's unit): coordinates in
    their SI unit, speeds der(s) in unit/s, momenta p_s (dT/ds') in J.s/unit, V_R'' in J/unit^2."""
    from ..model.units import matrix_units, motion_units

    if not found:
        return {}, ""
    s0 = found[0]
    cols = {c: units.get(c, "") for c in s0.values}
    cols.update({c: motion_units(units.get(c[4:-1], ""))[0] for c in s0.speeds})
    cols.update({c: motion_units(units.get(c[2:], ""))[1] for c in s0.momenta})
    return cols, matrix_units([units.get(c, "") for c in s0.reduced_coords or s0.values]).get("K", "")


def format_steady(name: str, pins: dict, found, units: dict | None = None) -> str:
    """The table of steady motions; ``units``: each coordinate's SI unit, said in the column heads."""
    from ..analysis.tables import num, table

    said = ", ".join(f"{k} = {num(v)}" for k, v in pins.items())
    if not found:
        return f"{name}: no steady motion found with {said}\n  hint: give a guess with --guess NAME=VALUE"
    cols, ku = steady_units(found, units or {})
    rows = [[str(i)] + [num(v) for v in (*s.values.values(), *s.speeds.values(), *s.momenta.values())]
            + [{True: "stable", False: "unstable", None: "undetermined"}[s.stable],
               ", ".join(num(x) for x in s.hessian_eigenvalues)] for i, s in enumerate(found, 1)]
    lines = [f"{name}: {len(found)} steady motion{'' if len(found) == 1 else 's'} with {said} "
             f"(ignorable: {', '.join(found[0].ignorable)})",
             table(["#"] + [c + (f" [{u}]" if u else "") for c, u in cols.items()]
                   + ["stability", "Hessian of V_R" + (f" [{ku}]" if ku else "")], rows)]
    lines += [f"  {i}: {s.reason}" for i, s in enumerate(found, 1)]
    return "\n".join(lines)


def _si_units(m) -> dict:
    """coordinate -> the unit its values are in (SI; rad for an angle declared in deg)."""
    from ..numbers import si_unit

    return {c.name: u for c in m.model.coordinates if (u := si_unit(c.unit))}


def format_equilibria(name: str, coords, eqs, units: dict | None = None) -> str:
    """The table of equilibria; ``units``: each coordinate's unit (SI), said in its column's head."""
    from ..analysis.tables import num, table
    from ..model.units import matrix_units

    search_notes = [f"  note: {n}" for n in getattr(eqs, "notes", None) or ()]
    if not eqs:
        why = eqs.search.why_none(coords) if hasattr(eqs, "search") else ""
        return "\n".join([f"{name}: no equilibrium found" + (f": {why}" if why else " (no starting guess converged)"),
                          "  hint: give a guess with --guess NAME=VALUE; a steady motion (a circular orbit, a "
                          "spinning top) is a relative equilibrium, not a rest state"] + search_notes)
    kinds = sorted({e.kind for e in eqs})
    lines = [f"{name}: {len(eqs)} equilibri{'um' if len(eqs) == 1 else 'a'} ({', '.join(kinds)})"]
    rows = []
    # constrained models: the multipliers of the constraints kept (dropped redundant ones are 0)
    lam_names = list(eqs[0].active_constraints) if eqs[0].multipliers is not None else []
    for i, e in enumerate(eqs, 1):
        lam = [num(e.lambdas[c]) for c in lam_names]
        rows.append([str(i)] + [num(v) for v in e.q] + lam + [e.kind, e.stability,
                                                              "[" + ", ".join(num(v) for v in e.hessian_eigenvalues) + "]"])
    head = "Hessian eigenvalues" if not lam_names else "reduced Hessian eigenvalues"
    units, lam_units = units or {}, eqs[0].lambda_units if lam_names else {}
    ku = matrix_units([units.get(c, "") for c in coords]).get("K")
    head += f" [{ku}]" if ku else ""
    heads = [c + (f" [{units[c]}]" if units.get(c) else "") for c in coords]
    lines.append(table(["#"] + heads + [f"lambda[{c}]" + (f" [{lam_units[c]}]" if lam_units.get(c) else "")
                                       for c in lam_names] + ["kind", "stability", head], rows))
    common = [n for n in eqs[0].notes if all(n in e.notes for e in eqs[1:])] if len(eqs) > 1 else []
    for i, e in enumerate(eqs, 1):
        lines.append(f"  {i}: {e.reason}")
        for note in e.notes:
            if note not in common:
                lines.append(f"     note: {note}")
    lines += [f"  note: {n}" for n in common]
    return "\n".join(lines + search_notes)
