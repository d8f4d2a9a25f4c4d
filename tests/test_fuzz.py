"""Property tests of the front end's robustness (hypothesis).

The shipped models and the files of the broken-input corpus are mutated (a token deleted, duplicated or swapped with another, a line
deleted, a keyword or symbol inserted, the text truncated), and random bytes and random text
are fed in.  For every input the front end (decode, parse, print, analyze, flatten every model
and scene, dump) either succeeds or raises MechError whose diagnostics all carry a code E\\d\\d\\d
and a position inside the file.  Any other exception fails the test.

The default run is short and deterministic (CI).  MECHDSL_FUZZ=long explores more, with fresh
random inputs on every run; MECHDSL_FUZZ=<number> sets the number of examples per test.
"""
from __future__ import annotations

import os
import re

import pytest
from hypothesis import HealthCheck, given, settings, strategies as st

from mechdsl.diagnostics import Diagnostic, MechError, Span
from mechdsl.frontend.dump import dump_ast, dump_model
from mechdsl.frontend.parser import KEYWORDS, decode_source, parse
from mechdsl.frontend.printer import to_source
from mechdsl.semantic import analyze

from conftest import TESTS, model_files

FILE = "fuzz.mech"
MODELS = [p.read_text(encoding="utf-8") for p in model_files()]
# the broken-input corpus is a second source of seeds: small files that reach many error paths
CORPUS = [p.read_text(encoding="utf-8") for p in sorted((TESTS / "corpus").glob("*.mech"))
          if p.read_bytes().startswith(b"// expect:") and p.stat().st_size < 4000]

_mode = os.environ.get("MECHDSL_FUZZ", "")
if _mode == "long":
    EXAMPLES, DERANDOMIZE = 2000, False
elif _mode.isdigit():
    EXAMPLES, DERANDOMIZE = int(_mode), False
else:
    EXAMPLES, DERANDOMIZE = 60, True
FUZZ = settings(max_examples=EXAMPLES, deadline=None, derandomize=DERANDOMIZE, database=None,
                suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])

# tokens of the language plus some traps, for insertion
INSERTS = sorted(KEYWORDS) + [
    "(", ")", "[", "]", "{", "}", ";", ",", ".", ":", "=", "==", "<>", "+", "-", "*", "/", "^", "\"", "'",
    "/*", "*/", "//", "0", "1", "2.5", "1e400", "-1", "time", "world", "pi", "der", "x", "q", "N",
    "Real", "Integer", "Boolean", "Rod", "PointMass", "Revolute", "Prismatic", "Free", "Spring", "Frame",
    "Point", "Gravity", "connect(world, j, rod.a);", "extends", "\n", "\x00", "\u00e9", "\u2028", "\x0c",
]
NUMBERS = ["0", "1", "2", "3", "0.5", "-1", "1e308", "1e-320", "100000", "2.5", "1e400", "3.0", "(-8)", "(1/0)"]
NAMES = ["world", "time", "pi", "Real", "Integer", "Body", "Rod", "Disk", "Cylinder", "Sphere", "Box", "PointMass",
         "Point", "Frame", "Revolute", "Prismatic", "Cylindrical", "Planar", "Spherical", "Free", "Fixed",
         "Gravity", "Spring", "Damper", "SpringDamper", "Force", "Torque", "GeneralizedForce", "Gravitation",
         "Potential", "Contact", "der", "sin", "sqrt", "cross", "norm", "zeros", "identity", "size", "sum",
         "kinetic_energy", "reaction_force", "position", "a", "b", "com", "phi", "s", "r", "R", "w", "x", "stop_time",
         "tolerance", "points", "outputs", "method", "start", "speed", "fixed", "unit", "each", "min", "max"]
TOKEN = re.compile(r'"[^"\n]*"?|//[^\n]*|/\*|\*/|\d+(?:\.\d*)?(?:[eE][+-]?\d+)?|\w+|\S')


def tokens(text: str) -> list[tuple[int, int]]:
    return [m.span() for m in TOKEN.finditer(text)]


