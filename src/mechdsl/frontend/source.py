"""Reading a .mech file: size limit, regular files only, UTF-8, no NUL bytes (E001-E006).

Kept apart from the parser so that a run served from the model cache (mechdsl.eom.modelcache)
reads its source without importing lark and the front end.
"""
from __future__ import annotations

import os
import stat
from pathlib import Path

from . import limits
from ..diagnostics import Diagnostic, MechError, Span


def read_source(path: str | os.PathLike) -> tuple[str, str]:
    """Read a .mech file: (filename as given, text).  Problems are E0xx diagnostics."""
    name = str(path)
    p = Path(path)
    if not p.exists():
        raise MechError(Diagnostic("E001", f"file not found: {name}", Span(name),
                                   "check the path; models are .mech files"))
    if p.is_dir():
        raise MechError(Diagnostic("E003", f"{name} is a directory, not a .mech file", Span(name),
                                   f"pass the files inside it, e.g. {name.rstrip('/')}/*.mech"))
    limit = limits.get("file_bytes")
    try:
        # stat before opening: opening a FIFO blocks, reading a device never ends
        st = os.stat(p)
        if not stat.S_ISREG(st.st_mode):
            raise MechError(Diagnostic("E006", f"{name} is not a regular file ({_file_kind(st.st_mode)})", Span(name),
                                       "models are read from ordinary .mech files; save the text to a file first"))
        if st.st_size > limit:
            raise MechError(_too_large(name, st.st_size))
        with open(p, "rb") as f:
            data = f.read(limit + 1)  # the file may grow after stat: never read more than the limit
    except OSError as e:
        raise MechError(Diagnostic("E001", f"cannot read {name}: {e.strerror or e}", Span(name),
                                   "check the file's permissions")) from None
    return name, decode_source(data, name)


def _too_large(name: str, size: int) -> Diagnostic:
    return Diagnostic("E005", f"file is too large ({size:,} bytes, more than {limits.get('file_bytes'):,})", Span(name),
                      "mechdsl reads hand-written models; " + limits.hint("file_bytes"))


def _file_kind(mode: int) -> str:
    for test, kind in ((stat.S_ISFIFO, "a FIFO"), (stat.S_ISCHR, "a character device"),
                       (stat.S_ISBLK, "a block device"), (stat.S_ISSOCK, "a socket")):
        if test(mode):
            return kind
    return "not an ordinary file"


def decode_source(data: bytes, name: str = "<input>") -> str:
    from ..diagnostics import forget_source

    forget_source(name)  # an older text of the same name must not be shown under these errors
    if len(data) > limits.get("file_bytes"):
        raise MechError(_too_large(name, len(data)))
    try:
        text = data.decode("utf-8-sig")
    except UnicodeDecodeError as e:
        line = data[:e.start].count(b"\n") + 1
        col = len(data[data.rfind(b"\n", 0, e.start) + 1:e.start].decode("utf-8", "replace")) + 1
        raise MechError(Diagnostic("E002", f"file is not valid UTF-8 (byte 0x{data[e.start]:02x})",
                                   Span(name, line, col, line, col + 1),
                                   "save the file as UTF-8 text")) from None
    if "\x00" in text:
        i = text.index("\x00")
        line = text.count("\n", 0, i) + 1
        col = i - (text.rfind("\n", 0, i) + 1) + 1
        raise MechError(Diagnostic("E002", "file contains a NUL byte: not a text file",
                                   Span(name, line, col, line, col + 1), "is this a binary file?"))
    return text
