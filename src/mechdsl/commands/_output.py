"""What every ``mech`` command hands back: human text, or with ``--json`` one JSON document.

One pattern for every command (docs/internals.md, "How to add a command"):

- ``run(args)`` prints its human text with ``print()`` as always;
- it hands its machine-readable result to ``args.out`` (an :class:`Output`):
  ``args.out.set(key=value, ...)``, the files it wrote with ``args.out.wrote(path)``, warnings
  with ``args.out.warn(text)`` (or through ``logging``: the CLI's handler records them too),
  remarks on what it chose (a default, a picked speed) with ``args.out.note(text)`` (stderr,
  silent under ``-q``),
  diagnostics with ``args.out.diagnostic(d)``;
- a command whose product *is* text (``compile``, ``equations``, ``completion``) hands it to
  ``args.out.product(text)``: stdout in human mode (even under ``-q``), the ``text`` field with
  ``--json``.

cli.main does the rest for every command alike (:meth:`Output.session`): under ``--json`` the
human text goes to stderr (the Python-level ``sys.stdout`` and, for what C libraries print,
file descriptor 1 are pointed there while the command runs), and exactly one JSON document is
written to stdout at the end, also when the command fails (usage error, model error, internal
error, interrupt) and with the exit code unchanged.  ``-q`` silences the human text (errors and
warnings still go to stderr); ``-v``/``-vv`` show the library's INFO/DEBUG log messages.

The document's schema: mechdsl/schemas/cli-output.schema.json (docs/json.md).
"""
from __future__ import annotations

import contextlib
import json
import logging
import math
import os
import sys
from typing import Any

SCHEMA_VERSION = 1
LOGGER = "mechdsl"


class Output:
    """The run's machine-readable record (and where its human text goes)."""

    def __init__(self, command: str | None, json_mode: bool = False, verbosity: int = 0):
        self.command = command
        self.json = bool(json_mode)
        self.verbosity = int(verbosity)          # -q: -1, default 0, -v: 1, -vv: 2
        self.result: dict[str, Any] = {}
        self.files: list[str] = []
        self.warnings: list[str] = []
        self.diagnostics: list[dict] = []
        self.error: dict | None = None
        self._stdout = None                      # the real stdout while a session runs

    # ---------------------------------------------------------------- what commands call
    @property
    def quiet(self) -> bool:
        return self.verbosity < 0

    def set(self, **fields) -> None:
        """Fields of the command's result (``result`` in the JSON document)."""
        self.result.update(fields)

    def wrote(self, *paths) -> None:
        """Files the command wrote (``files_written``)."""
        self.files += [str(p) for p in paths if p]

    def warn(self, text: str, echo: bool = True) -> None:
        """A warning: recorded (``warnings``) and shown on stderr as ``mech: warning: ...``."""
        self.warnings.append(str(text))
        if echo:
            print(f"mech: warning: {text}", file=sys.stderr)

    def note(self, text: str) -> None:
        """A remark on what the command chose for the user (a default end time, a picked speed):
        ``mech: text`` on stderr, so it never mixes with a product on stdout; nothing under -q."""
        if not self.quiet:
            print(f"mech: {text}", file=sys.stderr)

    def diagnostic(self, d) -> None:
        """A Diagnostic (error, warning or note) for ``diagnostics`` (printing it stays the caller's)."""
        self.diagnostics.append(diagnostic_dict(d))

    def product(self, text: str) -> None:
        """Text that is the command's product: stdout in human mode, ``result.text`` with --json."""
        if self.json:
            self.result["text"] = text
        else:
            (self._stdout or sys.stdout).write(text)

    # ---------------------------------------------------------------- what cli.main calls
    def fail(self, kind: str, message: str) -> None:
        self.error = {"kind": kind, "message": str(message)}

    def document(self, exit_code: int) -> dict:
        from .. import __version__

        return {"schema_version": SCHEMA_VERSION, "mechdsl": __version__, "command": self.command,
                "exit_code": int(exit_code), "ok": exit_code == 0, "error": self.error,
                "result": jsonable(self.result), "files_written": list(self.files),
                "warnings": list(self.warnings), "diagnostics": list(self.diagnostics)}

    def write_document(self, exit_code: int) -> bool:
        """Print the document; False when standard output cannot take it (a full device)."""
        text = json.dumps(self.document(exit_code), indent=2, allow_nan=False) + "\n"
        try:
            sys.stdout.write(text)
            sys.stdout.flush()
        except BrokenPipeError:
            pass
        except OSError as e:
            print(f"mech: error: cannot write <standard output>: {e.strerror or e}", file=sys.stderr)
            return False
        return True

    @contextlib.contextmanager
    def session(self):
        """While a command runs: its human text to the right place (stderr under --json), the
        library's log messages to stderr (warnings also into the record).  ``reconfigure``
        applies -q/-v once the words are parsed."""
        self._handler = _Handler(self)
        logger = logging.getLogger(LOGGER)
        old_level = logger.level
        logger.addHandler(self._handler)
        logger.setLevel(_level(self.verbosity))
        self._stdout = sys.stdout
        self._restore: list = []
        try:
            if self.json:
                self._redirect(sys.stderr)
            yield self
        finally:
            for undo in reversed(self._restore):
                undo()
            logger.removeHandler(self._handler)
            logger.setLevel(old_level)
            self._stdout = None

    def reconfigure(self) -> None:
        """Apply the parsed verbosity: the log level, and under -q no human text at all."""
        logging.getLogger(LOGGER).setLevel(_level(self.verbosity))
        if self.quiet:
            sink = open(os.devnull, "w")
            self._redirect(sink, fd=False)      # (descriptor 1 stays: product() writes there)
            self._restore.append(sink.close)

    def _redirect(self, sink, fd: bool = True) -> None:
        """Point sys.stdout (and file descriptor 1, for what C code prints) at ``sink`` until
        the session ends."""
        try:
            sys.stdout.flush()
        except (OSError, ValueError):
            pass
        saved_fd = _point_fd1_to(sink) if fd else None
        previous = sys.stdout
        sys.stdout = sink

        def undo():
            try:
                sys.stdout.flush()
            except (OSError, ValueError):
                pass
            sys.stdout = previous
            if saved_fd is not None:
                os.dup2(saved_fd, 1)
                os.close(saved_fd)
        self._restore.append(undo)


