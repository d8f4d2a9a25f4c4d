import os
import shutil
import sys
import tempfile
from pathlib import Path

import pytest

# Compiled bytecode shared by every Python process of the session (this one, the `mech` and
# `python -c` subprocesses, sweep workers): one temporary folder (PYTHONPYCACHEPREFIX), removed at
# the end.  The machines run with PYTHONDONTWRITEBYTECODE=1, so every child compiled mechdsl's
# modules from source again (about a third of a warm `mech simulate`: 0.35 s of CPU against
# 0.25 s); nothing is written next to the sources or the tests.
_SESSION_PYCACHE = tempfile.mkdtemp(prefix="mechdsl-test-pycache-")


def _seed_bytecode(prefix: str) -> None:
    """Link the bytecode the installed packages already have (``<dir>/__pycache__/*.pyc`` of the
    standard library and site-packages) into ``prefix``: with a prefix set, Python looks for
    bytecode only there, so without this every module imported after this point (sympy, scipy,
    pandas, ... and the standard library's) was compiled from source again in every session
    (about 6 s of CPU for the modules a simulation imports).  A link whose source changed is
    replaced by a file in ``prefix`` when Python compiles it again; the originals are never
    written.  About 0.4 s for 7000 links; the test suites of the standard library and of the
    packages are left out."""
    skip = {"test", "tests", "idlelib", "tkinter", "lib2to3", "ensurepip", "turtledemo"}
    suffix = f".{sys.implementation.cache_tag}.pyc"
    stack = list(dict.fromkeys(os.path.abspath(p) for p in sys.path if p and os.path.isdir(p)))
    while stack:
        folder = stack.pop()
        try:
            entries = list(os.scandir(folder))
        except OSError:
            continue
        for e in entries:
            if not e.is_dir(follow_symlinks=False):
                continue
            if e.name == "__pycache__":
                target = prefix + folder          # where Python looks for the bytecode of folder/*.py
                made = False
                for f in os.scandir(e.path):
                    if f.name.endswith(suffix) and f.name.count(".") == 2:
                        try:
                            if not made:
                                os.makedirs(target, exist_ok=True)
                                made = True
                            os.symlink(f.path, os.path.join(target, f.name))
                        except OSError:
                            pass
            elif e.name not in skip and e.name != "site-packages":     # site-packages: own sys.path entry
                stack.append(e.path)


if sys.implementation.cache_tag and os.name == "posix":
    _seed_bytecode(_SESSION_PYCACHE)
sys.pycache_prefix = _SESSION_PYCACHE
sys.dont_write_bytecode = False
os.environ["PYTHONPYCACHEPREFIX"] = _SESSION_PYCACHE
os.environ.pop("PYTHONDONTWRITEBYTECODE", None)

import mechdsl.examples  # noqa: E402 - after the bytecode folder is set: its modules are compiled into it

TESTS = Path(__file__).resolve().parent
# The shipped models as the installation has them (inside the wheel, or models/ of an editable
# checkout): tests never find them through the source tree's layout, so they pass against the
# installed wheel too (.ci/run runs them from a copy of tests/ outside the repository).
MODELS = mechdsl.examples.folder()
REFERENCES = TESTS / "references"   # verbatim copies of ../shared/references
# The source checkout, for the tests that are about the repository itself (its docs/, README.md,
# benchmarks/, editors/, grammar/): the folder above tests/, or MECHDSL_CHECKOUT when the tests run
# from a copy elsewhere (.ci/run's run against the installed wheel).  Nothing the package needs
# is read from here: the installed package's own files are found through mechdsl.__file__.
CHECKOUT = Path(os.environ.get("MECHDSL_CHECKOUT") or TESTS.parent).resolve()

# deep recursion guard for pathological inputs is part of the CLI; tests call the library directly
sys.setrecursionlimit(max(sys.getrecursionlimit(), 10000))
os.environ.setdefault("MPLBACKEND", "Agg")

# the tests never read or write the user's caches (model cache, compiled libraries): one
# temporary cache folder for the session (tests that need their own set MECHDSL_CACHE themselves)
_SESSION_CACHE = tempfile.mkdtemp(prefix="mechdsl-test-cache-")
os.environ["MECHDSL_CACHE"] = _SESSION_CACHE


def drop_prepared_runs(cache) -> None:
    """Remove the prepared warm runs of ``mech simulate`` (simulation/warm_run.py) from the cache
    folder ``cache``: the next run of the same command goes the normal way (through the model
    cache), for tests of that path."""
    shutil.rmtree(os.path.join(str(cache), "runs"), ignore_errors=True)


def _has_compiler() -> bool:
    from mechdsl.eom.codegen import find_compiler

    return find_compiler() is not None


# compiled code needs a C compiler (CI's machines have gcc; a test of the fallback without one
# checks the message instead of skipping)
needs_cc = pytest.mark.skipif(not _has_compiler(), reason="no C compiler: compiled code cannot be built")


def chromium_path() -> str | None:
    """The system's Chromium (the browser tests drive it with Playwright; nothing is downloaded)."""
    for name in ("chromium", "chromium-browser", "google-chrome"):
        path = shutil.which(name)
        if path:
            return path
    return None


