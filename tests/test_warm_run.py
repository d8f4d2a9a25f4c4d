"""Prepared warm runs of ``mech simulate`` (simulation/warm_run.py, issue 24 item 8): the second
run of a command gives the same output, CSV and sidecar as the normal path, without importing
CasADi; another option or an edited file is another run."""
from __future__ import annotations

import json
import os
import re
import subprocess
import sys

import pytest

from conftest import MODELS, needs_cc

RUN = ("import sys; from mechdsl.cli import main; code = main(sys.argv[1:]); "
       "print('CASADI' if 'casadi' in sys.modules else 'NO-CASADI', 'NUMPY' if 'numpy' in sys.modules else 'NO-NUMPY', "
       "file=sys.stderr); sys.exit(code)")
TIMES = re.compile(r"[0-9.e+-]+ s (CPU|wall)")


def mech(cache, *args, cwd):
    env = dict(os.environ, MECHDSL_CACHE=str(cache))
    p = subprocess.run([sys.executable, "-c", RUN, *args], capture_output=True, text=True, env=env, cwd=cwd)
    assert p.returncode == 0, p.stderr
    return p.stdout, p.stderr


def without_times(doc: dict) -> dict:
    for k in ("cpu_time", "wall_time", "error_estimate_cpu_time"):
        doc["stats"].pop(k)
    return doc


@needs_cc
def test_second_run_is_the_same_run_without_casadi(tmp_path):
    model = tmp_path / "chain.mech"
    model.write_text((MODELS / "nlink_pendulum.mech").read_text())
    cache = tmp_path / "cache"
    args = ("simulate", "chain.mech", "--set", "N=4", "--t-end", "2", "--no-progress")
    out1, err1 = mech(cache, *args, "-o", "a.csv", cwd=tmp_path)
    assert "CASADI" in err1.split()
    assert len(os.listdir(cache / "runs")) == 1
    out2, err2 = mech(cache, *args, "-o", "b.csv", cwd=tmp_path)
    assert "NO-CASADI" in err2.split()                 # the prepared run: no CasADi, no model loaded,
    assert "NO-NUMPY" in err2.split()                  # no numpy (plain buffers: the same bytes)
    assert (tmp_path / "a.csv").read_bytes() == (tmp_path / "b.csv").read_bytes()
    assert "error estimate:" in out2 and "energy drift" in out2 and "ran: ode problem" in out2
    # the normal path on a warm cache (the entry removed): the same sidecar and summary (the first run
    # differs only in its note that it compiled the model)
    for f in os.listdir(cache / "runs"):
        os.remove(cache / "runs" / f)
    out3, err3 = mech(cache, *args, "-o", "c.csv", cwd=tmp_path)
    assert "CASADI" in err3.split()
    assert (tmp_path / "c.csv").read_bytes() == (tmp_path / "a.csv").read_bytes()
    b = without_times(json.loads((tmp_path / "b.json").read_text()))
    c = without_times(json.loads((tmp_path / "c.json").read_text()))
    assert b == c
    assert b["metadata"]["accuracy"]["error_estimate"] > 0 and b["stats"]["energy_drift"] >= 0
    assert TIMES.sub("", out3).replace("c.", "b.") == TIMES.sub("", out2)
    assert TIMES.sub("", out1).split("note:")[0] == TIMES.sub("", out2).split("note:")[0]


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
@needs_cc
def test_other_options_or_text_are_other_runs(tmp_path):
    model = tmp_path / "chain.mech"
    model.write_text((MODELS / "nlink_pendulum.mech").read_text())
    cache = tmp_path / "cache"
    args = ("simulate", "chain.mech", "--set", "N=3", "--no-progress")
    mech(cache, *args, "--t-end", "1", cwd=tmp_path)
    _, err = mech(cache, *args, "--t-end", "1.5", cwd=tmp_path)
    assert "CASADI" in err.split()                     # another end time: not the prepared run
    _, err = mech(cache, *args, "--t-end", "1", "--error-estimate", "off", cwd=tmp_path)
    assert "CASADI" in err.split()
    model.write_text(model.read_text() + "\n")
    out, err = mech(cache, *args, "--t-end", "1", cwd=tmp_path)
    assert "CASADI" in err.split()                     # the file changed
    out2, err = mech(cache, *args, "--t-end", "1", cwd=tmp_path)
    assert "NO-CASADI" in err.split()
    assert TIMES.sub("", out) == TIMES.sub("", out2)


def test_plain_figures_are_numpys():
    """The replay's plain-Python figures (difference.report's max/argmax/division, accuracy.note_plain)
    follow numpy's rules on the same floats, nan, inf and zeros included: the same numbers."""
    from array import array

    import numpy as np

    from mechdsl.simulation import accuracy as A
    from mechdsl.simulation import difference as D

    rng = np.random.default_rng(7)
    cases = [rng.normal(size=6), np.array([1.0, 3.0, 3.0, 2.0]), np.array([0.0, np.inf, 1.0, np.inf]),
             np.array([1.0, np.nan, 5.0, np.nan]), np.array([-0.0, 0.0]), np.array([2.0])]
    for a in cases:
        xs = a.tolist()
        assert D._argmax(xs) == int(np.argmax(a))
        m, ref = D._max(xs), float(a.max())
        assert (m != m and ref != ref) or m == ref
    with np.errstate(divide="ignore", invalid="ignore"):
        for a, b in [(1.0, 0.0), (-1.0, 0.0), (0.0, 0.0), (1.0, -0.0), (np.nan, 0.0), (3.0, 7.0), (np.inf, 0.0)]:
            got, ref = D._div(a, b), float(np.float64(a) / np.float64(b))
            assert (got != got and ref != ref) or got == ref
    block = rng.normal(size=(3, 50)) * [[1e-3], [1.0], [1e5]]
    rows = [array("d", r.tolist()) for r in block]
    assert A.note_plain(rows)
    plain = [A._facts(v) for v in rows]
    views = list(block)
    A.note_facts(block, views)
    assert plain == [A._facts(v) for v in views]
    assert not A.note_plain([array("d", [1.0, float("nan")])])


def test_a_payload_that_needs_numpy_is_not_used(tmp_path, monkeypatch):
    """A prepared run is plain data: one holding a numpy value (another writer) is refused on read
    (the normal path runs) rather than importing numpy; the plain one reads back."""
    from array import array

    import numpy as np

    from mechdsl.simulation import warm_run

    monkeypatch.setenv("MECHDSL_CACHE", str(tmp_path))
    plain = {"run": {"loop": {"runtime": None}}, "companion": None, "grid": array("d", [0.0, 1.0])}
    assert warm_run.write("a" * 64, plain)
    assert warm_run.read("a" * 64)["grid"] == array("d", [0.0, 1.0])
    assert warm_run.write("b" * 64, {**plain, "grid": np.array([0.0, 1.0])})
    assert warm_run.read("b" * 64) is None
