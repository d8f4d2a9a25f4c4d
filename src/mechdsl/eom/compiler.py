"""Which C compiler mechdsl uses ($CC, else gcc, cc or clang on PATH), without CasADi: codegen
compiles with it, a prepared warm run (simulation/warm_run.py) keys on it."""
from __future__ import annotations

import os


def _which(name: str) -> str | None:
    """shutil.which on POSIX (importing shutil costs a warm run 2 ms: it imports lzma and bz2)."""
    if os.name != "posix":
        import shutil

        return shutil.which(name)
    folders = [""] if os.sep in name else os.get_exec_path()
    for d in folders:
        path = os.path.join(d, name)
        if os.path.isfile(path) and os.access(path, os.X_OK):
            return path
    return None


def find_compiler() -> str | None:
    for cand in (os.environ.get("CC"), "gcc", "cc", "clang"):
        if cand:
            path = _which(cand)
            if path:
                return path
            if os.environ.get("CC") == cand:
                return None  # an explicit CC that does not exist: do not guess another
    return None
