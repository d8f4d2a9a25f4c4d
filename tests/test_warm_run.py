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
       "print('CASADI' if 'casadi' in sys.modules else 'NO-CASADI', file=sys.stderr); sys.exit(code)")
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
    assert "NO-CASADI" in err2.split()                 # the prepared run: no CasADi, no model loaded
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
