"""Whole-pipeline fuzzing: mutated shipped models through `mech check` and a short `mech simulate`.

The mutations keep the syntax valid and go for values: numbers (0, -1, 1e-320, 1e308, values
that overflow, huge integers), geometry vectors, structural sizes (Integer parameters, array
sizes) and scene settings, plus now and then a token-level mutation of tests/test_fuzz.py.
Each mutant runs `check` and `simulate --t-end 0.05 --points 5` in a forked child with a time
limit.  The property, for each command: exit 0 (and for simulate a CSV whose values are all
finite), or exit 1 with a coded error located in the file (`file:line:col: error[Exxx]` or
`file: error[Exxx]` for later phases).  Exit 2 or 3, another code, a signal, a traceback or a
timeout fails.

Default run: a few derandomized examples (CI).  The long run (`-m slow`, MECHDSL_FUZZ=<n>
examples, default 1500) collects every failure instead of stopping at the first and writes a
summary to $MECHDSL_FUZZ_REPORT (default: the test's temporary folder).
"""
from __future__ import annotations

import csv
import json
import math
import multiprocessing
import os
import re
import time
from pathlib import Path

import pytest
from hypothesis import HealthCheck, Phase, given, settings, strategies as st

from conftest import model_files
from test_fuzz import mutated_model

SEEDS = {p.name: p.read_text(encoding="utf-8") for p in model_files()}
TIME_LIMIT = 120.0      # seconds per command: a shipped model checks and runs 0.05 s in a few;
                        # a model at the coordinates budget (500) simulates 0.05 s in about 60
T_END, POINTS = "0.05", "5"

NUMBERS = ["0", "-1", "1e-320", "1e308", "1e-12", "1e12", "-0.5", "3", "1e400", "(0/0)", "(1e308*10)",
           "123456789012345678901234567890", "2", "0.001"]
VECTORS = ["{0, 0, 0}", "{1e308, 0, 0}", "{1e-320, 0, 0}", "{0, 0, -1}", "{1, 1, 1}", "{0, 1e-12, 0}",
           "{-1, 0, 0}", "{1e400, 0, 0}",
           "{1e32, 0, 1}", "{1e10, 0, 1}", "{1, 0, 1e-16}"]     # components far apart (issue 25: a hang)
SIZES = ["0", "1", "2", "3", "50", "-1", "1000", "100000", "123456789012345678901234567890"]
SETTINGS = {
    "stop_time": ["0", "-1", "1e-320", "1e308", "0.05"],
    "start_time": ["0", "-1", "-1e308"],   # later starts would conflict with --t-end (a usage error, rightly)
    "tolerance": ["0", "-1", "1e-320", "1e308", "1e-3", "1"],
    "rtol": ["0", "1e-320", "1e308"],
    "atol": ["0", "1e-320", "1e308"],
    "points": ["0", "1", "2", "1e308", "100000000"],
    "dt": ["1e-320", "1e308", "0.01", "-1"],
    "method": ['"rk4"', '"euler"', '"idas"', '"cvodes-bdf"', '"bogus"', '"symplectic"'],
    "formulation": ['"ggl"', '"baumgarte"', '"partitioning"', '"projection"', '"bogus"'],
    "rest_speed": ["0", "-1", "1e308"],
    "compiled": ["true", "false"],
}

NUMBER = re.compile(r"(?<![\w.])\d+(?:\.\d*)?(?:[eE][+-]?\d+)?(?![\w.])")
VECTOR = re.compile(r"\{[^{}\n]*,[^{}\n]*,[^{}\n]*\}")
SIZE = re.compile(r"(parameter\s+Integer\s+\w+\s*=\s*)(\d+)|(\w\[)(\d+)(\])")
JOINT = re.compile(r"^(\s*)(?:Revolute|Prismatic|Cylindrical|Planar|Spherical) (\w+)\([^;]*\);", re.M)
SETTING = re.compile(r"^(\s*)(" + "|".join(SETTINGS) + r")\s*=\s*[^;\n]*;", re.M)


