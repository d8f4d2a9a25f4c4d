"""A hand-written C unit linked into every model's library (the compiled stepping loop, crk.c) is
compiled once and its object kept in the cache (codegen._unit_object): the next model links it
instead of compiling it again (0.4 s of gcc at -O2 each).  The library is the same, byte for byte,
as one compiled from scratch; a kept object that is not the one recorded is compiled again."""
from __future__ import annotations

import os
import subprocess
from pathlib import Path

import casadi as ca

from conftest import needs_cc
from mechdsl.eom import codegen

pytestmark = needs_cc

EXTRA = "int mechdsl_test_kept_unit(int k) { return 3 * k + 1; }\n"


def _function():
    x = ca.SX.sym("x", 2)
    return ca.Function("energy", [x], [0.5 * x[0] ** 2 + ca.cos(x[1])])


def _build(monkeypatch):
    """(library bytes, the sources gcc compiled) of one build into an empty library slot."""
    compiled = []
    real = subprocess.Popen

    def popen(args, *a, **k):
        compiled.extend(w for w in args if w.endswith(".c"))
        return real(args, *a, **k)

    monkeypatch.setattr(subprocess, "Popen", popen)
    funcs, note, lib = codegen.compile_functions([_function()], jacobian=False, extra_units=(EXTRA,))
    monkeypatch.setattr(subprocess, "Popen", real)
    assert funcs is not None and note.startswith("compiled "), note
    assert float(funcs["energy"]([1.0, 0.0])) == 1.5
    data = Path(lib).read_bytes()
    for path in (Path(lib), codegen._digest_path(Path(lib))):
        os.remove(path)                               # the next build compiles the library again
    return data, compiled


def test_a_kept_object_is_linked_and_gives_the_same_library(tmp_path, monkeypatch):
    monkeypatch.setenv("MECHDSL_CACHE", str(tmp_path))
    first, compiled = _build(monkeypatch)
    assert compiled == ["unit0.c", "unit1.c"]
    kept = list((tmp_path / "objects").glob("*.o"))
    assert len(kept) == 1 and codegen._digest_path(kept[0]).is_file()

    second, compiled = _build(monkeypatch)
    assert compiled == ["unit0.c"]                    # the hand-written unit came from the cache
    assert second == first

    kept[0].write_bytes(b"not an object")            # not what was recorded: compiled again, kept anew
    third, compiled = _build(monkeypatch)
    assert compiled == ["unit0.c", "unit1.c"] and third == first
    fourth, compiled = _build(monkeypatch)
    assert compiled == ["unit0.c"] and fourth == first
