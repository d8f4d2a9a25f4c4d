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

import errno
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
    _check_name(p)
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


TEMP_ROOM = 32      # characters a temporary name adds to a file name: ".NAME.PID.XXXXXXXX.SUFFIX"


def _check_name(p: Path) -> None:
    """A name the file system takes, with room for the temporary name it is written under."""
    folder = p.parent
    try:
        most = os.pathconf(folder if folder.is_dir() else ".", "PC_NAME_MAX")
    except (OSError, ValueError, AttributeError):
        most = 255
    if len(os.fsencode(p.name)) + TEMP_ROOM > most:
        raise UsageError(f"the file name {p.name[:40]}... is too long ({len(os.fsencode(p.name))} bytes; at most "
                         f"{most - TEMP_ROOM} here: the file system takes {most}, and mechdsl writes under a "
                         "temporary name first)")
    try:
        p.exists()
    except OSError as e:            # a path too long as a whole, a loop of links, ...
        raise UsageError(f"cannot use the output name {str(p)[:60]}...: {e.strerror or e}"
                         + (" (the path is too long)" if e.errno == errno.ENAMETOOLONG else "")) from None


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
            head = _head(p, 32)        # (never the whole file: an output may be gigabytes)
            if head.startswith(b"mode,kind,frequency_rad_s,"):    # mech linearize --csv
                return True
            side = p.with_suffix(".json")
            if not (side.is_file() and _has_marker(side)):
                return False
            # a results CSV starts with "time,", a sweep's table with "run,time,"; a table
            # (mech bench) is named in its sidecar
            return head.startswith((b"time,", b"run,time,")) or f'"table": "{p.name}"'.encode() in _head(side, 65536)
        if p.suffix == ".nc":
            return _netcdf_by_mechdsl(p)
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


def _netcdf_by_mechdsl(p: Path) -> bool:
    """A netCDF (HDF5) file whose global attribute ``generator`` names mechdsl (a sweep's)."""
    if not _head(p, 8).startswith(b"\x89HDF"):
        return False
    try:
        import h5py
    except ImportError:
        return False
    try:
        with h5py.File(p, "r") as f:
            g = f.attrs.get("generator")
    except Exception:  # noqa: BLE001 - any file h5py cannot read is not ours
        return False
    g = g.decode("utf-8", "replace") if isinstance(g, bytes) else str(g)
    return g.startswith("mechdsl")


def pair_problem(csv_path: str | os.PathLike) -> str | None:
    """None when a CSV mechdsl wrote and its JSON sidecar belong together, else what is wrong.

    Both are renamed into place one after the other (the CSV first), so a kill between the
    two renames can leave a new CSV beside an old sidecar; the sidecar records the CSV's
    SHA-256, checked here (streamed: the CSV is not read whole)."""
    import hashlib
    import json

    p = Path(csv_path)
    side = p.with_suffix(".json")
    try:
        meta = json.loads(side.read_text(encoding="utf-8"))
    except FileNotFoundError:
        return f"has no sidecar {side.name} (written by something else, or its sidecar was removed)"
    except (OSError, ValueError) as e:
        return f"has an unreadable sidecar {side.name} ({e})"
    want = meta.get("csv_sha256") if isinstance(meta, dict) else None
    if not want:
        return f"has a sidecar {side.name} without the CSV's checksum"
    h = hashlib.sha256()
    with open(p, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    if h.hexdigest() != want:
        return (f"does not match its sidecar {side.name} (a different CSV was written after it: a run killed "
                "between writing the two, or an edited file); run again to write both")
    return None


def _head(p: Path, n: int) -> bytes:
    with open(p, "rb") as f:
        return f.read(n)


def _has_marker(p: Path) -> bool:
    head = _head(p, 65536)
    return b'"generator": "mechdsl' in head or (p.suffix in FIGURE_SUFFIXES and MARKER in head)


def temp_name(final: Path, suffix: str = ".tmp") -> Path:
    """``.NAME.PID.XXXXXXXX.SUFFIX`` beside ``final``: the writer's process id lets a later run
    tell the leftovers of a killed write (``remove_stale``) from a write still going on."""
    return final.parent / f".{final.name}.{os.getpid()}.{os.urandom(4).hex()}{suffix}"   # (secrets: 15 ms import)


def remove_stale(final: Path) -> list[Path]:
    """Remove the temporary files (and folders) of earlier writes of ``final`` whose writer is
    gone (killed: SIGKILL, a power cut); those of a live process are left alone.  Returns what
    was removed."""
    import re

    pattern = re.compile(r"\." + re.escape(final.name) + r"\.(\d+)\.[0-9a-f]{8}(\.[\w.-]*)?$")
    removed = []
    try:
        entries = [e for e in os.scandir(final.parent) if e.name.startswith(f".{final.name}.")]
    except OSError:
        return removed
    for e in entries:
        m = pattern.match(e.name)
        if m is None or _alive(int(m.group(1))):
            continue
        try:
            if e.is_dir(follow_symlinks=False):
                import shutil      # (only here: a warm run does not import it)

                shutil.rmtree(e.path)
            else:
                os.unlink(e.path)
            removed.append(Path(e.path))
        except OSError:
            pass
    return removed


def _alive(pid: int) -> bool:
    if pid == os.getpid():
        return True
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except (PermissionError, OverflowError):
        return True              # another user's process (or an absurd number): not ours to judge
    return True


def _new_temp(final: Path, suffix: str = ".tmp") -> tuple[int, Path]:
    """A fresh temporary file beside ``final``: mode 0666 & ~umask, or final's mode if it exists.
    The leftovers of killed writes of ``final`` are removed first."""
    remove_stale(final)
    for _ in range(100):
        tmp = temp_name(final, suffix)
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
