"""Formatting a .mech file: every statement printed by the printer (frontend/printer.py), the
comments and the paragraphs (blank lines) of the file kept.

The AST has no comments, so the printer alone would drop them.  Here the file is cut at its
statements (a model's header, each declaration, the ``equation`` keyword, each equation, a
``for`` loop's header and ``end for;``, ``end Name;``; a scene's items): each statement is
replaced by its printed form at its depth, and what lies between statements (comments, blank
lines) is kept: a comment on a statement's line stays behind it, a comment on a line of its own
stays on a line of its own (indented as the statements around it), runs of blank lines become
one.  A statement with a comment inside it is kept as written.  Several ``equation`` sections
become one, as the printer writes them.

A file with syntax errors is never formatted (:func:`format_source` raises its MechError), and
the result is checked before it is returned: it must parse to the same AST and hold the same
comments in the same order, else :class:`FormatError` (a bug in the formatter, never a changed
model).
"""
from __future__ import annotations

import re

from . import ast
from . import printer as P
from .parser import _code_only, parse

_TOKEN = re.compile(r'"(?:[^"\\\n]|\\.)*"|//[^\r\n]*|/\*.*?\*/', re.S)
_STRING = re.compile(r'"(?:[^"\\\n]|\\.)*"')
_BLANK_LINE = re.compile(r"\n[ \t\r\f]*\n")
WIDTH = 100     # a statement the author wrapped stays wrapped when its printed line is longer


class FormatError(Exception):
    """The formatted text would not mean the same as the original (a bug): nothing is changed."""


def comments(text: str) -> list[tuple[int, int]]:
    """The [start, end) offsets of every comment (not inside a string)."""
    return [(m.start(), m.end()) for m in _TOKEN.finditer(text) if m.group().startswith("/")]


def format_source(text: str, filename: str = "<input>") -> str:
    """The formatted text (the same text when it is formatted already)."""
    tree = parse(text, filename)            # syntax errors: MechError, nothing formatted
    out = _Formatter(text).run(tree)
    try:
        again = parse(out, filename)
    except Exception as e:                   # noqa: BLE001 - any failure is the formatter's bug
        raise FormatError(f"the formatted text does not parse ({e})") from None
    finally:
        from ..diagnostics import remember_source

        remember_source(filename, text)     # diagnostics of this file show the user's text
    if again != tree:
        raise FormatError("the formatted text would mean something else")
    if _comment_texts(out) != _comment_texts(text):
        raise FormatError("the formatted text would lose or change a comment")
    return out


def _shift(line: str, by: int) -> str:
    if by >= 0:
        return " " * by + line if line.strip() else line
    cut = min(-by, len(line) - len(line.lstrip(" ")))
    return line[cut:]


def _comment_texts(text: str) -> list[str]:
    return [text[a:b].replace("\r\n", "\n").rstrip() for a, b in comments(text)]