def _code_only(text: str) -> str:
    """The text with comments blanked (same length), so that mutations land in code."""
    return re.sub(r"//[^\n]*|/\*.*?\*/", lambda m: re.sub(r"[^\n]", " ", m[0]), text, flags=re.S)


@st.composite
def value_mutant(draw) -> tuple[str, str, list[str]]:
    """(seed model name, mutated text, what was done)."""
    name = draw(st.sampled_from(sorted(SEEDS)))
    text = SEEDS[name]
    done = []
    for _ in range(draw(st.integers(1, 3))):
        op = draw(st.sampled_from(["number", "number", "vector", "size", "setting", "add_setting", "tokens",
                                   "twin_joint"]))
        code = _code_only(text)
        if op == "tokens":
            text = draw(mutated_model([text]))
            done.append("token mutation")
            continue
        if op == "twin_joint":
            # a redundant joint: a second copy of a joint between the same points (issue 25: a door
            # on two coaxial hinges was an internal error)
            joints = list(JOINT.finditer(code))
            if joints:
                m = joints[draw(st.integers(0, len(joints) - 1))]
                twin = text[m.start():m.end()].replace(f" {m[2]}(", f" {m[2]}_twin(", 1)
                text = text[:m.end()] + "\n" + twin + text[m.end():]
                done.append(f"twin of joint {m[2]}")
            continue
        if op == "add_setting":
            scenes = [m.end() for m in re.finditer(r"^scene \w+[^\n]*\n(\s*model [^;]*;\n)?", code, re.M)]
            if scenes:
                at = draw(st.sampled_from(scenes))
                key = draw(st.sampled_from(sorted(SETTINGS)))
                new = f"  {key} = {draw(st.sampled_from(SETTINGS[key]))};\n"
                text = text[:at] + new + text[at:]
                done.append(f"added {new.strip()}")
            continue
        pattern = {"number": NUMBER, "vector": VECTOR, "size": SIZE, "setting": SETTING}[op]
        spans = list(pattern.finditer(code))
        if not spans:
            continue
        m = spans[draw(st.integers(0, len(spans) - 1))]
        if op == "number":
            new, (a, b) = draw(st.sampled_from(NUMBERS)), m.span()
        elif op == "vector":
            new, (a, b) = draw(st.sampled_from(VECTORS)), m.span()
        elif op == "size":
            g = 2 if m[2] is not None else 4
            new, (a, b) = draw(st.sampled_from(SIZES)), m.span(g)
        else:
            key = m[2]
            new, (a, b) = f"{m[1]}{key} = {draw(st.sampled_from(SETTINGS[key]))};", m.span()
        done.append(f"line {text.count(chr(10), 0, a) + 1}: {text[a:b].strip()!r} -> {new.strip()!r}")
        text = text[:a] + new + text[b:]
    return name, text, done


# ----------------------------------------------------------------------------- running a mutant

LOCATED = r"(?::\d+:\d+)?: error\[E\d{3}\]: "


def _child(jobs: list[tuple[list[str], str, str]], codes: str) -> None:
    """In the forked child: run CLI commands one after the other (the second reuses the derived
    equations of the first), each with stdout/stderr (also the C level) sent to its own files;
    the exit codes go to `codes` as they come."""
    import sys

    os.environ.pop("MECHDSL_DEBUG", None)
    done = []
    for argv, out, err in jobs:
        try:
            for fd, name in ((1, out), (2, err)):
                f = os.open(name, os.O_WRONLY | os.O_CREAT | os.O_TRUNC)
                os.dup2(f, fd)
                os.close(f)
            sys.stdout = open(1, "w", closefd=False)
            sys.stderr = open(2, "w", closefd=False)
            from mechdsl.cli import main

            code = main(argv)
        except SystemExit as e:
            code = e.code if isinstance(e.code, int) else 98
        except BaseException:  # noqa: BLE001 - anything escaping main is a finding
            code = 97
        sys.stdout.flush()
        sys.stderr.flush()
        done.append(code)
        with open(codes, "w") as f:
            json.dump(done, f)
    os._exit(0)


