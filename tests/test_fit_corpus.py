"""The broken-data corpus of ``mech fit`` (tests/corpus/fit/): every data file fails with exactly
the diagnostic EXPECT.txt names, located in the data file (``file:line:col: error[CODE]``, the
line, a caret under the column, a hint), exit 1, nothing written, never a traceback."""
from __future__ import annotations

import re

import pytest

import mechdsl.estimation.data
from mechdsl.cli import main

from conftest import MODELS, TESTS

CORPUS = TESTS / "corpus" / "fit"
HEADER = re.compile(r"^(?P<file>.*):(?P<line>\d+):(?P<col>\d+): error\[(?P<code>E\d{3})\]: (?P<msg>.+)$")


def expectations() -> dict[str, tuple[str, int, int, list[str]]]:
    out = {}
    for line in (CORPUS / "EXPECT.txt").read_text(encoding="utf-8").splitlines():
        if line.strip() and not line.startswith("#"):
            name, code, pos, *args = line.split()
            ln, col = pos.split(":")
            out[name] = (code, int(ln), int(col), args)
    return out


EXPECT = expectations()


def test_every_file_is_expected_and_every_data_code_has_a_file():
    assert set(EXPECT) == {p.name for p in CORPUS.glob("*.csv")}
    src = open(mechdsl.estimation.data.__file__, encoding="utf-8").read()
    emitted = set(re.findall(r"\b(E77\d)\b", src))
    assert emitted == {"E771", "E772", "E773"} and emitted <= {c for c, *_ in EXPECT.values()}


@pytest.mark.parametrize("name", sorted(EXPECT))
def test_corpus_file(name, tmp_path, capsys):
    code, line, col, args = EXPECT[name]
    path = CORPUS / name
    out = tmp_path / "fit.json"
    rc = main(["fit", str(MODELS / "pendulum.mech"), "--model", "Pendulum", "--fit", "L", "--data", str(path),
               "-o", str(out), *args])
    err = capsys.readouterr().err
    assert rc == 1 and not out.exists() and "Traceback" not in err, err
    lines = err.splitlines()
    heads = [(i, m) for i, m in enumerate(map(HEADER.match, lines)) if m]
    assert len(heads) == 1, err
    i, m = heads[0]
    assert (m["file"], m["code"], int(m["line"]), int(m["col"])) == (str(path), code, line, col), err
    source = path.read_text(encoding="utf-8").splitlines()[line - 1]
    assert lines[i + 1] == "    " + source and lines[i + 2].index("^") == 4 + col - 1, err
    assert lines[i + 3].startswith("  help: ") and len(lines[i + 3]) > 12, err