@pytest.hookimpl(tryfirst=True)
def pytest_collection_modifyitems(config, items):
    """``@pytest.mark.slow_cases("id", ...)`` on a parametrized test: the cases with those ids
    (the part in brackets of the test's name) are slow, the others stay in the default run (the
    test budget, docs/internals.md "Testing").  Runs before ``-m`` deselects.  An id that names
    no case of the test is an error, so a renamed case cannot drop out of the slow set unseen."""
    seen: dict = {}
    for item in items:
        mark = item.get_closest_marker("slow_cases")
        if mark is None:
            continue
        callspec = getattr(item, "callspec", None)
        case = callspec.id if callspec is not None else None
        key = (item.nodeid.split("[")[0], tuple(mark.args))
        seen.setdefault(key, set()).add(case)
        if case in mark.args:
            item.add_marker(pytest.mark.slow)
    for (name, wanted), cases in seen.items():
        missing = [w for w in wanted if w not in cases]
        # only when every case of the test was collected (not under -k or a test's node id)
        if missing and not config.option.keyword and not any("::" in str(a) for a in config.args):
            raise pytest.UsageError(f"{name}: slow_cases names no case {missing!r}")


def pytest_unconfigure(config):
    shutil.rmtree(_SESSION_CACHE, ignore_errors=True)
    shutil.rmtree(_SESSION_PYCACHE, ignore_errors=True)


@pytest.fixture
def models_dir() -> Path:
    return MODELS


def model_files():
    return sorted(MODELS.glob("*.mech"))


def run_stability_case(name: str, size: str):
    """Run case `name` of benchmarks/stability at `size` ("small" | "full"); its assertions must hold."""
    import importlib
    import sys

    if str(CHECKOUT / "benchmarks") not in sys.path:
        sys.path.insert(0, str(CHECKOUT / "benchmarks"))
    case = importlib.import_module(f"stability.{name}").run(size)
    assert case.checks, f"{name}: no checks"
    assert case.holds, "\n" + case.report()
    return case


# ----------------------------------------------------------------------------- golden files

GOLDEN_CHANGES = pytest.StashKey[list]()


def simulate_with_csv_input(tmp_path, source: str, csv_text: str, *args: str):
    """``mech simulate`` of ``source`` with input F from a CSV of ``csv_text`` (``{csv}`` in
    ``args`` is its path), written to out.csv: (exit code, header, rows as floats)."""
    from mechdsl.cli import main

    src = tmp_path / "model.mech"
    src.write_text(source)
    csv_in = tmp_path / "f.csv"
    csv_in.write_text(csv_text)
    out = tmp_path / "out.csv"
    rc = main(["simulate", str(src), *(a.format(csv=csv_in) for a in args), "-o", str(out), "--no-progress"])
    if rc != 0:
        return rc, [], []
    lines = out.read_text().splitlines()
    return rc, lines[0].split(","), [[float(v) for v in ln.split(",")] for ln in lines[1:]]


def pytest_addoption(parser):
    parser.addoption("--update-golden", action="store_true", default=False,
                     help="rewrite tests/golden/*.txt from the current output (tests/test_golden.py) "
                          "and list the files that changed")


@pytest.fixture
def update_golden(request) -> bool:
    return request.config.getoption("--update-golden")


@pytest.fixture
def golden_changes(request) -> list:
    """Where test_golden records the files it wrote or removed under --update-golden."""
    return request.config.stash.setdefault(GOLDEN_CHANGES, [])


def _cpu_seconds() -> float | None:
    """CPU time (user + system) of this process and of its waited-for children, in s (None
    where the resource module is missing: not POSIX)."""
    try:
        import resource
    except ImportError:
        return None
    own, kids = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
    return own.ru_utime + own.ru_stime + kids.ru_utime + kids.ru_stime


# The test budget (docs/internals.md, "Testing"): the default run stays under about 2 minutes of
# CPU on 2 cores.  The session's CPU is printed at the end so a change that breaks it is seen; it
# is a number to read, never a test that fails on a slow machine.
CPU_BUDGET = 120.0


def pytest_terminal_summary(terminalreporter, exitstatus, config):
    cpu = _cpu_seconds()
    if cpu is not None:
        whole_default_run = (getattr(getattr(config, "args_source", None), "name", "") == "TESTPATHS"
                             and config.option.markexpr == "not slow")
        over = ("  (over the default run's budget: make tests cheaper or mark slow work @pytest.mark.slow)"
                if whole_default_run and cpu > CPU_BUDGET else "")
        terminalreporter.write_line(f"CPU: {cpu:.0f} s (this process and its children, user + system; "
                                    f"budget about {CPU_BUDGET:.0f} s for the default run){over}")
    if not config.getoption("--update-golden"):
        return
    changes = config.stash.get(GOLDEN_CHANGES, [])
    terminalreporter.section("golden files")
    if not changes:
        terminalreporter.write_line("no golden file changed")
    for line in sorted(changes):
        terminalreporter.write_line(line)
