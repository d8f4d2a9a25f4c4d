"""``mech compile FILE --emit ast|source|model|eom|problem``: dump a named intermediate form (deterministic)."""
from __future__ import annotations

from ..output.fileio import check_writable, write_atomic
from ._common import add_force_arg, target_line

EMITS = ("ast", "source", "model", "eom", "problem")


def add_parser(sub):
    p = sub.add_parser("compile", help="dump an intermediate form (ast, source, model, eom, problem)",
                       description="Run the pipeline up to a phase and print its named intermediate form.")
    p.add_argument("file", metavar="FILE")
    p.add_argument("--emit", choices=EMITS, default="model", help="which form (default: model)")
    p.add_argument("--model", help="model to compile (default: first scene's model or the last model)")
    p.add_argument("--scene", help="scene to compile")
    p.add_argument("--no-spans", action="store_true", help="omit source positions from --emit ast")
    p.add_argument("-o", "--output", help="write to this file instead of standard output")
    p.add_argument("--no-units", action="store_true", help="skip dimensional analysis")
    p.add_argument("--t-end", type=float, metavar="T",
                   help="--emit problem: end time (default: the scene's stop_time, else 10)")
    add_force_arg(p)
    return p


def run(args) -> int:
    from ..api import Model
    from ..frontend.dump import dump_ast, dump_model
    from ..frontend.parser import parse_file
    from ..frontend.printer import to_source
    from ..semantic import analyze

    if args.output:
        check_writable(args.output, args.force)
    tree = parse_file(args.file)
    if args.emit == "ast":
        text = dump_ast(tree, spans=not args.no_spans)
    elif args.emit == "source":
        text = to_source(tree)
    else:
        program = analyze(tree, units=not args.no_units)
        m = Model._from_program(program, args.model, args.scene)
        args.out.note(target_line(args, m))
        args.out.set(target=target_line(args, m), model=m.name)
        if args.emit == "model":
            text = dump_model(m.model)
        elif args.emit == "problem":
            from ..simulation import dump

            text = dump(m.problem(t_end=args.t_end))      # none given: the scene's, else the default
        else:
            from ..eom.dump_eom import dump_eom

            text = dump_eom(m.eom)
    args.out.set(emit=args.emit)
    if args.output:
        write_atomic(args.output, text, overwrite=args.force)
        args.out.wrote(args.output)
    else:
        args.out.product(text)
    return 0
