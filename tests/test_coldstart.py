"""Cold start (issues 12 and 16): what a fresh ``mech`` process imports.  Times are measured in
benchmarks/coldstart.py, never here; these tests check the imports that must not happen."""
import os
import subprocess
import sys

import numpy as np
import pytest

from conftest import MODELS, drop_prepared_runs


def imported(*args, env=None):
    r = subprocess.run([sys.executable, "-X", "importtime", "-m", "mechdsl", *args], capture_output=True,
                       text=True, env=env)
    names = {line.rsplit("|", 1)[-1].strip() for line in r.stderr.splitlines() if line.startswith("import time")}
    return r, names


def imported_by_numpy_and_casadi():
    """What ``import numpy, casadi`` alone brings in with the installed versions (older numpy
    imports numpy.ma and secrets itself): not mechdsl's to avoid."""
    r = subprocess.run([sys.executable, "-c", "import sys, numpy, casadi; print(chr(10).join(sys.modules))"],
                       capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    return set(r.stdout.split())


def test_version_imports_no_command_and_no_numpy():
    r, names = imported("--version")
    assert r.returncode == 0 and r.stdout.strip().startswith("mechdsl ")
    assert "mechdsl.cli" in names                      # the check sees the imports
    assert not {"numpy", "casadi", "lark", "mechdsl.commands.simulate", "mechdsl.commands.bench"} & names


def test_a_run_imports_neither_scipy_nor_secrets_nor_subprocess(tmp_path):
    """A warm run: scipy's version is read from its version.py; fileio names temporary files
    without secrets; codegen imports subprocess and tempfile only to compile."""
    env = {**os.environ, "MECHDSL_CACHE": str(tmp_path)}
    args = ("simulate", str(MODELS / "pendulum.mech"), "--t-end", "0.1", "--points", "3", "--no-progress",
            "-o", str(tmp_path / "r.csv"), "--force")
    imported(*args, env=env)                    # the first run fills the model cache
    r, prepared = imported(*args, env=env)      # the prepared warm run (simulation/warm_run.py)
    assert r.returncode == 0, r.stderr[-2000:]
    assert "mechdsl.simulation.warm_run" in prepared and "casadi" not in prepared
    drop_prepared_runs(tmp_path)
    r, names = imported(*args, env=env)         # the normal path through the model cache
    assert r.returncode == 0, r.stderr[-2000:]
    assert "mechdsl.simulation.backends.ode" in names
    unwanted = {"scipy", "secrets", "subprocess", "tempfile", "difflib", "mechdsl.output.display", "numpy.ma", "shutil"}
    assert unwanted & (names | prepared) - imported_by_numpy_and_casadi() == set()


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
def test_a_warm_compiled_run_starts_no_process(tmp_path):
    """Issue 12's command, compiled stepping loop loaded from the cache: the compiler's version
    is remembered (codegen.compiler_version) and its path found without shutil, so the run
    imports neither subprocess nor tempfile nor shutil (with lzma and bz2)."""
    env = {**os.environ, "MECHDSL_CACHE": str(tmp_path)}
    args = ("simulate", str(MODELS / "double_pendulum.mech"), "--no-progress", "-o", str(tmp_path / "r.csv"),
            "--force")
    imported(*args, "--compiled", env=env)      # fills the model cache and compiles (a run without
    #                                             --compiled loads that library: crk.build_loop(rent=True))
    drop_prepared_runs(tmp_path)                # (the normal path: model cache and compiled library)
    r, names = imported(*args, env=env)
    assert r.returncode == 0, r.stderr[-2000:]
    assert "loaded compiled model from cache" in r.stdout + r.stderr
    assert {"subprocess", "tempfile", "shutil", "lzma", "bz2"} & names - imported_by_numpy_and_casadi() == set()
    assert "mechdsl.model.ir" in names and "mechdsl.frontend.parser" not in names


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
def test_a_warm_run_creates_no_dataclass(tmp_path):
    """Issue 12: the classes a warm run needs (ir's for the cached model, the EOM, settings,
    problem, result...) are made by mechdsl.model.records.record, not by @dataclass (an exec per
    generated method: ~13 ms for ir alone).  The run is spied on from within: every class
    dataclasses processes is listed."""
    env = {**os.environ, "MECHDSL_CACHE": str(tmp_path)}
    args = ["simulate", str(MODELS / "pendulum.mech"), "--t-end", "0.1", "--points", "3", "--no-progress",
            "-o", str(tmp_path / "r.csv"), "--force"]
    spy = ("import dataclasses, runpy, sys, atexit\n"
           "made = []\n"
           "real = dataclasses._process_class\n"
           "def spy(cls, *a, **k):\n"
           "    made.append(cls.__module__ + '.' + cls.__qualname__)\n"
           "    return real(cls, *a, **k)\n"
           "dataclasses._process_class = spy\n"
           "atexit.register(lambda: print('DATACLASSES', made, file=sys.stderr))\n"
           f"sys.argv = ['mech', *{args!r}]\n"
           "runpy.run_module('mechdsl', run_name='__main__')\n")
    subprocess.run([sys.executable, "-m", "mechdsl", *args], capture_output=True, env=env)   # fills the cache
    for _ in ("the prepared warm run", "the normal path through the model cache"):
        r = subprocess.run([sys.executable, "-c", spy], capture_output=True, text=True, env=env)
        assert r.returncode == 0, r.stderr[-2000:]
        made = [line for line in r.stderr.splitlines() if line.startswith("DATACLASSES")]
        assert made == ["DATACLASSES []"], made
        drop_prepared_runs(tmp_path)


def test_scipy_version_without_importing_scipy(monkeypatch):
    import scipy

    from mechdsl.output.result import _scipy_version

    monkeypatch.delitem(sys.modules, "scipy")
    assert _scipy_version() == scipy.__version__
    assert "scipy" not in sys.modules


def test_median_is_numpys_without_importing_numpy_ma():
    """analysis.core.median replaces np.median (which imports numpy.ma: 11 ms of `mech check`);
    it must give numpy's value bit for bit, NaN and both parities included."""
    from mechdsl.analysis.core import median

    rng = np.random.default_rng(3)
    for n in (1, 2, 3, 4, 7, 10):
        x = list(rng.normal(size=n) * 10.0 ** rng.integers(-5, 5, size=n))
        assert median(x) == float(np.median(x))
    assert np.isnan(median([1.0, float("nan"), 2.0]))
    assert np.isnan(median([]))


def test_documented_submodules_after_a_plain_import():
    """``import mechdsl`` then ``mechdsl.examples.path(...)`` (and the other documented submodules)
    works as after ``import mechdsl.examples``: imported on first use, not by ``import mechdsl``."""
    code = ("import sys, mechdsl; before = {'mechdsl.examples', 'mechdsl.sweep'} & set(sys.modules); "
            "print(sorted(before), mechdsl.examples.path('pendulum').name, callable(mechdsl.sample.normal), "
            "callable(mechdsl.sweep.table))")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    assert r.stdout.split() == ["[]", "pendulum.mech", "True", "True"]
