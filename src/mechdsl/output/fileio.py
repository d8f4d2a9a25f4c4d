"""Atomic file output: write to a temporary file in the same folder, then rename.

Nothing the user wrote is overwritten unless asked: ``check_writable`` refuses to replace a
source file ever, and any other existing file that mechdsl did not write itself unless
``overwrite=True`` (``--force``).  mechdsl's own outputs carry a marker: JSON files a
"generator" key, plots the "mechdsl" software tag, and a results CSV its JSON sidecar; those
are replaced when a command is run again.

New files are created with mode 0666 minus the umask, like any tool's output (the temporary
file is opened with ``os.open(..., 0o666)``, so the kernel applies the umask; no process-wide
``os.umask`` round trip); a replaced file keeps its mode.  A missing output folder is an error,
never created silently.
"""
from __future__ import annotations

import os
from pathlib import Path

from ..diagnostics import UsageError

PROTECTED_SUFFIXES = {".mech", ".py", ".md", ".toml", ".lark"}
FIGURE_SUFFIXES = (".png", ".svg", ".pdf")


def check_writable(path: str | os.PathLike, overwrite: bool = False, source: bool = False) -> Path:
    """Refuse, before any work is done, an output that cannot or must not be written.  ``source``:
    the output is itself a source file (``mech import`` writes a .mech): an existing file of that
    name is replaced only when asked (``overwrite``, ``--force``), never otherwise."""
    p = Path(path)
    if not str(path):
        raise UsageError("an output file name is empty")
    if p.exists() and p.is_dir():
        raise UsageError(f"{p} is a directory, not a file")
    if source and p.exists() and not overwrite:
        raise UsageError(f"{p} exists (pass --force to replace it)")
    if p.suffix in PROTECTED_SUFFIXES and p.exists() and not source:
        raise UsageError(f"refusing to overwrite source file {p} (choose another output name)")
    if p.exists() and not overwrite and not is_own_output(p):
        raise UsageError(f"{p} exists and was not written by mechdsl (pass --force to replace it)")
    folder = p.parent
    if not folder.is_dir():
        raise UsageError(f"cannot write {p}: the folder {folder} does not exist (create it first)")
    if not os.access(folder, os.W_OK | os.X_OK):
        raise UsageError(f"cannot write {p}: the folder {folder} is not writable")
    return p


def check_figure(path: str | os.PathLike, overwrite: bool = False) -> Path:
    """check_writable for a figure: also its format, before any work is done."""
    p = Path(path)
    if p.suffix.lower() not in FIGURE_SUFFIXES:
        raise UsageError(f"figure file must end in {', '.join(FIGURE_SUFFIXES)} (got {str(path)!r})")
    return check_writable(p, overwrite)


def output_folder(path: str | os.PathLike) -> Path:
    """A folder named as an output (``mech bench -o DIR``): created if missing, but only inside a
    folder that exists (no silent chain of new folders from a typo)."""
    d = Path(path)
    if d.exists() and not d.is_dir():
        raise UsageError(f"{d} is not a folder")
    if not d.exists():
        if not d.parent.is_dir():
            raise UsageError(f"cannot create {d}: the folder {d.parent} does not exist (create it first)")
        d.mkdir()
    return d


MARKER = b"mechdsl"


def is_own_output(p: Path) -> bool:
    """True for a file mechdsl wrote (so re-running a command may replace it)."""
    try:
        if p.suffix == ".fmu":                                  # mech export: its modelDescription says so
            return _own_fmu(p)
        if p.suffix == ".csv":
            if p.read_bytes()[:32].startswith(b"mode,kind,frequency_rad_s,"):    # mech linearize --csv
                return True
            side = p.with_suffix(".json")
            if not (side.is_file() and _has_marker(side)):
                return False
            # a results CSV starts with "time,"; a table (mech bench) is named in its sidecar
            return p.read_bytes()[:5] == b"time," or f'"table": "{p.name}"'.encode() in side.read_bytes()[:65536]
        return _has_marker(p)
    except OSError:
        return False


def _own_fmu(p: Path) -> bool:
    import zipfile

    try:
        with zipfile.ZipFile(p) as zf:
            head = zf.read("modelDescription.xml")[:4096]
    except (zipfile.BadZipFile, KeyError, OSError, RuntimeError):
        return False
    return b'generationTool="mechdsl' in head


def _has_marker(p: Path) -> bool:
    with open(p, "rb") as f:
        head = f.read(65536)
    return b'"generator": "mechdsl' in head or (p.suffix in FIGURE_SUFFIXES and MARKER in head)


def _new_temp(final: Path, suffix: str = ".tmp") -> tuple[int, Path]:
    """A fresh temporary file beside ``final``: mode 0666 & ~umask, or final's mode if it exists."""
    for _ in range(100):
        tmp = final.parent / f".{final.name}.{os.urandom(4).hex()}{suffix}"   # (secrets costs 15 ms to import)
        try:
            fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o666)
        except FileExistsError:
            continue
        try:
            os.chmod(fd, final.stat().st_mode & 0o7777)
        except FileNotFoundError:
            pass
        return fd, tmp
    raise OSError(f"cannot create a temporary file in {final.parent}")


def write_atomic(path: str | os.PathLike, data: str | bytes, overwrite: bool = False, source: bool = False) -> Path:
    return write_atomic_group([(path, data)], overwrite, source)[0]


def write_atomic_group(items, overwrite: bool = False, source: bool = False) -> list[Path]:
    """Write several files that belong together (a CSV and its sidecar): every file is written
    and synced to a temporary name first, then all are renamed in order, so an error while
    writing (a full disk, a kill) leaves the earlier pair untouched."""
    finals = [check_writable(path, overwrite, source) for path, _ in items]
    temps: list[Path] = []
    try:
        for final, (_, data) in zip(finals, items):
            fd, tmp = _new_temp(final)
            temps.append(tmp)
            raw = data if isinstance(data, bytes) else data.encode("utf-8")
            with os.fdopen(fd, "wb") as f:
                f.write(raw)
                f.flush()
                os.fsync(f.fileno())
        for tmp, final in zip(temps, finals):
            os.replace(tmp, final)
    except BaseException:
        for tmp in temps:
            try:
                os.unlink(tmp)
            except OSError:
                pass
        raise
    return finals


def atomic_target(path: str | os.PathLike, overwrite: bool = False) -> tuple[Path, Path]:
    """For writers that need a filename (matplotlib): returns (tmp, final); call ``commit``."""
    p = check_writable(path, overwrite)
    fd, tmp = _new_temp(p, suffix=p.suffix)
    os.close(fd)
    return tmp, p


def commit(tmp: Path, final: Path) -> Path:
    os.replace(tmp, final)
    return final
