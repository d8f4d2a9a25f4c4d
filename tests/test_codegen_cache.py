"""The compiled-code cache (codegen.compile_functions, cache_dir()) verifies what it loads.

A truncated cached library used to kill the next run with SIGBUS (exit 135, no message) and
was never rebuilt; another library placed under the right name was loaded and gave wrong
numbers.  The build records the library's SHA-256 in a sidecar (`<hash>.sha256`, written
atomically); a load checks it and rebuilds on a mismatch, with a note.

Each build and load runs in a subprocess: a library truncated under a process that has it
mapped would kill that process (pytest) too.
"""
from __future__ import annotations

import hashlib
import json
import math
import os
import subprocess
import sys
from pathlib import Path

import pytest

from conftest import needs_cc

pytestmark = needs_cc

# build (or load) the compiled energy of a pendulum and evaluate it at one state.  The "other"
# model is a pendulum whose potential has the opposite sign: a valid library with the same
# function name and signature that gives other numbers.
SCRIPT = """
import json, sys
import casadi as ca
sys.path.insert(0, {tests!r})
from sim_models import _syms, pendulum
from mechdsl import eom as E
from mechdsl.eom.codegen import _build, compile_functions
if {other!r}:
    q, qd, t, p = _syms(1, 3)
    e = E.from_lagrangian("Other", ["theta"], ["m", "L", "g"], [1.0, 1.0, 9.81], q, qd, t, p,
                          0.5*p[0]*p[1]**2*qd[0]**2, p[0]*p[2]*p[1]*ca.cos(q[0]), q0=[0.0])
else:
    e = pendulum()
funcs, note, lib = compile_functions([_build(e, "energy", None)], jacobian=False)
value = float(funcs["energy"](0.0, [0.7, -1.3], [], e.param_values)[2])  # (t, x, u, p) -> (T, V, E)
print(json.dumps(dict(note=note, lib=lib, value=value)))
"""
# the closed form of the pendulum's energy (sim_models.pendulum: m = L = 1, g = 9.81)
ENERGY = 0.5*1.0*1.0**2*(-1.3)**2 - 1.0*9.81*1.0*math.cos(0.7)


def build(cache: Path, other: bool = False) -> dict:
    env = {k: v for k, v in os.environ.items() if k not in ("MECHDSL_CACHE", "XDG_CACHE_HOME")}
    env["XDG_CACHE_HOME"] = str(cache)
    p = subprocess.run([sys.executable, "-c", SCRIPT.format(tests=str(Path(__file__).parent), other=other)],
                       capture_output=True, text=True, timeout=120, env=env)
    assert p.returncode == 0, f"exit {p.returncode}: {p.stderr[-2000:]}"
    return json.loads(p.stdout.strip().splitlines()[-1])


def test_cache_hit_is_verified(tmp_path):
    first = build(tmp_path)
    lib = Path(first["lib"])
    assert lib.parent == tmp_path / "mechdsl" and first["note"].startswith("compiled ")
    assert lib.with_suffix(".sha256").read_text().split()[0] == hashlib.sha256(lib.read_bytes()).hexdigest()
    assert first["value"] == pytest.approx(ENERGY, rel=1e-12)
    second = build(tmp_path)
    assert second["note"] == f"loaded compiled model from cache {lib}"
    assert second["value"] == pytest.approx(ENERGY, rel=1e-12)


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
def test_truncated_library_is_rebuilt(tmp_path):
    lib = Path(build(tmp_path)["lib"])
    data = lib.read_bytes()
    lib.write_bytes(data[: len(data) // 3])  # what a full disk or a killed copy leaves
    again = build(tmp_path)  # used to die of SIGBUS (exit 135) here, and on every later run
    assert "does not match its recorded content hash" in again["note"] and "rebuilt" in again["note"]
    assert again["value"] == pytest.approx(ENERGY, rel=1e-12)
    assert build(tmp_path)["note"].startswith("loaded compiled model from cache")


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
def test_other_library_under_the_right_name_is_rebuilt(tmp_path):
    lib = Path(build(tmp_path)["lib"])
    other = build(tmp_path / "other", other=True)
    assert other["value"] != pytest.approx(ENERGY, rel=1e-3)  # it really computes something else
    lib.write_bytes(Path(other["lib"]).read_bytes())
    again = build(tmp_path)  # used to load it and return the other model's numbers
    assert "rebuilt" in again["note"]
    assert again["value"] == pytest.approx(ENERGY, rel=1e-12)


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
def test_library_without_recorded_hash_is_rebuilt(tmp_path):
    lib = Path(build(tmp_path)["lib"])
    lib.with_suffix(".sha256").unlink()
    again = build(tmp_path)
    assert "has no recorded content hash" in again["note"] and "rebuilt" in again["note"]
    assert lib.with_suffix(".sha256").exists() and again["value"] == pytest.approx(ENERGY, rel=1e-12)
