"""Diagnostics as data.

Every user-facing problem is a :class:`Diagnostic` (code, message, span, help).  Early
phases collect many and raise them together as one :class:`MechError`; later phases stop
at the first.  A bug in mechdsl itself is an :class:`InternalError`, never a Diagnostic.

Rendered form (``render``)::

    models/x.mech:3:12: error[E201]: undefined name 'lenght'
        parameter Real m = lenght;
                           ^^^^^^
      help: did you mean 'length'?
"""
from __future__ import annotations

from dataclasses import field
from typing import Iterable, Sequence

from .model.records import record


@record(order=True)
class Span:
    """A half-open region of a source file (1-based lines and columns)."""

    file: str = "<input>"
    line: int = 0
    col: int = 0
    end_line: int = 0
    end_col: int = 0

    @staticmethod
    def none(file: str = "<input>") -> "Span":
        return Span(file, 0, 0, 0, 0)

    def __str__(self) -> str:
        return f"{self.file}:{self.line}:{self.col}"


@record
class Diagnostic:
    code: str
    message: str
    span: Span = field(default_factory=Span)
    help: str | None = None
    severity: str = "error"  # "error" | "warning" | "note"

    def render(self, source: str | None = None) -> str:
        return render(self, source)


class MechError(Exception):
    """One or more user errors (bad model, bad input).  Carries Diagnostics."""

    def __init__(self, diagnostics: Diagnostic | Sequence[Diagnostic]):
        if isinstance(diagnostics, Diagnostic):
            diagnostics = [diagnostics]
        self.diagnostics: list[Diagnostic] = list(diagnostics)
        super().__init__("; ".join(f"{d.code}: {d.message}" for d in self.diagnostics))

    @property
    def first(self) -> Diagnostic:
        return self.diagnostics[0]

    def __str__(self) -> str:
        """The same located text the command line prints: ``file:line:col: error[CODE]: ...``, the
        source line, a caret and the hint, one block per diagnostic."""
        from .diagnostics import format_diagnostics

        return format_diagnostics(self.diagnostics)


class InternalError(Exception):
    """A bug in mechdsl (never the user's fault)."""


class UsageError(Exception):
    """Wrong use of the command line or the Python API (exit code 2)."""


class DiagnosticBag:
    """Collects diagnostics of a phase; ``raise_if_errors`` ends the phase."""

    def __init__(self) -> None:
        self.items: list[Diagnostic] = []

    def error(self, code: str, message: str, span: Span | None = None, help: str | None = None) -> None:
        self.items.append(Diagnostic(code, message, span or Span(), help))

    def warning(self, code: str, message: str, span: Span | None = None, help: str | None = None) -> None:
        self.items.append(Diagnostic(code, message, span or Span(), help, "warning"))

    def extend(self, diags: Iterable[Diagnostic]) -> None:
        self.items.extend(diags)

    @property
    def errors(self) -> list[Diagnostic]:
        return [d for d in self.items if d.severity == "error"]

    @property
    def warnings(self) -> list[Diagnostic]:
        return [d for d in self.items if d.severity == "warning"]

    def raise_if_errors(self) -> None:
        errs = list(dict.fromkeys(self.errors))  # the same error found twice (e.g. in two passes) once
        if errs:
            unique = list(dict.fromkeys(errs))  # the same problem found twice is reported once
            raise MechError(sorted(unique, key=_order))


def _order(d: Diagnostic):
    return (d.span.file, d.span.line, d.span.col, d.code)


def did_you_mean(name: str, candidates: Iterable[str]) -> str | None:
    import difflib      # (4 ms to import: only when a name is wrong)

    close = difflib.get_close_matches(name, sorted(set(candidates)), n=1, cutoff=0.6)
    return f"did you mean '{close[0]}'?" if close else None


def render(d: Diagnostic, source: str | None = None) -> str:
    """``file:line:col: error[CODE]: message``, the source line, a caret, and the hint."""
    s = d.span
    loc = f"{s.file}:{s.line}:{s.col}" if s.line > 0 else s.file
    out = [f"{loc}: {d.severity}[{d.code}]: {d.message}"]
    if source is not None and s.line > 0:
        lines = [ln.rstrip("\r") for ln in source.split("\n")]  # lines as the lexer counts them (\n only)
        if 1 <= s.line <= len(lines):
            text = lines[s.line - 1].expandtabs(4) if "\t" not in lines[s.line - 1] else lines[s.line - 1].replace("\t", " ")
            # control characters (escape sequences in a damaged file) are not sent to the terminal
            text = "".join(c if c.isprintable() else "\ufffd" for c in text)
            if len(text) > 200:  # keep the caret line readable for minified input
                start = max(0, s.col - 80)
                text = text[start:start + 160]
                col = s.col - start
            else:
                col = s.col
            width = 1
            if s.end_line == s.line and s.end_col > s.col:
                width = min(s.end_col - s.col, max(1, len(text) - col + 1))
            out.append(f"    {text}")
            out.append("    " + " " * max(0, col - 1) + "^" * max(1, width))
    if d.help:
        out.append(f"  help: {d.help}")
    return "\n".join(out)


# --- printing diagnostics with their source lines (sources are cached by file name)
_SOURCES: dict[str, str] = {}


def remember_source(filename: str, text: str) -> None:
    _SOURCES[filename] = text


def forget_source(filename: str) -> None:
    _SOURCES.pop(filename, None)


def source_of(filename: str) -> str | None:
    return _SOURCES.get(filename)


def format_diagnostics(diags: Iterable[Diagnostic]) -> str:
    return "\n".join(render(d, source_of(d.span.file)) for d in diags)

