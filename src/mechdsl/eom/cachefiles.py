"""Trust and integrity of mechdsl's cache files (the model cache, compiled libraries, the
first-integrals cache): one rule for all of them.

Trust (as ssh treats a key file with loose permissions): a cache folder or entry that another
user owns, or that a group or other users can write, is never read.  The run says so in one
line (a WARNING of the ``mechdsl.cache`` logger, once per folder or entry and process) and
goes on without it: nothing is read from or written to that folder.  Pickled entries (the
model cache) and shared libraries (compiled code) run code when loaded, so this is what keeps
another user's file from running as you.  Folders the cache creates are 0700 and its files
0600, whatever the umask, so a group-writable umask never makes mechdsl refuse its own cache.

Integrity: every entry is named by a digest of its key and carries its full key; a reader
checks that key (a swapped entry is another model's) and the entry's content hash, and a bad
entry is rebuilt.  Every miss has a reason, logged at DEBUG (``MECHDSL_DEBUG=1``,
``mech check -v``).
"""
from __future__ import annotations

import os
import stat
import sys
from pathlib import Path


def cache_dir() -> Path:
    """The cache root: $MECHDSL_CACHE, else $XDG_CACHE_HOME/mechdsl (~/.cache/mechdsl)."""
    d = os.environ.get("MECHDSL_CACHE")
    if d:
        return Path(d)
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return Path(base) / "mechdsl"


LOGGER = "mechdsl.cache"

_WARNED: set = set()          # folders and entries already reported in this process


def _euid() -> int:
    return os.geteuid() if hasattr(os, "geteuid") else -1


def problem(st: os.stat_result, kind: str) -> str | None:
    """Why a folder or file with this status must not be trusted (None: it may)."""
    if _euid() >= 0 and st.st_uid != _euid():
        return f"is owned by another user (uid {st.st_uid})"
    if st.st_mode & (stat.S_IWGRP | stat.S_IWOTH):
        return f"is writable by other users (mode {stat.S_IMODE(st.st_mode):04o})"
    if kind == "folder" and not stat.S_ISDIR(st.st_mode):
        return "is not a folder"
    if kind == "file" and not stat.S_ISREG(st.st_mode):
        return "is not a regular file"
    return None


def refuse(path: Path, why: str, kind: str) -> None:
    """The one line that says a cache folder or entry is not used."""
    key = str(path)
    if key in _WARNED:
        return
    _WARNED.add(key)
    fix = f"chmod go-w {path}" if "writable" in why else f"remove it or give it to yourself ({path})"
    import logging

    logging.getLogger(LOGGER).warning(f"not using the cache {kind} {path}: it {why}; running without it "
                                      f"(fix: {fix})")


def trusted_folder(folder: Path, create: bool = False) -> bool:
    """True when ``folder`` (and the cache root above it) may be read and written; with
    ``create``, missing folders are made (mode 0700).  Says so once when it may not."""
    return folder_state(folder, create) is None


def folder_state(folder: Path, create: bool = False) -> str | None:
    """None when ``folder`` (and the cache root above it) may be used, else why not."""
    root = cache_dir()
    chain = [root] + ([folder] if folder != root else [])
    for d in chain:
        try:
            st = os.lstat(d)
        except FileNotFoundError:
            if not create:
                return "no entry (the cache folder does not exist yet)"
            try:
                _make(d)
                st = os.lstat(d)
            except OSError as e:
                return f"the cache folder {d} cannot be created ({e.strerror or e})"
        except OSError as e:
            return f"the cache folder {d} cannot be read ({e.strerror or e})"
        why = problem(st, "folder")
        if why:
            refuse(d, why, "folder")
            return f"the cache folder {d} {why}"
    return None


