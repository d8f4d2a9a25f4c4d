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


def build_shared(cc: str, units, flags, folder) -> tuple[str | None, list[str]]:
    """Compile the C texts ``units`` (``flags``: one list of options each) in ``folder`` and link
    them into one shared library: (its path ``folder/lib.so`` or None, the compiler's errors).
    Relative names in the folder (``unit<i>.c`` -> ``unit<i>.o``, compiled in parallel, then
    ``cc -shared ... -lm``): the library does not embed the folder's name, so the same sources,
    flags and compiler give the same bytes wherever they are built -- the cache's build
    (eom/codegen.py) and the install-time build of the runtime library (hatch_build.py) are
    this one function."""
    import subprocess

    folder = os.fspath(folder)
    procs, objs = [], []
    for i, (code, fl) in enumerate(zip(units, flags)):
        with open(os.path.join(folder, f"unit{i}.c"), "w") as f:
            f.write(code)
        objs.append(f"unit{i}.o")
        procs.append(subprocess.Popen([cc, *fl, "-fPIC", "-c", f"unit{i}.c", "-o", objs[-1]], cwd=folder,
                                      stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True))
    errors = []
    for pr in procs:
        out, err = pr.communicate()
        if pr.returncode != 0:
            errors.append((err or out).strip())
    if errors:
        return None, errors
    r = subprocess.run([cc, "-shared", *objs, "-o", "lib.so", "-lm"], capture_output=True, text=True, cwd=folder)
    if r.returncode != 0:
        return None, [(r.stderr or r.stdout).strip()]
    return os.path.join(folder, "lib.so"), []