def run_cli(commands: list[list[str]], folder: Path) -> list[tuple[int | str, str, float]]:
    """[(exit code, or 'timeout' / 'signal N'; stdout + stderr; seconds)] of `mech argv` for each
    command, run in one forked child under a time limit of TIME_LIMIT per command."""
    codes = folder / "codes.json"
    jobs = [(argv, str(folder / f"{i}.out"), str(folder / f"{i}.err")) for i, argv in enumerate(commands)]
    ctx = multiprocessing.get_context("fork")
    p = ctx.Process(target=_child, args=(jobs, str(codes)))
    t0 = time.monotonic()
    p.start()
    p.join(TIME_LIMIT * len(commands))
    secs = time.monotonic() - t0
    if p.is_alive():
        p.kill()
        p.join()
        last: int | str = "timeout"
    else:
        last = f"signal {-p.exitcode}" if p.exitcode < 0 else f"child exit {p.exitcode}"
    got = json.loads(codes.read_text()) if codes.exists() else []
    out = []
    for i, (argv, o, e) in enumerate(jobs):
        rc = got[i] if i < len(got) else (last if i == len(got) else "not run")
        text = "".join(Path(x).read_text(encoding="utf-8", errors="replace") if Path(x).exists() else ""
                       for x in (o, e))
        out.append((rc, text, secs))
    return out


FAILED_RUN = re.compile(r"^FAILED at t = \S+: .+", re.M)


def classify(rc, text: str, path: Path, csv_path: Path | None) -> str | None:
    """None if the outcome is allowed, else the failure class.  `text`: stdout + stderr."""
    if rc == 0:
        if csv_path is not None:
            if not csv_path.exists():
                return "exit 0 without a CSV"
            with open(csv_path, newline="") as f:
                rows = list(csv.reader(f))
            if len(rows) < 2:
                return "exit 0 with an empty CSV"
            try:
                values = [float(x) for row in rows[1:] for x in row]
            except ValueError:
                return "exit 0 with a CSV that does not parse"
            if not all(math.isfinite(v) for v in values):
                return "exit 0 with non-finite values in the CSV"
        return None
    if rc == 1:
        if "Traceback" in text:
            return "exit 1 with a traceback"
        if re.search("^" + re.escape(str(path)) + LOCATED, text, re.M):
            return None
        if csv_path is not None and FAILED_RUN.search(text):
            return None  # a simulation that failed: it says when and why (docs/simulate.md)
        return "exit 1 without a located coded error"
    return {2: "exit 2 (usage error)", 3: "exit 3 (internal error)"}.get(rc, f"exit {rc}" if isinstance(rc, int) else rc)


def run_mutant(text: str, folder: Path) -> list[dict]:
    """Failures of `check` and `simulate` on one mutant (empty: both fine)."""
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / "mutant.mech"
    path.write_text(text, encoding="utf-8")
    out = folder / "out.csv"
    commands = [["check", str(path)],
                ["simulate", str(path), "--t-end", T_END, "--points", POINTS, "--no-progress", "-o", str(out)]]
    failures = []
    for argv, (rc, msg, secs) in zip(commands, run_cli(commands, folder)):
        bad = classify(rc, msg, path, out if argv[0] == "simulate" else None)
        if bad:
            failures.append(dict(command=argv[0], failure=bad, seconds=round(secs, 1), output=msg[-1500:]))
    return failures


# ----------------------------------------------------------------------------- tests


