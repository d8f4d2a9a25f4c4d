"""Printing diagnostics with their source lines (sources are cached by file name)."""
from __future__ import annotations

import sys
from typing import Iterable

from .diagnostics import Diagnostic, render

_SOURCES: dict[str, str] = {}


def remember_source(filename: str, text: str) -> None:
    _SOURCES[filename] = text


def forget_source(filename: str) -> None:
    _SOURCES.pop(filename, None)


def source_of(filename: str) -> str | None:
    return _SOURCES.get(filename)


def format_diagnostics(diags: Iterable[Diagnostic]) -> str:
    return "\n".join(render(d, source_of(d.span.file)) for d in diags)


def print_diagnostics(diags: Iterable[Diagnostic], file=None) -> None:
    diags = list(diags)
    print(format_diagnostics(diags), file=file or sys.stderr)
    n_err = sum(d.severity == "error" for d in diags)
    if n_err > 1:
        print(f"{n_err} errors", file=file or sys.stderr)
