"""``mech import ROBOT.urdf -o ROBOT.mech``: a URDF robot description as a .mech model
(mechdsl.urdf, docs/import.md)."""
from __future__ import annotations

import sys

from ..diagnostics import UsageError


def add_parser(sub):
    p = sub.add_parser("import", help="import a URDF robot description as a .mech model",
                       description="Write the .mech text of a URDF file: one Body per link (links fixed to "
                                   "another merged into it), one joint per movable joint (coordinate J.phi or "
                                   "J.s), limits as parameters, gravity {0, 0, -9.81}. Without -o the text goes "
                                   "to standard output.")
    p.add_argument("file", metavar="ROBOT.urdf")
    p.add_argument("-o", "--output", metavar="ROBOT.mech", help="the .mech file to write")
    p.add_argument("--force", action="store_true", help="replace the output file if it exists")
    p.add_argument("--floating", action="store_true",
                   help="give the root link a Free joint (quaternion) instead of fixing it to the world")
    p.add_argument("--measured-inertia", action="store_true",
                   help="accept inertias that break the triangle inequality beyond rounding as measured data "
                        "(measured_inertia = true on those bodies)")
    p.add_argument("--package-dir", action="append", default=[], metavar="NAME=DIR",
                   help="the folder of the ROS package NAME, for package://NAME/... mesh paths (repeatable)")
    p.add_argument("--skip-missing-meshes", action="store_true",
                   help="a mesh file that is not found is a warning and is not drawn, instead of an error "
                        "(the dynamics do not need meshes)")
    return p


def run(args) -> int:
    from ..diagnostics import format_diagnostics
    from ..output.fileio import check_writable, write_atomic
    from ..urdf import convert

    out = args.out
    dirs = {}
    for item in args.package_dir:
        name, eq, folder = item.partition("=")
        if not eq or not name or not folder:
            raise UsageError(f"--package-dir takes NAME=DIR, got {item!r}")
        dirs[name] = folder
    if args.output:
        if not args.output.endswith(".mech"):
            raise UsageError(f"the output of mech import is a .mech file (got {args.output!r})")
        check_writable(args.output, overwrite=args.force, source=True)
    from pathlib import Path

    imp = convert(args.file, floating=args.floating, measured_inertia=args.measured_inertia, package_dirs=dirs,
                  mech_name=Path(args.output).name if args.output else None,
                  skip_missing_meshes=args.skip_missing_meshes)
    if imp.diagnostics:                       # warnings (a skipped mesh): shown even under -q
        print(format_diagnostics(imp.diagnostics), file=sys.stderr)
        for d in imp.diagnostics:
            out.diagnostic(d)
    out.set(**result(args.file, args.output, imp, args.floating))
    lines = summary(args.file, args.output, imp, args.floating)
    if args.output:
        write_atomic(args.output, imp.text, overwrite=args.force, source=True)
        out.wrote(args.output)
        print("\n".join(lines))
    else:
        out.product(imp.text)                 # the model is the product: stdout (or result.text)
        if not out.quiet:                     # the summary beside it, on stderr
            print("\n".join(lines), file=sys.stderr)
    return 0


def result(source: str, output: str | None, imp, floating: bool) -> dict:
    """The --json result: the model and how the URDF's names map onto it."""
    return {"source": str(source), "output": output, "model": imp.model, "root": imp.root, "floating": floating,
            "bodies": dict(imp.bodies), "joints": dict(imp.joints),
            "coordinates": {j: list(c) for j, c in imp.coordinates.items()}, "kinds": dict(imp.kinds),
            "mimics": {j: {"follows": t, "multiplier": k, "offset": c} for j, (t, k, c) in imp.mimics.items()},
            "left_out": list(imp.left_out), "measured_inertia": list(imp.measured), "shapes": len(imp.shapes)}


def summary(source: str, output: str | None, imp, floating: bool) -> list[str]:
    from collections import Counter

    kinds = Counter(imp.kinds.values())
    n = sum(len(c) for c in imp.coordinates.values())
    lines = [f"{source} -> {output or 'standard output'}: model {imp.model}: {len(imp.bodies)} bodies, "
             f"{len(imp.joints)} joints, {n} coordinate{'s' * (n != 1)}"
             + (f" ({', '.join(f'{k} {v}' for k, v in sorted(kinds.items()))})" if kinds else "")]
    if floating:
        lines.append(f"  root link \"{imp.root}\": free-floating (root_joint, a Free joint in quaternions)")
    else:
        lines.append(f"  root link \"{imp.root}\": fixed to the world (--floating gives it a Free joint)")
    for j, (target, mult, offset) in imp.mimics.items():
        lines.append(f"  mimic: joint \"{j}\" follows \"{target}\" ({mult:g} times it + {offset:g}: no coordinate "
                     "of its own)")
    for j in imp.left_out:
        lines.append(f"  left out: joint \"{j}\" (closes a loop; URDF describes trees)")
    for link in imp.measured:
        lines.append(f"  measured inertia: link \"{link}\" breaks the triangle inequality; accepted as measured data")
    return lines
