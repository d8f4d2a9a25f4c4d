"""``mech equations FILE``: Lagrange's equations of a model, as people write them."""
from __future__ import annotations

from ._common import add_cache_arg, add_set_arg, add_target_args, load_model, target_line


def add_parser(sub):
    p = sub.add_parser("equations", help="print the Lagrange equations of a model",
                       description="Print T, V, D, Q and one Lagrange equation per coordinate, simplified "
                                   "(sympy). Large models are described by their structure instead.")
    add_target_args(p, what="print")
    add_cache_arg(p)
    add_set_arg(p)
    p.add_argument("--latex", action="store_true", help="print LaTeX (an align environment)")
    p.add_argument("--hamiltonian", action="store_true", help="print Hamilton's equations instead")
    return p


def run(args) -> int:
    m = load_model(args)
    model = m.model
    out = args.out
    head = ("% " if args.latex else "") + target_line(args, m) + "\n"
    out.set(target=target_line(args, m), model=m.name, form="hamilton" if args.hamiltonian else "lagrange",
            latex=bool(args.latex))
    if args.hamiltonian:
        from ..analysis.hamilton import format_hamiltonian

        text = format_hamiltonian(model, latex=args.latex)
    else:
        from ..mechanics.printing import format_equations

        text = format_equations(model, latex=args.latex)
    # the equations are the product (shown under -q too); the target line heads them
    out.product(text if out.json else head + text)
    return 0
