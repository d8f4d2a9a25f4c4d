"""Atomic file output: write to a temporary file in the same folder, then rename.

Nothing the user wrote is overwritten unless asked: ``check_writable`` refuses to replace a
source file ever, and any other existing file that mechdsl did not write itself unless
``overwrite=True`` (``--force``).  mechdsl's own outputs carry a marker: JSON files a
"generator" key, plots the "mechdsl" software tag, and a results CSV its JSON sidecar.
"""
from __future__ import annotations

import os
import tempfile
from pathlib import Path

from .diagnostics import UsageError

PROTECTED_SUFFIXES = {".mech", ".py", ".md", ".toml", ".lark"}


def check_writable(path: str | os.PathLike, overwrite: bool = True) -> Path:
    p = Path(path)
    if p.suffix in PROTECTED_SUFFIXES and p.exists():
        raise UsageError(f"refusing to overwrite source file {p} (choose another output name)")
    if p.exists() and p.is_dir():
        raise UsageError(f"{p} is a directory, not a file")
    if p.exists() and not overwrite and not is_own_output(p):
        raise UsageError(f"{p} exists and was not written by mechdsl (pass --force to replace it)")
    if not p.parent.exists():
        p.parent.mkdir(parents=True, exist_ok=True)
    return p


MARKER = b"mechdsl"


def is_own_output(p: Path) -> bool:
    """True for a file mechdsl wrote (so re-running a command may replace it)."""
    try:
        if p.suffix == ".csv":
            side = p.with_suffix(".json")
            return side.is_file() and _has_marker(side) and p.read_bytes()[:5] == b"time,"
        return _has_marker(p)
    except OSError:
        return False


def _has_marker(p: Path) -> bool:
    with open(p, "rb") as f:
        head = f.read(65536)
    return b'"generator": "mechdsl' in head or (p.suffix in (".png", ".svg", ".pdf") and MARKER in head)


def write_atomic(path: str | os.PathLike, data: str | bytes, overwrite: bool = True) -> Path:
    p = check_writable(path, overwrite)
    mode = "wb" if isinstance(data, bytes) else "w"
    fd, tmp = tempfile.mkstemp(prefix=f".{p.name}.", suffix=".tmp", dir=str(p.parent))
    try:
        with os.fdopen(fd, mode, **({} if mode == "wb" else {"encoding": "utf-8", "newline": "\n"})) as f:
            f.write(data)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, p)
    except BaseException:
        try:
            os.unlink(tmp)
        except OSError:
            pass
        raise
    return p


def atomic_target(path: str | os.PathLike, overwrite: bool = True) -> tuple[Path, Path]:
    """For writers that need a filename (matplotlib): returns (tmp, final); call ``commit``."""
    p = check_writable(path, overwrite)
    fd, tmp = tempfile.mkstemp(prefix=f".{p.stem}.", suffix=p.suffix, dir=str(p.parent))
    os.close(fd)
    return Path(tmp), p


def commit(tmp: Path, final: Path) -> Path:
    os.replace(tmp, final)
    return final