class _Formatter:
    def __init__(self, text: str):
        self.text = text
        self.code = _code_only(text)
        self.comments = comments(text)
        self.starts = [0] + [i + 1 for i, c in enumerate(text) if c == "\n"]
        self.lines: list[str] = []
        self.on_line = False        # the last output line ends where the original text stands (a
        self.want_blank = False     # comment there stays on it); a blank line before the next line

    # ------------------------------------------------------------------ positions
    def off(self, line: int, col: int) -> int:
        return self.starts[line - 1] + col - 1

    def span(self, node) -> tuple[int, int]:
        s = node.span
        return self.off(s.line, s.col), self.off(s.end_line, s.end_col)

    def keyword(self, word: str, a: int, b: int, last: bool = False) -> int:
        found = [m.start() for m in re.finditer(rf"\b{word}\b", self.code[a:b])]
        if not found:
            raise FormatError(f"'{word}' not found")     # cannot happen for a parsed file
        return a + (found[-1] if last else found[0])

    def has_comment(self, a: int, b: int) -> bool:
        return any(a <= c0 < b for c0, _ in self.comments)

    # ------------------------------------------------------------------ output
    def newline(self, line: str) -> None:
        if self.want_blank and self.lines and self.lines[-1] != "":
            self.lines.append("")
        self.want_blank = False
        self.lines.append(line)

    def gap(self, a: int, b: int, indent: str) -> None:
        """The comments and blank lines of text[a:b] (no code there but keywords dropped)."""
        p = a
        for c0, c1 in self.comments:
            if not a <= c0 < b:
                continue
            between = self.text[p:c0]
            body = self.text[c0:c1].replace("\r\n", "\n")
            if "\n" not in between and self.on_line and self.lines:
                first, *rest = body.split("\n")
                self.lines[-1] += between.replace("\r", "") + first
                self.lines += rest
            else:
                if _BLANK_LINE.search(between):
                    self.want_blank = True
                first, *rest = body.split("\n")
                self.newline(indent + first)
                self.lines += rest
            self.on_line = True
            p = c1
        if _BLANK_LINE.search(self.text, p, b):
            self.want_blank = True

    def statement(self, a: int, b: int, printed: list[str]) -> None:
        """One statement text[a:b]: its printed lines, or the original text when a comment is
        inside it, or when the author wrapped it over several lines and printed it is too long."""
        original = self.text[a:b].replace("\r\n", "\n")
        wrapped = "\n" in original and any(len(x) > WIDTH for x in printed)
        if self.has_comment(a, b) or wrapped:
            first, *rest = original.split("\n")
            indent = printed[0][:len(printed[0]) - len(printed[0].lstrip())]
            if not self.has_comment(a, b):      # continuation lines move with the first line
                line_start = self.text.rfind("\n", 0, a) + 1
                old = a - line_start if not self.text[line_start:a].strip() else len(indent)
                rest = [_shift(x, len(indent) - old) for x in rest]
            printed = [indent + first] + rest
        self.newline(printed[0])
        self.lines += printed[1:]
        self.on_line = True

    # ------------------------------------------------------------------ the file
    def run(self, tree: ast.File) -> str:
        pos = 0
        for k, u in enumerate(tree.items):
            a, b = self.span(u)
            if k:
                self.want_blank = True          # units are paragraphs of their own
            self.gap(pos, a, "")
            head_end = self.header_end(u)
            self.statement(a, head_end, [P.header(u)])
            pos = head_end
            if isinstance(u, ast.ModelDef):
                pos = self.model_body(u, pos)
            else:
                for it in u.items:
                    pos = self.item(it, pos, 1, [P.INDENT + P.scene_item(it)])
            end = self.keyword("end", pos, b, last=True)
            self.gap(pos, end, P.INDENT)
            self.statement(end, b, [f"end {u.name};"])
            pos = b
        self.gap(pos, len(self.text), "")
        out = "\n".join(self.lines) + "\n"
        return out.replace("\n", "\r\n") if "\r\n" in self.text else out

    def header_end(self, u) -> int:
        end = self.off(u.name_span.end_line, u.name_span.end_col)
        if u.doc is None:
            return end
        m = _STRING.search(self.text, end)      # the doc string: the next string after the name
        return m.end() if m else end

    def model_body(self, m: ast.ModelDef, pos: int) -> int:
        for el in m.elements:
            pos = self.item(el, pos, 1, [P.INDENT + P.element(el)])
        if m.equations:
            first = self.span(m.equations[0])[0]
            kw = self.keyword("equation", pos, first)
            self.gap(pos, kw, P.INDENT)
            self.statement(kw, kw + len("equation"), ["equation"])
            pos = kw + len("equation")
            for eq in m.equations:
                pos = self.equation(eq, pos, 1)
        return pos

    def item(self, node, pos: int, depth: int, printed: list[str]) -> int:
        a, b = self.span(node)
        self.gap(pos, a, P.INDENT * depth)
        self.statement(a, b, printed)
        return b

    def equation(self, eq, pos: int, depth: int) -> int:
        ind = P.INDENT * depth
        if not isinstance(eq, ast.ForEquation) or not eq.body:
            return self.item(eq, pos, depth, P.equation(eq, depth))
        a, b = self.span(eq)
        head = self.keyword("loop", self.span(eq.range)[1], self.span(eq.body[0])[0]) + len("loop")
        end = self.keyword("end", self.span(eq.body[-1])[1], b, last=True)
        if self.has_comment(a, head) or self.has_comment(end, b):
            return self.item(eq, pos, depth, P.equation(eq, depth))
        self.gap(pos, a, ind)
        self.statement(a, head, [ind + P.for_header(eq)])
        pos = head
        for inner in eq.body:
            pos = self.equation(inner, pos, depth + 1)
        self.gap(pos, end, ind + P.INDENT)
        self.statement(end, b, [ind + "end for;"])
        return b


__all__ = ["format_source", "FormatError", "comments"]
