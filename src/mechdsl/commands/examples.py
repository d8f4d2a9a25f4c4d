"""``mech examples [--copy DIR [--force]]``: the example models shipped with mechdsl
(mechdsl.examples): list them with their one-line descriptions, or copy them into a folder."""
from __future__ import annotations

HELP = "list the example models shipped with mechdsl, or copy them into a folder"


def add_parser(sub):
    p = sub.add_parser("examples", help=HELP,
                       description=HELP + ". Then, e.g.: mech examples --copy ex && "
                                          "mech simulate ex/double_pendulum.mech -o dp.csv")
    p.add_argument("names", nargs="*", metavar="NAME", help="only these examples (default: all)")
    p.add_argument("--copy", metavar="DIR", help="copy the examples into DIR (created if missing)")
    p.add_argument("--path", action="store_true", help="print the path of each example instead of its description")
    p.add_argument("--force", action="store_true", help="with --copy: replace files of the same name in DIR")
    return p


def run(args) -> int:
    from .. import examples

    out = args.out
    chosen = [examples.path(n).stem for n in args.names] if args.names else examples.names()
    if args.copy:
        written = examples.copy(args.copy, force=args.force, only=chosen)
        out.wrote(*written)
        out.set(folder=str(args.copy), examples=[{"name": p.stem, "path": str(p)} for p in written])
        print(f"copied {len(written)} example{'s' if len(written) != 1 else ''} into {args.copy}; try:\n"
              f"  mech simulate {_join(args.copy, 'double_pendulum.mech' if 'double_pendulum' in chosen else written[0].name)}")
        return 0
    rows = [(n, examples.description(n), examples.path(n)) for n in chosen]
    out.set(folder=str(examples.folder()),
            examples=[{"name": n, "description": d, "path": str(p)} for n, d, p in rows])
    width = max(len(n) for n, _, _ in rows)
    for n, d, p in rows:
        print(f"{n:<{width}}  {p if args.path else d}")
    return 0


def _join(folder, name) -> str:
    import os

    return os.path.join(str(folder), name)
