"""Issue 25, caches: an entry is checked against its full key, a bad entry is rebuilt, and a
cache folder or entry that another user owns or can write is never read (as ssh treats a key
file with loose permissions): one line says so and the run goes on without it.

The later runs are separate processes (as a user's next command), so nothing in memory helps.
"""
from __future__ import annotations

import json
import os
import pickle
import subprocess
import sys
from pathlib import Path

import pytest

from conftest import MODELS, drop_prepared_runs, needs_cc


def run(cache: Path, *args, env=None, check=True):
    e = dict(os.environ, MECHDSL_CACHE=str(cache))
    e.pop("MECHDSL_DEBUG", None)
    e.update(env or {})
    p = subprocess.run([sys.executable, "-m", "mechdsl", *map(str, args)], capture_output=True, text=True,
                       env=e, timeout=600)
    if check:
        assert p.returncode == 0, p.stdout + p.stderr
    return p


def python(cache: Path, code: str, env=None):
    e = dict(os.environ, MECHDSL_CACHE=str(cache))
    e.pop("MECHDSL_DEBUG", None)
    e.update(env or {})
    p = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=e, timeout=600)
    assert p.returncode == 0, p.stdout + p.stderr
    return p


def cache_key(cache: Path, path: Path) -> str:
    """The model cache's key of ``path``, its entry (the resolved model) written into ``cache``.
    In this process (a subprocess cost 0.6 s a key): only the runs after it are the subject."""
    import mechdsl

    before = os.environ.get("MECHDSL_CACHE")
    os.environ["MECHDSL_CACHE"] = str(cache)
    try:
        key = mechdsl.load(path)._cache.key
    finally:
        os.environ["MECHDSL_CACHE"] = before if before is not None else ""
        if before is None:
            del os.environ["MECHDSL_CACHE"]
    assert (cache / "models" / f"{key}.pkl").exists()
    return key


# ------------------------------------------------------------------ the model cache


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
def test_a_swapped_model_cache_entry_is_not_served(tmp_path):
    """Another model's entry under this model's name printed "model Pendulum" for the double
    pendulum and wrote the pendulum's results, exit 0, on every run."""
    cache = tmp_path / "cache"
    k_dp = cache_key(cache, MODELS / "double_pendulum.mech")
    k_p = cache_key(cache, MODELS / "pendulum.mech")
    models = cache / "models"
    (models / f"{k_dp}.pkl").write_bytes((models / f"{k_p}.pkl").read_bytes())
    out = tmp_path / "dp.csv"
    p = run(cache, "simulate", MODELS / "double_pendulum.mech", "--t-end", "0.01", "--points", "3",
            "--no-progress", "-o", out)
    assert "DoublePendulum" in p.stdout and "model Pendulum" not in p.stdout, p.stdout
    assert out.read_text().splitlines()[0].startswith("time,j1.phi,j2.phi"), out.read_text()[:200]
    # rebuilt: the entry under the double pendulum's key is the double pendulum's again
    code = (f"from mechdsl.eom import modelcache; e = modelcache.read({k_dp!r}); print(e.model.name)")
    assert python(cache, code).stdout.strip() == "DoublePendulum"


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
def test_every_cache_miss_says_why_under_mechdsl_debug(tmp_path):
    cache = tmp_path / "cache"
    p = run(cache, "simulate", MODELS / "pendulum.mech", "--t-end", "0.01", "--points", "3", "--no-progress",
            env={"MECHDSL_DEBUG": "1"})
    assert "model cache: miss" in p.stderr and "no entry" in p.stderr, p.stderr
    k = cache_key(cache, MODELS / "pendulum.mech")
    path = cache / "models" / f"{k}.pkl"
    path.write_bytes(path.read_bytes()[:-10])
    drop_prepared_runs(cache)                  # (the same command again would be the prepared run)
    p = run(cache, "simulate", MODELS / "pendulum.mech", "--t-end", "0.01", "--points", "3", "--no-progress",
            env={"MECHDSL_DEBUG": "1"})
    assert "model cache: miss" in p.stderr and "hash" in p.stderr, p.stderr
    p = run(cache, "check", "-v", MODELS / "pendulum.mech")
    assert "cache" in p.stderr, p.stderr


# ------------------------------------------------------------------ the first-integrals cache


