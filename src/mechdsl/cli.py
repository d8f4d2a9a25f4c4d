"""The ``mech`` command line.  Exit codes: 0 ok, 1 model/simulation error, 2 usage error.

Never shows a Python traceback for bad input: user errors are Diagnostics; an internal
error prints a short report asking for a bug report (with the traceback only under
MECHDSL_DEBUG=1).
"""
from __future__ import annotations

import argparse
import errno
import importlib
import os
import sys

# mechdsl's matrices are small: a threaded BLAS only fights the integrator for the cores
# (measured: equilibria of the 81-coordinate N-four-bar 8.3 s threaded, 2.4 s single).
# Set before numpy loads; a user's own setting wins.
for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

from .diagnostics import InternalError, MechError, UsageError


class _Formatter(argparse.HelpFormatter):
    """argparse's formatter with the terminal width found as shutil finds it, without importing
    shutil (and zlib, bz2, lzma): argparse builds a formatter for every option it registers."""

    def __init__(self, prog, **kw):
        kw.setdefault("width", _columns() - 2)
        super().__init__(prog, **kw)


def _columns() -> int:
    try:
        columns = int(os.environ.get("COLUMNS", "0"))
    except ValueError:
        columns = 0
    if columns <= 0:
        try:
            columns = os.get_terminal_size(sys.__stdout__.fileno()).columns
        except (AttributeError, ValueError, OSError):
            columns = 0
    return columns if columns > 0 else 80


class _Parser(argparse.ArgumentParser):
    def __init__(self, *a, **kw):
        kw.setdefault("formatter_class", _Formatter)
        super().__init__(*a, **kw)

    def error(self, message):  # usage errors: exit 2, no traceback (cli.main prints them)
        raise _BadArguments(self, message)


class _BadArguments(Exception):
    def __init__(self, parser, message):
        super().__init__(message)
        self.parser = parser


def build_parser(only: str | None = None) -> argparse.ArgumentParser:
    """The argument parser; ``only``: import and register just that command (a run of one
    command imports only what it needs: bench, plotting and analysis stay unloaded)."""
    from . import __version__
    from .commands import COMMANDS, module_of
    from .commands._common import add_common_args

    ap = _Parser(prog="mech", description="mechdsl: equation-based modelling of rigid-body mechanics")
    ap.add_argument("--version", action="version", version=f"mechdsl {__version__}")
    sub = ap.add_subparsers(dest="command", metavar="COMMAND", parser_class=_Parser)
    for name in ([only] if only in COMMANDS else COMMANDS):
        try:
            mod = importlib.import_module(f".commands.{module_of(name)}", __package__)
        except ModuleNotFoundError as e:
            if e.name and e.name.endswith(f"commands.{module_of(name)}"):
                continue  # command not built (yet)
            raise
        p = mod.add_parser(sub)
        p.add_argument("--limit", action="append", default=[], metavar="NAME=N", type=_limit,
                       help="raise a size budget of the front end, e.g. coordinates=5000 "
                            "(names and defaults: docs/language.md, Limits)")
        add_common_args(p)
        p.set_defaults(_run=mod.run)
    return ap


def _limit(text: str) -> tuple[str, int]:
    from .frontend.limits import parse_setting

    try:
        return parse_setting(text)
    except ValueError as e:
        raise argparse.ArgumentTypeError(str(e)) from None


def main(argv: list[str] | None = None) -> int:
    """Run ``mech`` with these words (default: sys.argv[1:]); returns the exit code."""
    sys.setrecursionlimit(max(sys.getrecursionlimit(), 10000))
    words = sys.argv[1:] if argv is None else list(argv)
    if words == ["--version"]:           # without building every command's parser (imports)
        from . import __version__

        print(f"mechdsl {__version__}")
        return 0
    from .commands import COMMANDS
    from .commands._output import Output

    # known before parsing, so that a usage error is a JSON document too
    out = Output(words[0] if words and words[0] in COMMANDS else None, json_mode="--json" in words)
    with out.session():
        code = _run(words, out)
    if out.json and not out.write_document(code):
        _quiet_stdout()
        return code or 1
    return code