@st.composite
def mutated_model(draw, seeds=MODELS) -> str:
    text = draw(st.sampled_from(seeds))
    for _ in range(draw(st.integers(1, 3))):
        op = draw(st.sampled_from(["delete", "duplicate", "swap", "delete_line", "insert", "truncate",
                                   "replace_name", "replace_number"]))
        toks = tokens(text)
        if not toks:
            break
        if op in ("replace_name", "replace_number"):
            # keeps the syntax valid more often, so that analysis is exercised
            kind = r"[A-Za-z_]\w*" if op == "replace_name" else r"\d[\d.eE+-]*"
            spans = [(a, b) for a, b in toks if re.fullmatch(kind, text[a:b]) and text[a:b] not in KEYWORDS]
            if spans:
                a, b = spans[draw(st.integers(0, len(spans) - 1))]
                pool = NUMBERS if op == "replace_number" else sorted({text[x:y] for x, y in spans}) + NAMES
                text = text[:a] + draw(st.sampled_from(pool)) + text[b:]
        elif op == "truncate":
            text = text[:draw(st.integers(0, len(text)))]
        elif op == "delete_line":
            lines = text.split("\n")
            del lines[draw(st.integers(0, len(lines) - 1))]
            text = "\n".join(lines)
        elif op == "insert":
            at = toks[draw(st.integers(0, len(toks) - 1))][draw(st.sampled_from([0, 1]))]
            text = text[:at] + " " + draw(st.sampled_from(INSERTS)) + " " + text[at:]
        else:
            a, b = toks[draw(st.integers(0, len(toks) - 1))]
            if op == "delete":
                text = text[:a] + text[b:]
            elif op == "duplicate":
                text = text[:b] + " " + text[a:b] + text[b:]
            else:
                c, d = toks[draw(st.integers(0, len(toks) - 1))]
                if (a, b) > (c, d):
                    a, b, c, d = c, d, a, b
                if b <= c:
                    text = text[:a] + text[c:d] + text[b:c] + text[a:b] + text[d:]
    return text


def check_diagnostics(e: MechError, text: str | None) -> None:
    assert e.diagnostics, "MechError without diagnostics"
    lines = text.split("\n") if text is not None else None
    for d in e.diagnostics:
        assert re.fullmatch(r"E\d{3}", d.code), d
        assert d.message and d.span.file == FILE, d
        if d.span.line == 0:
            assert d.code in ("E002", "E004", "E005") or text is not None, d
            continue
        assert d.span.line >= 1 and d.span.col >= 1, d
        if lines is not None:
            assert d.span.line <= len(lines), (d, len(lines))
            assert d.span.col <= len(lines[d.span.line - 1]) + 1, (d, lines[d.span.line - 1])


def front_end(data: str | bytes) -> None:
    """Everything `mech check` and `mech compile --emit ast|source|model` do, for every model and scene."""
    text = None
    try:
        text = decode_source(data, FILE) if isinstance(data, bytes) else data
        tree = parse(text, FILE)
        dump_ast(tree)
        printed = to_source(tree)
        assert parse(printed, "printed.mech") == tree, "parse(print(ast)) != ast"
        program = analyze(tree)
        for name in program.model_names():
            try:
                dump_model(program.model(name))
            except MechError as e:
                check_diagnostics(e, text)
        for name in program.scene_names():
            try:
                program.scene(name)
            except MechError as e:
                check_diagnostics(e, text)
    except MechError as e:
        check_diagnostics(e, text)


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
def test_shipped_models_pass():
    for text in MODELS:
        front_end(text)


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
@FUZZ
@given(mutated_model())
def test_mutated_models(text):
    front_end(text)


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
@FUZZ
@given(mutated_model(CORPUS))
def test_mutated_corpus(text):
    front_end(text)


@FUZZ
@given(st.binary(max_size=2000))
def test_random_bytes(data):
    front_end(data)


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
@FUZZ
@given(st.text(max_size=400))
def test_random_text(text):
    front_end(text)


@FUZZ
@given(st.lists(st.sampled_from(INSERTS + ["A", "model A", "end A;", "scene S", "end S;", "m", "=", "1;"]),
                max_size=60).map(" ".join))
def test_random_token_soup(text):
    front_end(text)


@FUZZ
@given(st.sampled_from(MODELS), st.binary(min_size=1, max_size=8), st.floats(0, 1))
def test_bytes_spliced_into_models(text, junk, where):
    data = text.encode("utf-8")
    at = int(where * len(data))
    front_end(data[:at] + junk + data[at:])


def test_the_checker_can_fail():
    """The harness itself: positions outside the file and malformed codes are caught."""
    text = "model A\nend A;\n"
    for d in (Diagnostic("E201", "x", Span(FILE, 9, 1, 9, 2)), Diagnostic("E201", "x", Span(FILE, 1, 40, 1, 41)),
              Diagnostic("X1", "x", Span(FILE, 1, 1, 1, 2)), Diagnostic("E201", "x", Span("other.mech", 1, 1))):
        with pytest.raises(AssertionError):
            check_diagnostics(MechError(d), text)
    check_diagnostics(MechError(Diagnostic("E201", "x", Span(FILE, 2, 7, 2, 8))), text)
