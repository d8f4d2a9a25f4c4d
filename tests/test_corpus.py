"""The broken-input corpus (tests/corpus/): every file fails `mech check` with exactly the
diagnostics its `// expect: CODE line:col` lines name (binary and empty files: EXPECT.txt),
rendered as `file:line:col: error[CODE]: message`, the source line, a caret and a hint;
never a traceback.  Also: every error code the front end can emit is covered here and
documented in docs/errors.md.
"""
from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

from mechdsl.frontend import limits
from mechdsl.frontend import parser as P
from mechdsl.cli import main
from mechdsl.diagnostics import MechError

import mechdsl
from conftest import CHECKOUT, MODELS, TESTS

CORPUS = TESTS / "corpus"
SRC = Path(mechdsl.__file__).resolve().parent      # the installed package's modules
DOCS = CHECKOUT / "docs" / "errors.md"

EXPECT_LINE = re.compile(r"^// expect: (E\d{3}) (\d+):(\d+)\s*$")
HEADER = re.compile(r"^(?P<file>.*):(?P<line>\d+):(?P<col>\d+): (?P<sev>error|warning)\[(?P<code>[EW]\d{3})\]: (?P<msg>.*)$")

# codes that no file in the corpus can produce, each with its own test below
NOT_FROM_A_FILE = {
    "E001": "test_missing_file",
    "E003": "test_directory",
    "E005": "test_file_too_large",
    "E006": "test_not_a_regular_file",
    "E602": "test_unknown_scene_via_api",
}


def expectations() -> dict[str, list[tuple[str, int, int]]]:
    out: dict[str, list[tuple[str, int, int]]] = {}
    for line in (CORPUS / "EXPECT.txt").read_text(encoding="utf-8").splitlines():
        if line.strip() and not line.startswith("#"):
            name, code, pos = line.split()
            ln, col = pos.split(":")
            out.setdefault(name, []).append((code, int(ln), int(col)))
    for path in sorted(CORPUS.glob("*.mech")):
        if path.name in out:
            continue
        lines = path.read_text(encoding="utf-8").splitlines()
        assert lines and EXPECT_LINE.match(lines[0]), f"{path.name} must start with `// expect: CODE line:col`"
        out[path.name] = [(m[1], int(m[2]), int(m[3])) for m in map(EXPECT_LINE.match, lines) if m]
    return out


EXPECT = expectations()


def blocks(stderr: str) -> list[dict]:
    """Split rendered diagnostics into blocks: header fields plus the lines that follow it."""
    out: list[dict] = []
    for line in stderr.splitlines():
        m = HEADER.match(line)
        if m:
            out.append({**m.groupdict(), "rest": []})
        elif out:
            out[-1]["rest"].append(line)
    return out


def run_check(path: Path, capsys) -> tuple[int, str, str]:
    rc = main(["check", str(path)])
    cap = capsys.readouterr()
    return rc, cap.out, cap.err


def test_corpus_is_large_enough():
    assert len(EXPECT) >= 50
    assert set(EXPECT) == {p.name for p in CORPUS.glob("*.mech")}, "EXPECT.txt names a file that does not exist"


# CPU budget: the cheaper tests of this file stay in the default run
@pytest.mark.slow_cases('E303_nested_loops_too_long.mech', 'E316_too_many_components.mech', 'E404_unknown_unit.mech')
@pytest.mark.parametrize("name", sorted(EXPECT))
def test_corpus_file(name, capsys):
    path = CORPUS / name
    rc, out, err = run_check(path, capsys)
    assert "Traceback" not in out + err and "internal error" not in out + err
    assert rc == 1, f"expected exit code 1, got {rc}\n{err}"
    got = [b for b in blocks(err) if b["sev"] == "error"]
    assert all(b["file"] == str(path) for b in got), err
    assert [(b["code"], int(b["line"]), int(b["col"])) for b in got] == EXPECT[name], err
    raw = path.read_bytes()
    # lines as the lexer counts them; control characters are shown as U+FFFD
    source_lines = ["".join(c if c.isprintable() else "\ufffd" for c in ln.rstrip("\r"))
                    for ln in raw.decode("utf-8", "replace").split("\n")]
    for b in got:
        assert b["msg"].strip(), f"empty message\n{err}"
        line = int(b["line"])
        rest = b["rest"]
        if name in _TEXT_FILES and 1 <= line <= len(source_lines):
            # the source line, then a caret under the column
            assert len(rest) >= 2 and re.fullmatch(r" *\^+", rest[1]), err
            shown = source_lines[line - 1]
            assert rest[0] == "    " + shown or len(shown) > 200, err
            if len(shown) <= 200:
                assert rest[1].index("^") == 4 + int(b["col"]) - 1, err
        helps = [r for r in rest if r.startswith("  help: ")]
        assert len(helps) == 1 and len(helps[0]) > len("  help: ") + 3, f"no hint for {b['code']}\n{err}"