def _run(words: list[str], out) -> int:
    args = None
    try:
        from .commands import COMMANDS

        ap = build_parser(words[0] if words and words[0] in COMMANDS else None)
        args = ap.parse_args(words)
        if not getattr(args, "_run", None):
            ap.print_help(sys.stderr)
            out.fail("usage", "no command given")
            return 2
        from .commands._common import verbosity

        out.verbosity = verbosity(args)
        out.reconfigure()
        args.out = out
        from .frontend.limits import override

        with override(dict(getattr(args, "limit", None) or [])):
            code = int(args._run(args) or 0)
        try:
            sys.stdout.flush()      # here, not at exit: a full device is an error we can report
        except OSError as e:
            e.filename = e.filename or "<standard output>"
            raise
        return code
    except _BadArguments as e:
        e.parser.print_usage(sys.stderr)
        print(f"mech: error: {e}", file=sys.stderr)
        out.fail("usage", str(e))
        return 2
    except SystemExit as e:
        return int(e.code) if isinstance(e.code, int) else (0 if e.code is None else 2)
    except UsageError as e:
        print(f"mech: error: {e}", file=sys.stderr)
        out.fail("usage", str(e))
        return 2
    except MechError as e:
        # diagnostics of later phases that carry no source position are located at the model
        # (or scene) the command worked on, else at the file
        path = getattr(args, "file", None) or (getattr(args, "files", None) or [None])[0]
        located = [_locate(d, path, getattr(args, "_where", None)) for d in e.diagnostics]
        print_diagnostics(located)
        for d in located:
            out.diagnostic(d)
        out.fail("model", located[0].message if located else str(e))
        return 1
    except KeyboardInterrupt:
        print("mech: interrupted", file=sys.stderr)
        out.fail("interrupted", "interrupted")
        return 130
    except BrokenPipeError:
        _quiet_stdout()
        return 0
    except OSError as e:
        if e.errno not in _IO_ERRORS:
            return _internal(e, out)
        _quiet_stdout()
        print(f"mech: error: cannot write{f' {e.filename}' if e.filename else ''}: {e.strerror or e}",
              file=sys.stderr)
        out.fail("output", f"cannot write{f' {e.filename}' if e.filename else ''}: {e.strerror or e}")
        return 1
    except (InternalError, Exception) as e:  # a bug in mechdsl, not in the model
        return _internal(e, out)


# what the environment did, not a bug: a full or read-only device, a quota, permissions, an I/O
# error, a name too long (exit 1 with the system's message)
_IO_ERRORS = {errno.ENOSPC, errno.EDQUOT, errno.EROFS, errno.EIO, errno.EACCES, errno.EPERM,
              errno.ENAMETOOLONG, errno.EFBIG, errno.EMFILE, errno.ENFILE, errno.ENOMEM}


def _internal(e, out) -> int:
    if os.environ.get("MECHDSL_DEBUG"):
        raise e
    print(f"mech: internal error: {type(e).__name__}: {e}\n"
          "  this is a bug in mechdsl; rerun with MECHDSL_DEBUG=1 for the traceback and report it",
          file=sys.stderr)
    out.fail("internal", f"{type(e).__name__}: {e}")
    return 3


def _quiet_stdout() -> None:
    """Point standard output at /dev/null: what is left in its buffer cannot be written, and
    Python's flush at exit would report the same error again as an ignored exception."""
    try:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        os.close(devnull)
    except (OSError, ValueError, AttributeError):
        pass


def print_diagnostics(diags) -> None:
    """The located diagnostics on stderr, and how many errors when more than one."""
    from .diagnostics import format_diagnostics

    diags = list(diags)
    print(format_diagnostics(diags), file=sys.stderr)
    n_err = sum(d.severity == "error" for d in diags)
    if n_err > 1:
        print(f"{n_err} errors", file=sys.stderr)


def _locate(d, path, where=None):
    import dataclasses

    if d.span.line > 0:
        return d
    if where is not None and where.line > 0:
        return dataclasses.replace(d, span=where)
    if path and d.span.file in ("<input>", ""):
        return dataclasses.replace(d, span=dataclasses.replace(d.span, file=str(path)))
    return d


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
