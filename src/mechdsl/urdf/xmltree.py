"""A small XML tree with source positions, read with the standard library's expat.

ElementTree keeps no line numbers, and every message about a URDF names the element it is about
(``file:line:col``), so the reader builds its own light tree.  Hostile XML is refused rather
than expanded: a document type declaration (which is where entities are declared: the "billion
laughs" and external-entity attacks) is an error, as is a file beyond ``MAX_BYTES``; URDF and
COLLADA files need neither.
"""
from __future__ import annotations

import os
import stat
from dataclasses import dataclass, field
from pathlib import Path
from xml.parsers import expat

from ..diagnostics import Diagnostic, MechError, Span

MAX_BYTES = 20_000_000          # a URDF (the largest in example-robot-data: 0.2 MB)


@dataclass
class Element:
    tag: str
    attrib: dict[str, str]
    line: int
    col: int
    children: list["Element"] = field(default_factory=list)
    text: str = ""

    def find(self, tag: str) -> "Element | None":
        for c in self.children:
            if c.tag == tag:
                return c
        return None

    def findall(self, tag: str) -> list["Element"]:
        return [c for c in self.children if c.tag == tag]

    def iter(self, tag: str):
        if self.tag == tag:
            yield self
        for c in self.children:
            yield from c.iter(tag)

    def get(self, key: str, default: str | None = None) -> str | None:
        return self.attrib.get(key, default)


class _Refused(Exception):
    pass


def read_bytes(path: str, limit: int | None = None, what: str = "URDF file") -> bytes:
    """The bytes of an ordinary file, at most ``limit`` (default MAX_BYTES; E001 missing, E003 a
    folder, E006 not a regular file, E005 too large)."""
    limit = MAX_BYTES if limit is None else limit
    p = Path(path)
    if not p.exists():
        raise MechError(Diagnostic("E001", f"file not found: {path}", Span(path), f"check the path of the {what}"))
    if p.is_dir():
        raise MechError(Diagnostic("E003", f"{path} is a directory, not a {what}", Span(path),
                                   "pass the file itself"))
    try:
        st = os.stat(p)
        if not stat.S_ISREG(st.st_mode):
            raise MechError(Diagnostic("E006", f"{path} is not a regular file", Span(path),
                                       f"save the {what} to an ordinary file first"))
        if st.st_size > limit:
            raise MechError(Diagnostic("E005", f"{path} is too large ({st.st_size:,} bytes, more than {limit:,})",
                                       Span(path), f"a {what} this large is not read"))
        with open(p, "rb") as f:
            return f.read(limit + 1)
    except OSError as e:
        raise MechError(Diagnostic("E001", f"cannot read {path}: {e.strerror or e}", Span(path),
                                   "check the file's permissions")) from None


def parse(data: bytes, name: str, code: str = "E020") -> Element:
    """The tree of an XML document; a document that is not well-formed XML, or declares a
    document type (entities), is ``code`` at the place expat stopped."""
    root: list[Element] = []
    stack: list[Element] = []
    p = expat.ParserCreate()
    p.buffer_text = True

    def start(tag, attrib):
        el = Element(tag, attrib, p.CurrentLineNumber, p.CurrentColumnNumber + 1)
        if stack:
            stack[-1].children.append(el)
        else:
            root.append(el)
        stack.append(el)
        chunks.append([])

    chunks: list[list[str]] = []

    def end(tag):
        el = stack.pop()
        parts = chunks.pop()
        if parts:
            el.text = "".join(parts)

    def text(data):
        if chunks:
            chunks[-1].append(data)

    def refuse(*args):
        raise _Refused()

    p.StartElementHandler = start
    p.EndElementHandler = end
    p.CharacterDataHandler = text
    p.StartDoctypeDeclHandler = refuse
    p.EntityDeclHandler = refuse
    try:
        p.Parse(data, True)
    except _Refused:
        at = data.find(b"<!DOCTYPE")
        line = data.count(b"\n", 0, at) + 1 if at >= 0 else p.CurrentLineNumber
        col = at - (data.rfind(b"\n", 0, at) + 1) + 1 if at >= 0 else p.CurrentColumnNumber + 1
        raise MechError(Diagnostic(code, "the file declares a document type (<!DOCTYPE ...>), which may define "
                                         "entities: refused", Span(name, line, col, line, col + 9),
                                   "remove the <!DOCTYPE> declaration; URDF needs none")) from None
    except expat.ExpatError as e:
        raise MechError(Diagnostic(code, f"not well-formed XML: {expat.ErrorString(e.code)}",
                                   Span(name, e.lineno, e.offset + 1, e.lineno, e.offset + 2),
                                   "is this a URDF file? check the line for an unclosed tag or a stray character")) from None
    if not root:
        raise MechError(Diagnostic(code, "the file holds no XML element", Span(name, 1, 1), "is this a URDF file?"))
    return root[0]


def span(name: str, el: Element) -> Span:
    """The place of an element: its start tag."""
    return Span(name, el.line, el.col, el.line, el.col + 1 + len(el.tag))