def _integral_entries(cache: Path) -> list[Path]:
    return sorted((cache / "integrals").iterdir())


# "swapped" (another model's entry, the case that gave wrong results) in the default run; the
# other damages are the same contract, in the slow set (test budget, docs/internals.md)
@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
@pytest.mark.parametrize("damage", [pytest.param("empty", marks=pytest.mark.slow),
                                    pytest.param("garbage", marks=pytest.mark.slow), "swapped"])
def test_a_bad_first_integrals_entry_is_rebuilt(tmp_path, damage):
    """An empty or swapped entry gave an internal error on every later run, never rebuilt."""
    cache = tmp_path / "cache"
    args = ("--t-end", "0.05", "--points", "3", "--no-progress", "--method", "erk")
    run(cache, "simulate", MODELS / "heavy_top.mech", *args, "-o", tmp_path / "a.csv")
    (top,) = _integral_entries(cache)
    good = top.read_bytes()
    if damage == "empty":
        top.write_bytes(b"")
    elif damage == "garbage":
        top.write_bytes(good[: len(good) // 2])
    else:
        run(cache, "simulate", MODELS / "pendulum.mech", *args, "-o", tmp_path / "p.csv")
        (other,) = [p for p in _integral_entries(cache) if p != top]
        top.write_bytes(other.read_bytes())
        other.write_bytes(good)
    for path in (MODELS / "heavy_top.mech", MODELS / "pendulum.mech"):
        out = tmp_path / f"{path.stem}.csv"
        p = run(cache, "simulate", path, *args, "-o", out, "--force")
        assert "internal error" not in p.stderr
    header = (tmp_path / "heavy_top.csv").read_text().splitlines()[0]
    assert "p_tip.phi" in header, header
    assert top.read_bytes() == good            # rebuilt: the same entry as the first run wrote


# ------------------------------------------------------------------ trust: owners and permissions


class Boom:
    """A pickle that runs code when loaded (what a planted cache entry could do)."""

    def __init__(self, marker):
        self.marker = marker

    def __reduce__(self):
        return (os.system, (f"touch {self.marker}",))


def _plant_model_entry(cache: Path, key: str, marker: Path) -> Path:
    """A model-cache entry with a valid header (format, key, hash) whose payload runs code."""
    from mechdsl.eom import modelcache

    payload = pickle.dumps(Boom(marker))
    path = cache / "models" / f"{key}.pkl"
    head = modelcache.header(key, payload)
    path.write_bytes(head + payload)
    return path


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
def test_a_cache_folder_others_can_write_is_never_read(tmp_path):
    cache = tmp_path / "cache"
    k = cache_key(cache, MODELS / "pendulum.mech")
    marker = tmp_path / "pwned"
    _plant_model_entry(cache, k, marker)
    os.chmod(cache / "models", 0o777)
    p = run(cache, "simulate", MODELS / "pendulum.mech", "--t-end", "0.01", "--points", "3", "--no-progress")
    assert not marker.exists(), "a planted cache entry ran code"
    notes = [ln for ln in p.stderr.splitlines() if "cache" in ln]
    assert len(notes) == 1 and "writable by other users" in notes[0] and str(cache / "models") in notes[0], p.stderr
    assert "model Pendulum" in p.stdout


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
def test_a_cache_entry_others_can_write_is_never_read(tmp_path):
    cache = tmp_path / "cache"
    k = cache_key(cache, MODELS / "pendulum.mech")
    marker = tmp_path / "pwned"
    path = _plant_model_entry(cache, k, marker)
    os.chmod(path, 0o666)
    p = run(cache, "simulate", MODELS / "pendulum.mech", "--t-end", "0.01", "--points", "3", "--no-progress")
    assert not marker.exists(), "a planted cache entry ran code"
    notes = [ln for ln in p.stderr.splitlines() if "cache" in ln]
    assert len(notes) == 1 and "writable by other users" in notes[0], p.stderr


def test_a_cache_owned_by_another_user_is_never_read(tmp_path, monkeypatch, caplog):
    """As if another user owned the folder (the process pretends to be someone else)."""
    import mechdsl
    from mechdsl.eom import cachefiles, modelcache

    cache = tmp_path / "cache"
    monkeypatch.setenv("MECHDSL_CACHE", str(cache))
    m = mechdsl.load(MODELS / "pendulum.mech")
    m.eom
    key = m._cache.key
    assert modelcache.read(key) is not None
    me = os.geteuid()
    monkeypatch.setattr(cachefiles, "_euid", lambda: me + 1)
    monkeypatch.setattr(cachefiles, "_WARNED", set())
    with caplog.at_level("WARNING", logger="mechdsl.cache"):
        assert modelcache.read(key) is None
        assert modelcache.read(key) is None
    said = [r.getMessage() for r in caplog.records if r.name == "mechdsl.cache"]
    assert len(said) == 1 and "owned by another user" in said[0], said


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
def test_new_cache_folders_and_entries_are_private(tmp_path):
    """Created 0700 / 0600 whatever the umask, so a group-writable umask (002) does not make
    mechdsl refuse its own cache."""
    cache = tmp_path / "cache"
    code = ("import os; os.umask(0o002); import mechdsl; m = mechdsl.load(%r); m.simulate(0.01, points=3)"
            % str(MODELS / "pendulum.mech"))
    python(cache, code)
    for p in [cache, *cache.rglob("*")]:
        mode = p.stat().st_mode & 0o777
        assert mode & 0o077 == 0, (p, oct(mode))


MALICIOUS_C = r"""
#include <stdio.h>
#include <stdlib.h>
__attribute__((constructor)) static void boom(void) {
    const char *m = getenv("MECHDSL_TEST_MARKER");
    if (m) { FILE *f = fopen(m, "w"); if (f) fclose(f); }
}
"""

COMPILE = """
import json, logging, sys
logging.basicConfig(format="%(levelname)s: %(message)s")   # the library's warnings, as an application shows them
sys.path.insert(0, {tests!r})
from sim_models import pendulum
from mechdsl.eom.codegen import _build, compile_functions
e = pendulum()
funcs, note, lib = compile_functions([_build(e, "energy", None)], jacobian=False)
value = float(funcs["energy"](0.0, [0.7, -1.3], [], e.param_values)[2]) if funcs else None
print(json.dumps(dict(note=note, lib=lib, value=value)))
"""


def _compile(cache: Path, marker: Path) -> tuple[dict, str]:
    code = COMPILE.format(tests=str(Path(__file__).parent))
    p = python(cache, code, env={"MECHDSL_TEST_MARKER": str(marker)})
    return json.loads(p.stdout.strip().splitlines()[-1]), p.stderr


def _plant_library(tmp_path: Path, lib: Path) -> None:
    """A library whose constructor runs code, under the right name, with the content hash of
    the old sidecar format (a hash of the file alone)."""
    import hashlib

    src = tmp_path / "evil.c"
    src.write_text(MALICIOUS_C)
    evil = tmp_path / "evil.so"
    subprocess.run(["cc", "-shared", "-fPIC", str(src), "-o", str(evil)], check=True)
    lib.write_bytes(evil.read_bytes())
    lib.with_suffix(".sha256").write_text(hashlib.sha256(evil.read_bytes()).hexdigest() + "\n")


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
@needs_cc
def test_a_planted_library_with_its_file_hash_is_not_loaded(tmp_path):
    cache, marker = tmp_path / "cache", tmp_path / "pwned"
    first, _ = _compile(cache, marker)
    _plant_library(tmp_path, Path(first["lib"]))
    again, _ = _compile(cache, marker)
    assert not marker.exists(), "a planted library's constructor ran"
    assert again["value"] == pytest.approx(first["value"], rel=1e-12)
    assert "rebuilt" in again["note"]


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
@needs_cc
def test_a_library_in_a_folder_others_can_write_is_not_loaded(tmp_path):
    cache, marker = tmp_path / "cache", tmp_path / "pwned"
    first, _ = _compile(cache, marker)
    lib = Path(first["lib"])
    _plant_library(tmp_path, lib)
    os.chmod(cache, 0o777)
    again, err = _compile(cache, marker)
    assert not marker.exists(), "a library in a folder others can write was loaded"
    assert again["value"] == pytest.approx(first["value"], rel=1e-12)
    notes = [ln for ln in err.splitlines() if "cache" in ln]
    assert len(notes) == 1 and "writable by other users" in notes[0], err
