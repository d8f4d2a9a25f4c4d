"""Positions: mechdsl's spans (1-based lines split at "\\n" only, as the lexer counts them; 1-based
columns in characters) <-> LSP positions (0-based lines; 0-based columns in the code units the
client and server agreed on: UTF-16 by default, or UTF-8 or UTF-32).

The text is split at "\\n" alone: a form feed or U+2028 inside a line is no line break for the
lexer nor for LSP clients (Python's str.splitlines would count them).
"""
from __future__ import annotations

from ..diagnostics import Span


def _units(ch: str, encoding: str) -> int:
    if encoding == "utf-8":
        return len(ch.encode("utf-8", "surrogatepass"))
    if encoding == "utf-32":
        return 1
    return 2 if ord(ch) > 0xFFFF else 1


class Lines:
    """One text's lines, for converting positions."""

    def __init__(self, text: str, encoding: str = "utf-16"):
        self.lines = [x[:-1] if x.endswith("\r") else x for x in text.split("\n")]
        self.encoding = encoding

    def _line(self, i: int) -> str:
        return self.lines[i] if 0 <= i < len(self.lines) else ""

    def to_lsp(self, line: int, col: int) -> tuple[int, int]:
        """1-based (line, column in characters) -> 0-based (line, column in code units)."""
        if line <= 0:
            return 0, 0
        i = min(line - 1, len(self.lines) - 1)
        text = self._line(i)
        k = max(0, min(col - 1, len(text)))
        if self.encoding == "utf-32" or text.isascii():
            return i, k
        return i, sum(_units(c, self.encoding) for c in text[:k])

    def from_lsp(self, line: int, character: int) -> tuple[int, int]:
        """0-based (line, column in code units) -> 1-based (line, column in characters)."""
        i = max(0, min(line, len(self.lines) - 1))
        text = self._line(i)
        if self.encoding == "utf-32" or text.isascii():
            return i + 1, min(max(0, character), len(text)) + 1
        units = 0
        for k, c in enumerate(text):
            if units >= character:
                return i + 1, k + 1
            units += _units(c, self.encoding)
        return i + 1, len(text) + 1

    def range(self, span: Span) -> tuple[tuple[int, int], tuple[int, int]]:
        """A span as an LSP range; a span without a position is the file's first character."""
        if span.line <= 0:
            return (0, 0), ((0, 1) if self.lines and self.lines[0] else (0, 0))
        start = self.to_lsp(span.line, span.col)
        if span.end_line <= 0 or (span.end_line, span.end_col) <= (span.line, span.col):
            end = self.to_lsp(span.line, span.col + 1)
        else:
            end = self.to_lsp(span.end_line, span.end_col)
        return start, end