_TEXT_FILES = {p.name for p in CORPUS.glob("*.mech") if p.read_bytes().startswith(b"// expect:")}


# ----------------------------------------------------------------------------- not from a corpus file


def test_missing_file(tmp_path, capsys):
    path = tmp_path / "no_such_model.mech"
    rc, out, err = run_check(path, capsys)
    assert rc == 1
    assert err.startswith(f"{path}: error[E001]: file not found: {path}\n")
    assert "help: " in err and "Traceback" not in err


def test_directory(tmp_path, capsys):
    rc, out, err = run_check(tmp_path, capsys)
    assert rc == 1
    assert err.startswith(f"{tmp_path}: error[E003]: {tmp_path} is a directory")
    assert "help: " in err and "Traceback" not in err


def test_not_a_regular_file(tmp_path, capsys):
    # a FIFO would block at open() and /dev/zero never ends: both refused from stat(), before opening
    fifo = tmp_path / "model.mech"
    os.mkfifo(fifo)
    for path in (fifo, Path("/dev/zero")):
        rc, out, err = run_check(path, capsys)
        assert rc == 1 and err.startswith(f"{path}: error[E006]: {path} is not a regular file ("), err
        assert "help: " in err and "Traceback" not in err


def test_file_size_checked_before_reading(tmp_path, capsys, monkeypatch):
    # a sparse file one byte over the limit: refused from its size, never read
    path = tmp_path / "huge.mech"
    with open(path, "wb") as f:
        f.truncate(limits.get("file_bytes") + 1)
    def no_reading(*a, **k):
        pytest.fail("the file was opened before the size check")

    monkeypatch.setattr(Path, "read_bytes", no_reading)
    monkeypatch.setattr(P, "open", no_reading, raising=False)  # the module's open() shadows the builtin
    rc, out, err = run_check(path, capsys)
    assert rc == 1 and f"error[E005]: file is too large ({limits.get('file_bytes') + 1:,} bytes" in err


def test_file_size_limit_can_be_raised(tmp_path, capsys):
    path = tmp_path / "m.mech"
    path.write_text("model A\n  coordinate Real q(start = 0);\nequation\n  kinetic = der(q)^2/2;\nend A;\n")
    with limits.override(file_bytes=40):
        assert run_check(path, capsys)[0] == 1
    assert main(["check", "--limit", "file_bytes=40", str(path)]) == 1
    assert main(["check", "--limit", "file_bytes=1e3", str(path)]) == 0


def test_file_too_large(tmp_path, capsys, monkeypatch):
    path = tmp_path / "big.mech"
    path.write_text("model A\n  coordinate Real q(start = 0);\nequation\n  kinetic = der(q)^2/2;\nend A;\n")
    assert run_check(path, capsys)[0] == 0
    with limits.override(file_bytes=40):  # the real limit is 1 MB; the check is the same
        rc, out, err = run_check(path, capsys)
    assert rc == 1 and err.startswith(f"{path}: error[E005]: file is too large (")
    assert "the limit is 40;" in err and "--limit file_bytes=N" in err


def test_unknown_scene_via_api():
    # `mech check --scene X` and mechdsl.load(scene=X) reject an unknown scene as a usage error (exit 2);
    # Program.scene is the library entry point that reports it as a diagnostic
    from mechdsl.semantic import analyze

    program = analyze(P.parse_file(MODELS / "pendulum.mech"))
    with pytest.raises(MechError) as e:
        program.scene("Swnig")
    assert e.value.first.code == "E602" and e.value.first.help == "did you mean 'Swing'?"


def test_unknown_scene_on_the_command_line(capsys):
    assert main(["check", str(MODELS / "pendulum.mech"), "--scene", "Swnig"]) == 2
    err = capsys.readouterr().err
    assert "no scene named 'Swnig'" in err and "did you mean 'Swing'?" in err


def test_several_files_report_each(capsys):
    good, bad = MODELS / "pendulum.mech", CORPUS / "E201_undefined_in_binding.mech"
    assert main(["check", str(bad), str(good), str(CORPUS / "E002_nul_byte.mech")]) == 1
    cap = capsys.readouterr()
    assert f"{good}: ok" in cap.out
    assert f"{bad}:4:22: error[E201]" in cap.err and "error[E002]" in cap.err


# ----------------------------------------------------------------------------- end to end


# The real program on a parse error by default; an undecodable file (the process's own stderr
# encoding), a later phase's error and the other files in the slow set (a process start each).
# Every corpus file's diagnostics (codes, lines, columns) are checked in-process by test_corpus_file.
_SLOW = pytest.mark.slow


# the real program on a parse error stays in the default run (CPU budget)
@pytest.mark.slow_cases("E002_non_utf8.mech", "E604_stop_time_string.mech")
@pytest.mark.parametrize("name", ["E107_missing_semicolon.mech", pytest.param("E201_several_undefined.mech", marks=_SLOW),
                                  "E002_non_utf8.mech",
                                  pytest.param("E104_nested_parentheses.mech", marks=_SLOW),
                                  pytest.param("E505_reversed_joint.mech", marks=_SLOW), "E604_stop_time_string.mech"])
