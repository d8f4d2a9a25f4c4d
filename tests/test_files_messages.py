"""Files and messages: created files follow the umask, nothing foreign is replaced without being
asked, outputs are checked before the run, a write that fails keeps the results, a CSV and its
sidecar belong together, API errors carry the CLI's located text."""
from __future__ import annotations

import errno
import hashlib
import json
import os
import stat

import pytest

import mechdsl
from mechdsl.cli import main
from mechdsl.diagnostics import UsageError
from test_sim_cli import files  # noqa: F401 - the fixture: pendulum.mech and blowup.mech in a fresh folder


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
@pytest.mark.parametrize("mask", [0o022, 0o077, 0o002])
def test_created_files_follow_the_umask(files, mask):
    old = os.umask(mask)
    try:
        assert main(["simulate", "pendulum.mech", "--t-end", "0.2", "--points", "3", "-o", "p.csv",
                     "--plot", "p.svg"]) == 0
    finally:
        os.umask(old)
    for name in ("p.csv", "p.json", "p.svg"):
        assert stat.S_IMODE((files / name).stat().st_mode) == 0o666 & ~mask, name


def test_replaced_file_keeps_its_mode(files):
    assert main(["simulate", "pendulum.mech", "--t-end", "0.2", "-o", "p.csv"]) == 0
    os.chmod(files / "p.csv", 0o640)
    assert main(["simulate", "pendulum.mech", "--t-end", "0.3", "-o", "p.csv"]) == 0   # own output: replaced
    assert stat.S_IMODE((files / "p.csv").stat().st_mode) == 0o640


def test_result_to_csv_does_not_replace_a_foreign_file(files):
    r = mechdsl.load("pendulum.mech").simulate(0.2, points=3)
    (files / "mine.csv").write_text("my data\n")
    with pytest.raises(UsageError, match="was not written by mechdsl"):
        r.to_csv("mine.csv")
    assert (files / "mine.csv").read_text() == "my data\n"
    r.to_csv("mine.csv", overwrite=True)
    assert (files / "mine.csv").read_text().startswith("time,")
    r.to_csv("mine.csv")                      # now mechdsl's own output: a rerun replaces it


def test_sidecar_names_the_csv_it_belongs_to(files):
    r = mechdsl.load("pendulum.mech").simulate(0.2, points=3)
    r.to_csv("a.csv")
    meta = json.loads((files / "a.json").read_text())
    assert meta["csv_sha256"] == hashlib.sha256((files / "a.csv").read_bytes()).hexdigest()


def test_outputs_are_checked_before_the_run(files, capsys):
    assert main(["simulate", "pendulum.mech", "-o", "p.csv", "--plot", "p.jpg"]) == 2
    assert "figure file must end in" in capsys.readouterr().err
    assert not (files / "p.csv").exists()
    assert main(["simulate", "pendulum.mech", "-o", "missing/p.csv"]) == 2
    assert "does not exist" in capsys.readouterr().err and not (files / "missing").exists()


def test_a_failed_write_keeps_the_results(files, monkeypatch, capsys):
    """A full disk at the end of a run: the results go to a fresh temporary folder, said so, exit 1."""
    real = os.replace

    def full_disk(src, dst):
        if str(files) in os.path.abspath(str(dst)):
            raise OSError(errno.ENOSPC, "No space left on device")
        return real(src, dst)

    monkeypatch.setattr(os, "replace", full_disk)
    assert main(["simulate", "pendulum.mech", "--t-end", "0.2", "--points", "3", "-o", "p.csv"]) == 1
    captured = capsys.readouterr()
    assert "could not write p.csv (No space left on device); wrote" in captured.err
    alt = captured.err.split("wrote ")[1].split(" instead")[0]
    assert open(alt).read().startswith("time,") and not (files / "p.csv").exists()
    assert not [f for f in os.listdir(files) if f.startswith(".")]      # no temporary files left behind


def test_failure_before_the_first_output_point(files, capsys):
    """u'' = u^3 from u = 1e6 (u' ~ 0) blows up at t* = sqrt(2)/u0 * int_1^inf dx/sqrt(x^4 - 1)
    = 1.854e-6 s, long before the first output point; the integrator stops at or after t*."""
    assert main(["simulate", "blowup.mech", "--set", "u.start=1e6", "--t-end", "1", "--points", "11"]) == 1
    out = capsys.readouterr().out
    assert "t = 0 .. 0 s" not in out
    assert "no output point after the start t = 0 s was reached" in out
    t_fail = float(out.split("FAILED at t = ")[1].split(":")[0])
    assert 1.85e-6 <= t_fail <= 3e-6
    assert "last good state there: u = 1e+06, der(u) = 0.707107" in out


def test_api_errors_carry_the_located_text():
    with pytest.raises(mechdsl.MechError) as e:
        mechdsl.loads("model A\n  parameter Real m = q;\nend A;\n", filename="a.mech")
    text = str(e.value)
    assert text.startswith("a.mech:2:22: error[E201]: undefined name 'q'")
    assert "parameter Real m = q;" in text and "^" in text and "help:" in text
