"""The stepping loop's runtime library built at install time (hatch_build.py, runtime_lib.py;
issue 24 item 8): the same bytes as the cache's build of it, found only for the sources it was
built from, and a compile that fails never fails anything.  Times: benchmarks/first_run.py."""
import os
import shutil

import pytest

from mechdsl.eom.codegen import compile_functions
from mechdsl.eom.compiler import build_shared, find_compiler
from mechdsl.simulation.backends import crk, runtime_lib

needs_cc = pytest.mark.skipif(find_compiler() is None, reason="needs a C compiler")


@pytest.fixture(scope="module")
def installed(tmp_path_factory):
    """A folder holding the install-time build of the runtime: the installed one (a wheel or an
    editable install ran hatch_build.py), else built here as hatch_build.py builds it."""
    have = runtime_lib.packaged()
    if have is not None:
        return os.path.dirname(have)
    folder = str(tmp_path_factory.mktemp("installed"))
    path, why = runtime_lib.build(folder, build_shared, find_compiler())
    assert path is not None, why
    return folder


@needs_cc
def test_the_install_time_build_is_the_cache_build_byte_for_byte(installed, tmp_path, monkeypatch):
    monkeypatch.setenv("MECHDSL_CACHE", str(tmp_path / "cache"))
    loaded, note, path = compile_functions([], tag="crk", jacobian=False, extra_units=runtime_lib.texts(),
                                           extra_flags=crk.RUNTIME_FLAGS)
    assert loaded is not None, note
    with open(path, "rb") as a, open(runtime_lib.packaged(folder=installed), "rb") as b:
        assert a.read() == b.read()         # same texts, flags, compiler and commands (compiler.build_shared)


@needs_cc
def test_a_first_run_loads_the_installed_runtime_and_compiles_no_runtime(installed, tmp_path, monkeypatch):
    monkeypatch.setattr(runtime_lib, "PACKAGED", installed)
    monkeypatch.setattr(crk, "_RUNTIME", {})
    monkeypatch.setattr(crk, "_LIBS", {})
    monkeypatch.setenv("MECHDSL_CACHE", str(tmp_path / "cache"))
    rt, note = crk.runtime()
    assert rt is not None and rt._name == runtime_lib.packaged(folder=installed), note
    assert not list((tmp_path / "cache").glob("*.so"))         # nothing was compiled for it
    assert note == ""


def test_edited_sources_do_not_find_the_installed_build(tmp_path):
    units = runtime_lib.texts()
    k = runtime_lib.key(units)
    (tmp_path / runtime_lib.file_name(k)).write_bytes(b"")
    assert runtime_lib.packaged(units, folder=str(tmp_path)) == str(tmp_path / runtime_lib.file_name(k))
    edited = (units[0] + "\n/* edited */\n", units[1])
    assert runtime_lib.key(edited) != k
    assert runtime_lib.packaged(edited, folder=str(tmp_path)) is None
    assert runtime_lib.key(units) == k                     # deterministic


def test_a_compile_that_fails_returns_why_and_leaves_no_library(tmp_path):
    false = shutil.which("false") or "/bin/false"
    path, why = runtime_lib.build(str(tmp_path), build_shared, false)
    assert path is None and isinstance(why, str)
    assert not list(tmp_path.glob("*.so"))
