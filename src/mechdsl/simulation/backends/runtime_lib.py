"""The runtime library's sources, flags and the copy built when mechdsl is installed.

The stepping loop's runtime (crk.c + vm.c beside this file, crk.py) is model-independent: the
wheel's build (hatch_build.py, at ``pip install`` / ``pip wheel`` / ``pip install -e``) compiles
it once into ``_runtime/crk-<key>.so`` in this folder, ``<key>`` the SHA-256 of the sources and
the flags, so a first run on a new machine does not wait for gcc (issue 24, item 8).  At run time
crk.runtime() loads that file when the key of the sources it has matches one (an edited crk.c
has another key: it is then built into the cache folder as before).  Both builds are
``compiler.build_shared`` on the same texts with the same flags: the same bytes for the same
compiler (tests/test_runtime_lib.py).

Standard library only, no package-relative imports: hatch_build.py loads this file (and
eom/compiler.py) by its path, without mechdsl's dependencies.
"""
from __future__ import annotations

import os

HERE = os.path.dirname(os.path.abspath(__file__))
SOURCES = (os.path.join(HERE, "crk.c"), os.path.join(HERE, "vm.c"))
PACKAGED = os.path.join(HERE, "_runtime")       # the install-time build (gitignored in a checkout)

# crk.c, vm.c: crk.c at -O1 takes gcc 0.36 s (-Og 0.19 s, but its loop steps about 5 % slower:
# pendulum, 2544 steps, 5.55 ms against 5.3 ms; every later run pays that, so the one-time compile
# keeps -O1); the interpreter of vm.c is 1.4x faster at -O2.  Same bits at every level (no
# fast-math, no FMA contraction on x86-64).
RUNTIME_FLAGS = (["-O1"], ["-O2"])


def texts() -> tuple[str, ...]:
    """The sources' texts (as the cache's build reads them)."""
    out = []
    for path in SOURCES:
        with open(path) as f:
            out.append(f.read())
    return tuple(out)


def key(units: tuple[str, ...] | None = None) -> str:
    """The first 24 hex digits of the SHA-256 of the sources and their flags."""
    try:                # CPython's own SHA-256 (as mechdsl.digest): hashlib would load OpenSSL in a warm run
        from _sha2 import sha256
    except ImportError:
        try:
            from _sha256 import sha256
        except ImportError:
            from hashlib import sha256
    h = sha256()
    for text, flags in zip(texts() if units is None else units, RUNTIME_FLAGS):
        h.update(text.encode())
        h.update(b"\0" + " ".join(flags).encode() + b"\0")
    return h.hexdigest()[:24]


def file_name(k: str) -> str:
    return f"crk-{k}.so"


def packaged(units: tuple[str, ...] | None = None, folder: str | None = None) -> str | None:
    """The install-time build of these sources (``units``: their texts, read when not given), or
    None when there is none (no compiler at install time, a source checkout never installed, sources
    edited since)."""
    path = os.path.join(folder or PACKAGED, file_name(key(units)))
    return path if os.path.isfile(path) else None


def build(folder: str, build_shared, cc: str) -> tuple[str | None, str]:
    """Compile the runtime with ``cc`` into ``folder/crk-<key>.so`` (``build_shared``:
    eom/compiler.py's), removing other builds there: (its path or None, what went wrong)."""
    import shutil
    import tempfile

    units = texts()
    os.makedirs(folder, exist_ok=True)
    with tempfile.TemporaryDirectory(prefix="mechdsl-runtime-") as tmp:
        built, errors = build_shared(cc, units, [list(f) for f in RUNTIME_FLAGS], tmp)
        if built is None:
            return None, " | ".join(errors[0].splitlines()[-3:]) if errors else "no library"
        dest = os.path.join(folder, file_name(key(units)))
        part = dest + f".{os.getpid()}.part"
        shutil.copyfile(built, part)
        os.chmod(part, 0o644)
        os.replace(part, dest)
    for name in os.listdir(folder):
        if name.startswith("crk-") and name != os.path.basename(dest):
            try:
                os.remove(os.path.join(folder, name))
            except OSError:
                pass
    return dest, ""
