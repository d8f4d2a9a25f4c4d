"""The language server's answers, computed in-process (mechdsl.lsp without the protocol):
diagnostics equal to what `mech check` reports, hover, completion in half-typed text, positions
in UTF-16.  tests/test_lsp_server.py drives the real server over stdio."""
from __future__ import annotations

import re

import pytest

from conftest import MODELS, model_files
from mechdsl.cli import main
from mechdsl.lsp.analysis import analyse, start_problems
from mechdsl.lsp.complete import completions
from mechdsl.lsp.context import context_at
from mechdsl.lsp.hover import hover_text
from mechdsl.lsp.positions import Lines

from lsp_client import where
from test_corpus import CORPUS, EXPECT

HEADER = re.compile(r"^(?P<file>.*):(?P<line>\d+):(?P<col>\d+): (?P<sev>error|warning)\[(?P<code>[EW]\d{3})\]: (?P<msg>.*)$")


def lsp_diagnostics(text: str, name: str):
    a = analyse(text, name)
    return a, a.diagnostics + start_problems(a)


def _corpus_texts():
    for name in sorted(EXPECT):
        try:
            yield name, (CORPUS / name).read_bytes().decode("utf-8")
        except UnicodeDecodeError:       # binary files: no editor sends them as text
            continue


CORPUS_TEXTS = list(_corpus_texts())


def _corpus_case(name, text):
    _, ds = lsp_diagnostics(text, name)
    got = sorted((d.code, d.span.line, d.span.col) for d in ds if d.severity == "error")
    assert got == sorted(EXPECT[name])


# every fifth file of the corpus in the default run (the whole corpus: the slow test below), less the
# nested-loop budget case, whose analysis alone takes seconds (its code and position: test_corpus)
SAMPLE = [(n, t) for n, t in CORPUS_TEXTS[::5] if n != "E303_nested_loops_too_long.mech"]


@pytest.mark.parametrize("name,text", SAMPLE, ids=[n for n, _ in SAMPLE])
def test_diagnostics_of_the_corpus_are_those_mech_check_reports(name, text):
    """The corpus's expectations are `mech check`'s exact codes and positions (tests/test_corpus.py)."""
    _corpus_case(name, text)


@pytest.mark.slow
@pytest.mark.parametrize("name,text", CORPUS_TEXTS, ids=[n for n, _ in CORPUS_TEXTS])
def test_diagnostics_of_the_whole_corpus_are_those_mech_check_reports(name, text):
    _corpus_case(name, text)


@pytest.mark.parametrize("name", ["E201_several_undefined.mech", "E102_several_syntax_errors.mech",
                                  "E508_negative_mass.mech", "E604_unknown_method.mech"])
def test_messages_hints_and_severities_are_mech_checks(name, capsys):
    """Side by side with the command: the same code, position, message and hint."""
    path = CORPUS / name
    assert main(["check", str(path)]) == 1
    err = capsys.readouterr().err.splitlines()
    printed = []
    for i, line in enumerate(err):
        m = HEADER.match(line)
        if m:
            helps = [x for x in err[i + 1:i + 4] if x.startswith("  help: ")]
            printed.append((m["code"], int(m["line"]), int(m["col"]), m["sev"], m["msg"],
                            helps[0][len("  help: "):] if helps else None))
    _, ds = lsp_diagnostics(path.read_text(), str(path))
    ours = [(d.code, d.span.line, d.span.col, d.severity, d.message, d.help) for d in ds]
    assert printed and sorted(ours) == sorted(printed)


@pytest.mark.slow_cases('nfourbar.mech')  # CPU budget: the cheaper tests of this file stay in the default run
@pytest.mark.parametrize("path", model_files(), ids=lambda p: p.name)
def test_shipped_models_have_no_errors(path):
    a, ds = lsp_diagnostics(path.read_text(), str(path))
    assert a.complete and a.loaded
    assert not [d for d in ds if d.severity == "error"]


