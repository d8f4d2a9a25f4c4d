"""Where mechdsl keeps what it builds (compiled libraries, the model cache, sxcode's instruction
lists): $MECHDSL_CACHE, else $XDG_CACHE_HOME/mechdsl or ~/.cache/mechdsl.  A module of its own
so that the modules writing into it need not import the code generator."""
from __future__ import annotations

import os
from pathlib import Path


def cache_dir() -> Path:
    d = os.environ.get("MECHDSL_CACHE")
    if d:
        return Path(d)
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return Path(base) / "mechdsl"
