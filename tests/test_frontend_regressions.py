"""Regression tests for front-end bugs found by the corpus and the fuzzer (valid inputs that
were rejected, and output details the corpus cannot express)."""
from __future__ import annotations

import pytest

from mechdsl import loads
from mechdsl.cli import main
from mechdsl.diagnostics import Diagnostic, MechError, Span, render

from conftest import MODELS


def test_joint_variable_of_a_connected_joint_in_an_output():
    # connect(...) used to run after the declarations were evaluated: j[1].phi in an output
    # looked for j[1]'s child before the connect set it (E210 on a valid model)
    text = (MODELS / "nlink_pendulum.mech").read_text().replace(
        "  output Real tip_x", "  output Real first = j[1].phi;\n  output Real tip_x")
    m = loads(text)
    assert [o.name for o in m.model.outputs][:1] == ["first"]
    assert m.coordinates == ("q[1]", "q[2]", "q[3]")


def test_long_chain_is_linear():
    # the per-element modifier split used to cost O(N) per element; N = 400 stays quick and right
    text = (MODELS / "nlink_pendulum.mech").read_text().replace("Integer N = 3", "Integer N = 400")
    m = loads(text)
    assert len(m.coordinates) == 400 and len(m.model.joints) == 400


def test_scene_override_must_name_a_declaration():
    text = (MODELS / "pendulum.mech").read_text()
    assert loads(text.replace("model Pendulum;", "model Pendulum(L = 2);"), scene="Swing").parameters["L"] == 2
    with pytest.raises(MechError) as e:
        loads(text.replace("model Pendulum;", "model Pendulum(LL = 2);"), scene="Swing")
    assert e.value.first.code == "E204" and e.value.first.help == "did you mean 'L'?"


def test_same_file_name_reused_does_not_show_old_source(tmp_path, capsys):
    # the source cache is keyed by file name: a file that fails to decode must not be shown
    # with the text an earlier file of the same name had
    path = tmp_path / "m.mech"
    path.write_text("model A\n  parameter Real x = y;\nend A;\n")
    assert main(["check", str(path)]) == 1
    capsys.readouterr()
    path.write_bytes(b"model A\n  parameter Real x = 1; // \xff\nend A;\n")
    assert main(["check", str(path)]) == 1
    err = capsys.readouterr().err
    assert f"{path}:2:" in err and "error[E002]" in err and "parameter Real x = y" not in err


def test_render_shows_lines_as_the_lexer_counts_them():
    src = "model A\x0c  x\n  parameter Real x = y;\r\nend A;\n"
    out = render(Diagnostic("E201", "undefined name 'y'", Span("f.mech", 2, 22, 2, 23), "h"), src)
    assert out.splitlines()[1] == "      parameter Real x = y;"
    assert out.splitlines()[2] == " " * 25 + "^"


def test_render_never_prints_control_characters():
    out = render(Diagnostic("E101", "m", Span("f.mech", 1, 3, 1, 4), "h"), "a \x1b[2J b\n")
    assert "\x1b" not in out and out.splitlines()[2] == "      ^"


def test_each_problem_is_reported_once(capsys, tmp_path):
    # equations run in two passes (connects, then the rest); an error in a loop range was reported twice
    path = tmp_path / "twice.mech"
    path.write_text("model A\n  coordinate Real q(start = 0);\nequation\n  kinetic = der(q)^2/2;\n"
                    "  for i in 1:M loop\n    force(q) = 0;\n    connect(world, j, q);\n  end for;\nend A;\n")
    assert main(["check", str(path)]) == 1
    err = capsys.readouterr().err
    assert err.count("error[E201]: undefined name 'M'") == 1


def test_huge_axis_components_are_normalized():
    # found by the fuzzer: |axis| overflowed (OverflowError) for components near 1e308
    text = (MODELS / "pendulum.mech").read_text().replace("axis = {0, 0, 1}", "axis = {0, 1e308, 1e308}")
    j = loads(text, model="Pendulum").model.joints[0]
    assert [c.value for c in j.axis] == pytest.approx([0.0, 2 ** -0.5, 2 ** -0.5])
