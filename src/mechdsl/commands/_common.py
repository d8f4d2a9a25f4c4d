"""What every ``mech`` command shares: the model-selection options, ONE ``--set`` grammar, one
number reader, one loader, and the line that says which scene (or none) a command used.

``--set`` (and ``--guess``) take one ``NAME=VALUE`` per option, and one option may hold several
comma-separated assignments: ``--set m=2 --set L=1`` and ``--set m=2,L=1`` mean the same in every
command.  An option never takes more than one argument, so it cannot swallow the FILE that
follows it.  ``NAME.start`` / ``NAME.speed`` set a coordinate's start value / speed.

Values are numbers or small arithmetic expressions (``pi/4``, ``2*pi/3``, ``deg(30)``,
``sqrt(2)``, ``2^3``), evaluated in floating point with a bounded text length, so that no value
can hang the reader (``9**9**9`` is an overflow, not a 370-million-digit integer) and every value
is finite.
"""
from __future__ import annotations


from ..diagnostics import UsageError, did_you_mean
from ..numbers import assignments, number  # noqa: F401  (the commands read values through here)
from ..model.names import split_state

# --------------------------------------------------------------------------- argparse pieces


def add_common_args(p) -> None:
    """The options every command has (cli.build_parser adds them to each): --json, -q, -v.
    What they do is in commands/_output.py (one place for every command)."""
    g = p.add_argument_group("output")
    g.add_argument("--json", action="store_true",
                   help="print one JSON document on stdout (result, files written, warnings, diagnostics; "
                        "schema: docs/json.md); human text goes to stderr")
    g.add_argument("-q", "--quiet", action="count", default=0,
                   help="print no results text, only errors and warnings")
    g.add_argument("-v", "--verbose", action="count", default=0,
                   help="also print what mechdsl does (-vv: in detail)")


def verbosity(args) -> int:
    """-q / -v as one number: -1 quiet, 0 default, 1 and 2 more."""
    return int(getattr(args, "verbose", 0) or 0) - int(getattr(args, "quiet", 0) or 0)


def add_target_args(p, *, what: str = "use") -> None:
    """FILE, --model and --scene (exclusive)."""
    p.add_argument("file", metavar="FILE", help=".mech file")
    g = p.add_mutually_exclusive_group()
    g.add_argument("--model", metavar="M", help=f"model to {what} (default: the file's first scene, else its last model)")
    g.add_argument("--scene", metavar="S", help=f"scene to {what} (its model, overrides and settings)")


def add_cache_arg(p) -> None:
    p.add_argument("--no-cache", action="store_true",
                   help="neither read nor write the model cache (parse, analyse and derive anew; docs/simulate.md)")


def add_set_arg(p) -> None:
    p.add_argument("--set", action="append", default=[], metavar="NAME=VALUE[,...]",
                   help="change a parameter (m=2) or a start value (theta.start=pi/4, theta.speed=0); "
                        "repeat it or separate assignments by commas")


def add_force_arg(p) -> None:
    p.add_argument("--force", action="store_true",
                   help="replace existing output files that mechdsl did not write (its own are replaced anyway)")


def add_guess_arg(p, help_text: str) -> None:
    p.add_argument("--guess", action="append", default=[], metavar="NAME=VALUE[,...]", help=help_text)


# --------------------------------------------------------------------------- values
# (number, assignments: mechdsl.numbers, shared with the Python API's sweeps)


def split_starts(values: dict[str, float]) -> tuple[dict[str, float], dict[str, float]]:
    """{name: value} -> (parameters, start values); start keys are 'c' or 'der(c)'."""
    params: dict[str, float] = {}
    starts: dict[str, float] = {}
    for name, v in values.items():
        if name.endswith(".start"):
            starts[name[: -len(".start")]] = v
        elif name.endswith(".speed"):
            starts[f"der({name[: -len('.speed')]})"] = v
        else:
            params[name] = v
    return params, starts


def start_overrides(coords, model_name: str, starts: dict[str, float]) -> dict[str, float]:
    """Check start-value keys against the coordinates (did-you-mean on a typo)."""
    for key in starts:
        name = split_state(key)[0]
        if name not in coords:
            hint = did_you_mean(name, list(coords))
            raise UsageError(f"--set {name}.start/.speed: '{name}' is not a coordinate of {model_name}"
                             + (f"; {hint}" if hint else f" (coordinates: {', '.join(coords)})"))
    return dict(starts)


# --------------------------------------------------------------------------- loading


def load_model(args, *, starts_in_model: bool = True):
    """mechdsl.load with --model/--scene/--no-units and --set applied.

    starts_in_model=True: start values go into the model (a new analysis), for commands that read
    the model's start state; False: returns ``(model, x0)`` with the start values as overrides of
    the state vector (no re-derivation), for runs.
    """
    from ..api import load

    m = load(args.file, model=getattr(args, "model", None), scene=getattr(args, "scene", None),
             units=not getattr(args, "no_units", False), cache=not getattr(args, "no_cache", False))
    # where a later phase's diagnostic without a position of its own is shown (cli._locate)
    args._where = (m.scene or m.model).span
    params, starts = split_starts(assignments(getattr(args, "set", None)))
    if starts_in_model:
        values = dict(params)
        for key, v in starts.items():
            coord, speed = split_state(key)
            values[f"{coord}.speed" if speed else f"{coord}.start"] = v
        if starts:
            start_overrides(m.coordinates, m.name, starts)
        return m.with_params(**values) if values else m
    if params:
        m = m.with_params(**params)
    return m, start_overrides(m.coordinates, m.name, starts)


def target_line(args, m) -> str:
    """Which model and scene a command used, said in its output (no scene applied silently)."""
    if m.scene is not None:
        how = "" if getattr(args, "scene", None) else \
            f" (the file's first scene; --model {m.name} for the model without it)"
        return f"scene {m.scene.name} of model {m.name}{how}"
    return f"model {m.name} (no scene)"