def test_start_state_problems_come_from_the_second_stage():
    text = (MODELS / "pendulum.mech").read_text()
    broken = text.replace("start = pi/2", "start = 1e17", 1)
    assert broken != text
    a = analyse(broken, "p.mech")
    assert not a.diagnostics                                 # the names and units are fine
    found = start_problems(a)                                # the start state is not
    assert [d.code for d in found] == ["E748"] and found[0].span.line == 24


def test_a_diagnostic_without_a_position_is_shown_at_the_models_header():
    from mechdsl.diagnostics import Diagnostic, Span
    from mechdsl.lsp.analysis import locate

    a = analyse("// a comment\nmodel Lone \"doc\"\n  parameter Real m = 1;\nend Lone;\n", "e.mech")
    unit = a.tree.models[0]
    d = locate([Diagnostic("E999", "somewhere in the model", Span("e.mech"))], unit)[0]
    assert (d.span.line, d.span.col, d.span.end_line, d.span.end_col) == (2, 1, 2, 11)


# ----------------------------------------------------------------------------- hover

PENDULUMS = (MODELS / "double_pendulum.mech").read_text()


def _hover(text: str, needle: str, delta: int = 0, nth: int = 0) -> str | None:
    a = analyse(text, "x.mech")
    occ = a.index.at(*where(text, needle, nth, delta))
    return hover_text(a, occ) if occ else None


def test_hover_says_type_unit_description_and_value():
    h = _hover(PENDULUMS, "-g, 0}", 1)                       # g used in Gravity's modifier
    assert 'parameter Real g(unit = "m/s2") = 9.81;' in h and "unit m/s2" in h and "g = 9.81 m/s2" in h
    h = _hover(PENDULUMS, "Revolute j1", 9)
    assert "component of model DoublePendulum" in h and "rotation about an axis" in h
    assert re.search(r"j1\.phi: start 1\.5707963\d* rad, speed 0", h), h
    h = _hover(PENDULUMS, "Rod rod1")                        # the class: its fields with units and defaults
    assert "a uniform slender rod" in h and "| `L` | m |" in h and "| `axis` | 1 | {1, 0, 0} |" in h
    h = _hover(PENDULUMS, "rod2.b.x", 5)
    assert "named point b of the Rod" in h
    h = _hover(PENDULUMS, "rod2.b.x", 7)
    assert "x component of the position" in h and "[m]" in h
    assert "total energy" in _hover(PENDULUMS, "energy()")
    assert "model DoublePendulum" in _hover(PENDULUMS, "model DoublePendulum;", 7)   # in the scene
    assert "relative tolerance" not in _hover(PENDULUMS, "tolerance = 1e-9")
    assert "sets rtol and atol" in _hover(PENDULUMS, "tolerance = 1e-9")
    h = _hover(PENDULUMS, "DoublePendulum \"")
    assert "2 coordinates" in h and "Two uniform rods" in h


def test_hover_on_attributes_and_instances():
    text = PENDULUMS.replace("  output Real E(", "  output Real w[3] = rod1.w_body;\n  output Real E(")
    h = _hover(text, "w_body")
    assert "angular velocity, body axes" in h and "1/s" in h
    text = (MODELS / "coupled_pendulums.mech").read_text()
    h = _hover(text, "right(x0 = d)", 6)            # the part's declaration, valued in the instance
    assert "parameter of model SwingingBob" in h and "pivot position" in h and "right.x0 = 0.5 m" in h
    h = _hover(text, "der(left.theta)", 9)
    assert "coordinate of model SwingingBob" in h and "left.theta: start 0.1 rad, speed 0" in h
    h = _hover(text, "SwingingBob left")
    assert "A point mass on a massless rod" in h and "1 coordinates" in h
    h = _hover(text, "SwingingBob left", 12)
    assert "instance of model SwingingBob" in h


# ----------------------------------------------------------------------------- completion


def _labels(prefix: str, text: str = PENDULUMS) -> set[str]:
    a = analyse(text, "x.mech")
    return {i.label for i in completions(a.index, context_at(prefix))}


HEAD = PENDULUMS[:PENDULUMS.index("  Revolute j1")]