def test_the_classifier_can_fail(tmp_path):
    path = tmp_path / "m.mech"
    good = f"{path}:3:5: error[E303]: x\n"
    assert classify(1, good, path, None) is None
    assert classify(1, f"{path}: error[E801]: x\n", path, None) is None
    assert classify(1, "mech: error: x\n", path, None) == "exit 1 without a located coded error"
    assert classify(1, good + "Traceback (most recent call last):\n", path, None) == "exit 1 with a traceback"
    assert classify(3, "", path, None) == "exit 3 (internal error)"
    assert classify("timeout", "", path, None) == "timeout"
    csv_path = tmp_path / "r.csv"
    csv_path.write_text("time,x\n0,1\n0.05,nan\n")
    assert classify(0, "", path, csv_path) == "exit 0 with non-finite values in the CSV"
    csv_path.write_text("time,x\n0,1\n0.05,2\n")
    assert classify(0, "", path, csv_path) is None
    assert classify(0, "", path, tmp_path / "missing.csv") == "exit 0 without a CSV"
    failed = "FAILED at t = 0.01: singular mass matrix (...)\nresults kept up to t = 0\n"
    assert classify(1, failed, path, csv_path) is None
    assert classify(1, failed, path, None) == "exit 1 without a located coded error"  # check never runs one


def test_the_runner_reports_signals_and_timeouts(tmp_path, monkeypatch):
    import signal

    monkeypatch.setattr("mechdsl.cli.main", lambda argv: 0 if argv[0] == "a" else os.kill(os.getpid(), signal.SIGTERM))
    got = [rc for rc, _, _ in run_cli([["a"], ["b"], ["c"]], tmp_path)]
    assert got == [0, f"signal {int(signal.SIGTERM)}", "not run"]
    monkeypatch.setattr("mechdsl.cli.main", lambda argv: time.sleep(30))
    monkeypatch.setitem(globals(), "TIME_LIMIT", 0.5)
    assert run_cli([["check", "x"]], tmp_path / "t" if (tmp_path / "t").mkdir() is None else None)[0][0] == "timeout"


DEFAULT = settings(max_examples=10, deadline=None, derandomize=True, database=None, phases=[Phase.generate],
                   suppress_health_check=list(HealthCheck))


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
@DEFAULT
@given(value_mutant())
def test_pipeline_on_mutated_models(tmp_path_factory, mutant):
    name, text, done = mutant
    failures = run_mutant(text, tmp_path_factory.mktemp("mutant"))
    assert not failures, json.dumps(dict(model=name, mutations=done, failures=failures), indent=1)


@pytest.mark.slow
def test_pipeline_long_run(tmp_path):
    """Thousands of mutants; every failure is recorded (not only the first) and summarized."""
    n = int(os.environ.get("MECHDSL_FUZZ", "1500")) if os.environ.get("MECHDSL_FUZZ", "").isdigit() else 1500
    budget = float(os.environ.get("MECHDSL_FUZZ_SECONDS", "1200"))
    report = Path(os.environ.get("MECHDSL_FUZZ_REPORT", tmp_path / "pipeline_fuzz.json"))
    found: list[dict] = []
    count = {"examples": 0}
    t0 = time.monotonic()

    class Spent(Exception):
        """The time budget is spent: ends the exploration (returning would make hypothesis go
        on generating up to max_examples)."""

    @settings(max_examples=n, deadline=None, derandomize=False, database=None, phases=[Phase.generate],
              suppress_health_check=list(HealthCheck))
    @given(value_mutant())
    def explore(mutant):
        if time.monotonic() - t0 > budget:
            raise Spent
        count["examples"] += 1
        name, text, done = mutant
        folder = tmp_path / f"m{count['examples']}"
        for f in run_mutant(text, folder):
            found.append(dict(model=name, mutations=done, **f))
            (folder / "keep").touch()

    try:
        explore()
    except Spent:
        pass
    by_class: dict[str, int] = {}
    for f in found:
        key = f"{f['command']}: {f['failure']}"
        by_class[key] = by_class.get(key, 0) + 1
    summary = dict(examples=count["examples"], seconds=round(time.monotonic() - t0), failures=len(found),
                   by_class=by_class, found=found)
    report.write_text(json.dumps(summary, indent=1), encoding="utf-8")
    assert not found, f"{len(found)} failures in {count['examples']} mutants: {by_class}; details in {report}"