def test_subprocess(name):
    path = CORPUS / name
    proc = subprocess.run([sys.executable, "-m", "mechdsl", "check", str(path)], capture_output=True, text=True,
                          cwd=TESTS, timeout=120)
    assert proc.returncode == 1, proc.stderr
    assert proc.stdout == ""
    assert "Traceback" not in proc.stderr and "internal error" not in proc.stderr
    got = [(b["code"], int(b["line"]), int(b["col"])) for b in blocks(proc.stderr) if b["sev"] == "error"]
    assert got == EXPECT[name]
    first = proc.stderr.splitlines()[0]
    code, line, col = EXPECT[name][0]
    assert re.fullmatch(rf"{re.escape(str(path))}:{line}:{col}: error\[{code}\]: .+", first)


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
def test_subprocess_missing_file(tmp_path):
    path = tmp_path / "missing.mech"
    proc = subprocess.run([sys.executable, "-m", "mechdsl", "check", str(path)], capture_output=True, text=True,
                          cwd=TESTS, timeout=120)
    assert proc.returncode == 1 and proc.stderr.startswith(f"{path}: error[E001]: ")


# ----------------------------------------------------------------------------- coverage and documentation


FRONT_END = [SRC / "frontend" / "parser.py", SRC / "frontend" / "source.py", SRC / "diagnostics.py", SRC / "api.py",
             SRC / "cli.py", SRC / "model" / "units.py",
             SRC / "commands" / "check.py", SRC / "commands" / "compile.py", *sorted((SRC / "semantic").glob("*.py")),
             SRC / "commands" / "import_urdf.py", *sorted((SRC / "urdf").glob("*.py")),
             SRC / "estimation" / "data.py"]


def codes_in_source() -> set[str]:
    """Error codes the front end (parse, analyze, check) can emit; later phases document their own."""
    codes: set[str] = set()
    for p in FRONT_END:
        codes |= set(re.findall(r"[\"'](E\d{3})[\"']", p.read_text(encoding="utf-8")))
    return codes


def test_every_code_is_in_the_corpus():
    from test_fit_corpus import EXPECT as FIT_EXPECT        # mech fit's data files (tests/corpus/fit)
    from test_urdf_corpus import EXPECT as URDF_EXPECT      # the importer's corpus (tests/corpus/urdf)

    covered = {c for exp in [*EXPECT.values(), *URDF_EXPECT.values()] for c, _, _ in exp if c.startswith("E")}
    covered |= {code for code, *_ in FIT_EXPECT.values()}
    missing = codes_in_source() - covered - set(NOT_FROM_A_FILE)
    assert not missing, f"error codes with no corpus file: {sorted(missing)}"
    assert covered <= codes_in_source(), "the corpus expects a code the source never emits"
    for test in NOT_FROM_A_FILE.values():
        assert callable(globals()[test])


def test_every_code_is_documented():
    text = DOCS.read_text(encoding="utf-8")
    documented = re.findall(r"^### (E\d{3})\b", text, flags=re.M)
    assert len(documented) == len(set(documented)), "a code is documented twice"
    assert codes_in_source() - set(documented) == set(), f"undocumented: {sorted(codes_in_source() - set(documented))}"
    assert set(documented) - codes_in_source() == set(), \
        f"documented but never emitted: {sorted(set(documented) - codes_in_source())}"


def test_documentation_is_current():
    """docs/errors.md is generated from real output; any change of a message must regenerate it."""
    import errors_doc

    assert errors_doc.generate() == DOCS.read_text(encoding="utf-8"), \
        "docs/errors.md is stale: run `PYTHONPATH=src python tests/errors_doc.py`"


def test_generalized_force_field_can_be_written(capsys):
    src = ("model A\n  coordinate Real q(start = 0);\n  GeneralizedForce push(coordinate = q, Q = 1);\n"
           "equation\n  kinetic = der(q)^2/2;\nend A;\n")
    tree = P.parse(src, "gf.mech")
    from mechdsl.frontend.printer import to_source

    assert P.parse(to_source(tree), "again") == tree
    import mechdsl

    r = mechdsl.loads(src).simulate(1.0, points=3)      # q'' = Q = 1
    assert abs(r["q"][-1] - 0.5) < 1e-8


def test_mutual_instances_are_found_by_check(capsys):
    # A has a B and B has an A: both are parts, which check used to skip ("checked there"),
    # so check passed while simulate refused the file.  The whole-file check names the cycle.
    path = CORPUS / "E207_mutual_instances.mech"
    for command in (["check"], ["simulate", "--t-end", "0.01"]):
        assert main([*command, str(path)]) == 1
        err = capsys.readouterr().err
        assert "error[E207]: model 'A' extends or contains itself (through A -> B -> A)" in err, err