@pytest.mark.parametrize("typed,must,must_not", [
    ("  Revolute j3(", {"parent", "child", "axis", "phi"}, {"m", "sin"}),
    ("  Revolute j3(parent = rod1.b, ", {"child", "axis"}, {"rod1"}),
    ("  Revolute j3(parent = rod1.b, phi(", {"start", "speed", "fixed"}, {"parent"}),
    ("  Revolute j3(parent = ", {"rod1", "world", "m", "sin"}, {"parent"}),
    ("  Real s = rod1.", {"a", "b", "com", "m", "L", "w_body", "R"}, {"rod1", "phi"}),
    ("  Real s = rod1.b.", {"x", "y", "r", "v"}, {"w_body", "b"}),
    ("  Real s = world.", {"x", "r", "R", "w"}, set()),
    ("  Real s = j1.", {"phi", "parent", "axis"}, {"w_body"}),
    ("  ", {"parameter", "output", "Rod", "Revolute", "Real", "extends", "equation", "end"}, {"connect", "m"}),
    ("  parameter ", {"Real", "Integer", "Boolean"}, {"Rod"}),
    ("  parameter Real k(", {"unit", "min", "max"}, {"start"}),
    ("  coordinate Real q(", {"start", "speed", "unit"}, set()),
    ("  Rod ", set(), {"Rod", "m"}),
    ("  // a comment: Rod", set(), {"Rod", "m"}),
    ('  Real s = "a string', set(), {"m"}),
    ("  Real s = 1.", set(), {"m"}),
])
def test_completion_in_half_typed_declarations(typed, must, must_not):
    got = _labels(HEAD + typed)
    assert must <= got, must - got
    assert not (must_not & got)


def test_completion_in_equations_scenes_and_between_units():
    eq = PENDULUMS[:PENDULUMS.index("end DoublePendulum")] + "equation\n  "
    got = _labels(eq)
    assert {"connect", "for", "kinetic", "rod1", "sin", "der"} <= got and "parameter" not in got
    scene = PENDULUMS[:PENDULUMS.index("  stop_time")] + "  "
    assert {"stop_time", "method", "outputs", "model"} <= _labels(scene)
    assert {"m", "l", "g"} <= _labels(PENDULUMS[:PENDULUMS.index("  stop_time")] + "  stop_time = ")
    assert _labels(PENDULUMS + "\n") == {"model", "scene"}
    assert _labels(PENDULUMS[:PENDULUMS.index("scene")] + "scene S\n  model ") == {"DoublePendulum"}


def test_completion_of_instance_members_and_extends():
    text = ("model Link\n  parameter Real L = 1 \"length\";\n  Rod rod(m = 1, L = L);\nend Link;\n"
            "model Base\n  parameter Real g = 9.81;\nend Base;\n"
            "model Top\n  extends Base;\n  Link link(L = 2);\nend Top;\n")
    top = text[:text.index("end Top")]
    assert {"L", "rod"} <= _labels(top + "  Real e = link.", text)
    assert {"m", "L", "a", "b"} <= _labels(top + "  Real e = link.rod.", text)
    assert {"L", "rod"} == _labels(top + "  Link other(", text)
    assert {"g", "link"} <= _labels(top + "  Real e = ", text)          # inherited names
    assert {"Link", "Base"} <= _labels(top + "  extends ", text)
    assert {"Link", "Base", "Rod"} <= _labels(top + "  ", text)


# ----------------------------------------------------------------------------- positions


def test_positions_count_utf16_code_units_and_only_newlines_break_lines():
    text = 'model A "π and 🙂"\n  parameter Real m = 1 "a\x0cb";\nend A;\n'
    lines = Lines(text)
    assert lines.to_lsp(1, 17) == (0, 17)             # the closing quote: 🙂 is two UTF-16 units
    assert lines.from_lsp(0, 17) == (1, 17)
    assert Lines(text, "utf-8").to_lsp(1, 17) == (0, 20)
    assert Lines(text, "utf-32").to_lsp(1, 17) == (0, 16)
    assert len(lines.lines) == 4                      # the form feed is inside line 2
