"""``mech export FILE --fmu OUT.fmu``: a model as a Functional Mock-up Unit (FMI 2.0 or 3.0)."""
from __future__ import annotations

from ._common import add_cache_arg, add_force_arg, add_set_arg, add_target_args, load_model, target_line

HELP = "export a model as an FMU (FMI 2.0 or 3.0; model exchange and/or co-simulation)"


def add_parser(sub):
    p = sub.add_parser("export", help=HELP, description=HELP + "; see docs/export.md")
    add_target_args(p, what="export")
    add_cache_arg(p)
    p.add_argument("--fmu", metavar="OUT.fmu", required=True, help="the FMU to write (its folder must exist)")
    p.add_argument("--fmi-version", choices=("2", "3"), default="2", help="FMI version (default 2)")
    p.add_argument("--fmi-type", choices=("me", "cs", "both"), default=None,
                   help="model exchange, co-simulation or both (default: every interface the model can have; "
                        "a model with contacts is exported for co-simulation)")
    add_set_arg(p)
    add_force_arg(p)
    return p


def run(args) -> int:
    from ..export import export_fmu
    from ..output.fileio import check_writable

    check_writable(args.fmu, args.force)            # before any work is done
    model = load_model(args)
    target = target_line(args, model)
    print(target)
    info = export_fmu(model, args.fmu, fmi_version=int(args.fmi_version), fmi_type=args.fmi_type,
                      overwrite=args.force)
    args.out.wrote(info.path)
    args.out.set(target=target, model=model.name, fmi_version=f"{info.fmi_version}.0",
                 interfaces=list(info.interfaces), identifier=info.identifier, variables=info.variables,
                 size=info.size, notes=list(info.notes))
    for note in info.notes:
        print(f"note: {note}")
    print(f"wrote {info.path} (FMI {info.fmi_version}.0: {', '.join(info.interfaces)}; modelIdentifier "
          f"{info.identifier}; {info.variables} variables; {info.size / 1000:.0f} kB)")
    return 0
