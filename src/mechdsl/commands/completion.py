"""``mech completion bash|zsh|tcsh``: a shell completion script for ``mech``, generated from the
command line's own argparse parser by shtab (the ``completion`` extra), so it cannot drift
from the commands and their options.

    mech completion bash > ~/.local/share/bash-completion/completions/mech
    mech completion zsh > ~/.zfunc/_mech        # with fpath+=(~/.zfunc) before compinit
"""
from __future__ import annotations

from ..diagnostics import UsageError

SHELLS = ("bash", "zsh", "tcsh")
HELP = "print a shell completion script (bash, zsh or tcsh; needs the 'completion' extra: shtab)"
# options naming files or folders complete as paths
FILE_DESTS = {"file", "files", "output", "plot", "csv", "reference", "fmu"}
DIR_DESTS = {"copy"}


def add_parser(sub):
    p = sub.add_parser("completion", help=HELP, description=HELP + ".  Install it with, e.g., "
                       "mech completion bash > ~/.local/share/bash-completion/completions/mech")
    p.add_argument("shell", choices=SHELLS, help="the shell to complete in")
    return p


def run(args) -> int:
    try:
        import shtab
    except ImportError:
        raise UsageError("mech completion needs shtab: pip install 'mechdsl[completion]'") from None
    args.out.set(shell=args.shell)
    args.out.product(script(args.shell, shtab))
    return 0


def script(shell: str, shtab) -> str:
    """The completion script of the whole ``mech`` parser for ``shell``."""
    from ..cli import build_parser

    parser = build_parser()
    for p in _parsers(parser):
        for action in p._actions:
            if action.dest in FILE_DESTS:
                action.complete = shtab.FILE
            elif action.dest in DIR_DESTS:
                action.complete = shtab.DIRECTORY
    text = shtab.complete(parser, shell=shell)
    return text if text.endswith("\n") else text + "\n"


def _parsers(parser):
    import argparse

    yield parser
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for sub in action.choices.values():
                yield from _parsers(sub)