def _make(d: Path) -> None:
    """``d`` and its missing parents, each 0700 (os.makedirs' mode applies to the last only)."""
    missing = []
    p = Path(d)
    while not p.exists():
        missing.append(p)
        if p.parent == p:
            break
        p = p.parent
    for q in reversed(missing):
        try:
            os.mkdir(q, 0o700)
        except FileExistsError:
            pass
        os.chmod(q, 0o700)             # (mkdir's mode is masked by the umask)


def read_bytes(path: Path) -> tuple[bytes | None, str]:
    """The content of a cache entry, or (None, why not).  The file is opened without following
    a symbolic link and judged by the status of what was opened (no race with a swap)."""
    why = folder_state(path.parent)
    if why:
        return None, why
    try:
        fd = os.open(path, os.O_RDONLY | getattr(os, "O_NOFOLLOW", 0))
    except FileNotFoundError:
        return None, "no entry"
    except OSError as e:
        return None, f"cannot open the entry ({e.strerror or e})"
    try:
        why = problem(os.fstat(fd), "file")
        if why:
            refuse(path, why, "entry")
            return None, f"the entry {why}"
        with os.fdopen(fd, "rb") as f:
            fd = None
            return f.read(), ""
    except OSError as e:
        return None, f"cannot read the entry ({e.strerror or e})"
    finally:
        if fd is not None:
            os.close(fd)


def check_file(path: Path) -> str | None:
    """For files loaded by others (a shared library through casadi.external): None when
    ``path`` may be loaded, else why not (said once)."""
    if not trusted_folder(path.parent):
        return "its folder is not used"
    try:
        st = os.lstat(path)
    except OSError as e:
        return f"cannot be read ({e.strerror or e})"
    why = problem(st, "file")
    if why:
        refuse(path, why, "entry")
    return why


def write_bytes(path: Path, data: bytes | list) -> bool:
    """Store an entry atomically (temporary name, then rename), mode 0600; False (and nothing
    left behind) when the folder cannot be used or written."""
    from ..output.fileio import remove_stale, temp_name

    if not trusted_folder(path.parent, create=True):
        return False
    remove_stale(path)
    tmp = temp_name(path)
    try:
        fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600)
        with os.fdopen(fd, "wb") as f:
            for part in (data if isinstance(data, list) else [data]):
                f.write(part)
        os.replace(tmp, path)
        return True
    except OSError:
        try:
            os.unlink(tmp)
        except OSError:
            pass
        return False


def remove_stale_builds(folder: Path) -> None:
    """Remove the build folders (``.build-PID-...``) that killed compilations left behind."""
    import re

    from ..output.fileio import _alive

    try:
        found = [e for e in os.scandir(folder) if e.name.startswith(".build-") and e.is_dir(follow_symlinks=False)]
    except OSError:
        return
    for e in found:
        m = re.match(r"\.build-(\d+)-", e.name)
        if m and not _alive(int(m.group(1))):
            import shutil

            shutil.rmtree(e.path, ignore_errors=True)


def describe() -> None:
    """INFO lines (mech check -v) on the cache folders: where they are, whether they are used,
    and why not."""
    import logging

    log = logging.getLogger(LOGGER)
    root = cache_dir()
    for d in (root, root / "models", root / "integrals"):
        try:
            st = os.lstat(d)
        except OSError:
            log.info(f"cache folder {d}: not created yet")
            continue
        why = problem(st, "folder")
        log.info(f"cache folder {d}: " + (f"not used: it {why}" if why else "used (yours, written by you alone)"))


def miss(kind: str, what: str, why: str) -> None:
    """A cache miss and its reason (DEBUG: MECHDSL_DEBUG=1 or -vv)."""
    _debug(f"{kind} cache: miss for {what}: {why}")


def hit(kind: str, what: str) -> None:
    _debug(f"{kind} cache: hit for {what}")


def _debug(text: str) -> None:
    # only where logging is in use (imported by whoever configured it): a warm run does not
    # pay for importing it
    logging = sys.modules.get("logging")
    if logging is not None:
        logging.getLogger(LOGGER).debug(text)