def _point_fd1_to(sink):
    """Point file descriptor 1 at ``sink`` (what C code prints goes there too); returns a copy
    of the old descriptor to restore, or None when stdout is not descriptor 1 (a test's capture)."""
    try:
        if sys.stdout.fileno() != 1:
            return None
        target = sink.fileno()
    except (AttributeError, OSError, ValueError):
        return None
    saved = os.dup(1)
    os.dup2(target, 1)
    return saved


def _level(verbosity: int) -> int:
    if os.environ.get("MECHDSL_DEBUG"):
        return logging.DEBUG
    return {-1: logging.ERROR, 0: logging.WARNING, 1: logging.INFO}.get(max(-1, min(2, verbosity)), logging.DEBUG)


class _Handler(logging.Handler):
    """The CLI's handler of the ``mechdsl`` logger: ``mech: [level: ]message`` on the stderr of
    the moment (so a test's capture sees it), warnings also recorded in the JSON document."""

    def __init__(self, out: Output):
        super().__init__()
        self.out = out

    def emit(self, record: logging.LogRecord) -> None:
        try:
            text = record.getMessage()
            if record.levelno >= logging.WARNING:
                self.out.warnings.append(text)
            tag = "" if record.levelno == logging.INFO else f"{record.levelname.lower()}: "
            print(f"mech: {tag}{text}", file=sys.stderr)
        except Exception:            # pragma: no cover - logging must never break a run
            self.handleError(record)


def diagnostic_dict(d) -> dict:
    s = d.span
    known = s.line > 0
    return {"code": d.code, "severity": d.severity, "message": d.message, "file": s.file or None,
            "line": s.line if known else None, "column": s.col if known else None,
            "end_line": s.end_line if known and s.end_line > 0 else None,
            "end_column": s.end_col if known and s.end_col > 0 else None, "hint": d.help}


def jsonable(x):
    """Plain JSON types (numpy arrays and scalars, tuples, paths, non-finite floats as null)."""
    if isinstance(x, dict):
        return {str(k): jsonable(v) for k, v in x.items()}
    if isinstance(x, (list, tuple, set, frozenset)):
        return [jsonable(v) for v in (sorted(x, key=str) if isinstance(x, (set, frozenset)) else x)]
    if isinstance(x, bool) or x is None or isinstance(x, str):
        return x
    if isinstance(x, int):
        return x
    if isinstance(x, float):
        return x if math.isfinite(x) else None
    if hasattr(x, "tolist"):                       # numpy arrays and scalars
        return jsonable(x.tolist())
    if isinstance(x, os.PathLike):
        return os.fspath(x)
    if hasattr(x, "to_dict"):
        return jsonable(x.to_dict())
    return str(x)
