"""Every shipped model under every command (issue 11): each cell exits 0, or exits 1 with a
located, coded diagnostic (``file:line:col: error[E...]`` on stderr); never exit 3 (an
internal error), never a traceback, never a hang.

The cheap cells (check, compile --emit ...) run in the default test run, in this process
under an alarm; the others run each in its own ``python -m mechdsl`` process with a
timeout and are marked slow (``python -m pytest -m slow tests/test_matrix.py``).
"""
from __future__ import annotations

import os
import re
import signal
import subprocess
import sys

import pytest

from mechdsl.cli import main

from conftest import MODELS, model_files

MODEL_FILES = model_files()
CHEAP = [("check",), ("compile", "--emit", "ast"), ("compile", "--emit", "source"), ("compile", "--emit", "model"),
         ("compile", "--emit", "eom")]
EXPENSIVE = [("simulate",), ("simulate", "--plot", "{tmp}/plot.png"), ("equations",), ("equations", "--latex"),
             ("equations", "--hamiltonian"), ("equilibrium",), ("linearize",), ("bench",)]
CHEAP_TIMEOUT = 60          # s, a cell in this process
TIMEOUT = {"bench": 300}    # s, a cell in its own process (default below)
DEFAULT_TIMEOUT = 180
LOCATED = re.compile(r"^\S+:\d+:\d+: error\[E\d{3}\]: ", re.M)


def check_cell(code: int, out: str, err: str, what: str) -> None:
    assert code != 3 and "internal error" not in err, f"{what}: internal error\n{err}"
    assert "Traceback" not in err + out, f"{what}: a traceback\n{err}"
    if code == 0:
        return
    assert code == 1, f"{what}: exit {code}\n{err}"
    assert LOCATED.search(err), f"{what}: exit 1 without a located, coded diagnostic on stderr\n{err}\n{out[-2000:]}"


class _Hang(Exception):
    pass


def _alarm(signum, frame):
    raise _Hang


def _ids(cells):
    return [" ".join(c) for c in cells]


@pytest.mark.slow_cases('nfourbar-check')  # CPU budget: the cheaper tests of this file stay in the default run
@pytest.mark.parametrize("cmd", CHEAP, ids=_ids(CHEAP))
@pytest.mark.parametrize("path", MODEL_FILES, ids=[p.stem for p in MODEL_FILES])
def test_cheap_cell(path, cmd, capsys):
    what = f"mech {cmd[0]} {path.name} {' '.join(cmd[1:])}"
    old = signal.signal(signal.SIGALRM, _alarm)
    signal.alarm(CHEAP_TIMEOUT)
    try:
        code = main([cmd[0], str(path), *cmd[1:]])
    except _Hang:
        pytest.fail(f"{what}: no answer within {CHEAP_TIMEOUT} s")
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, old)
    cap = capsys.readouterr()
    check_cell(code, cap.out, cap.err, what)


@pytest.mark.slow
@pytest.mark.parametrize("cmd", EXPENSIVE, ids=_ids(EXPENSIVE))
@pytest.mark.parametrize("path", MODEL_FILES, ids=[p.stem for p in MODEL_FILES])
def test_expensive_cell(path, cmd, tmp_path):
    args = [a.format(tmp=tmp_path) for a in cmd]
    what = f"mech {args[0]} {path.name} {' '.join(args[1:])}"
    timeout = TIMEOUT.get(cmd[0], DEFAULT_TIMEOUT)
    env = dict(os.environ, MPLBACKEND="Agg")
    env.pop("MECHDSL_DEBUG", None)
    try:
        p = subprocess.run([sys.executable, "-m", "mechdsl", args[0], str(path), *args[1:]], cwd=tmp_path, env=env,
                           capture_output=True, text=True, timeout=timeout, stdin=subprocess.DEVNULL)
    except subprocess.TimeoutExpired:
        pytest.fail(f"{what}: no answer within {timeout} s")
    check_cell(p.returncode, p.stdout, p.stderr, what)
    if p.returncode == 0 and "--plot" in args:
        assert (tmp_path / "plot.png").stat().st_size > 0, what


def test_matrix_covers_every_shipped_model():
    assert len(MODEL_FILES) >= 19 and all(p.parent == MODELS for p in MODEL_FILES)
