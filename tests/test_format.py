"""Formatting (frontend/format.py, the language server's textDocument/formatting): the printer's
statements, the file's comments and paragraphs kept; never a changed model, never a file with
syntax errors touched."""
from __future__ import annotations

import pytest

from conftest import model_files
from mechdsl.diagnostics import MechError
from mechdsl.frontend.format import comments, format_source
from mechdsl.frontend.parser import parse


@pytest.mark.slow_cases('andrews.mech')  # CPU budget: the cheaper tests of this file stay in the default run
@pytest.mark.parametrize("path", model_files(), ids=lambda p: p.name)
def test_shipped_models_keep_their_meaning_and_comments_and_format_once(path):
    text = path.read_text()
    out = format_source(text, str(path))
    assert parse(out) == parse(text)
    assert [out[a:b] for a, b in comments(out)] == [text[a:b] for a, b in comments(text)]
    assert format_source(out, str(path)) == out                 # formatted once is formatted


UGLY = """\
// header comment
model   A "doc"   // after the header
    parameter Real m( unit="kg" )=1;   // trailing
  /* a block
     comment */
  parameter Real k = 2*m;


  Rod rod(m = m, /* inside */ L = 1);
  Revolute j(parent = world, child = rod.a, axis = {0,0,1});
equation
  for i in 1:2 loop
      // in the loop
      potential = i*k*j.phi^2;
  end for;
equation
    force(j.phi) = -k*  der(j.phi);
end A;
// between
scene S
  model A(m=2);
  stop_time=1e-09;
end S;
"""

FORMATTED = """\
// header comment
model A "doc"   // after the header
  parameter Real m(unit = "kg") = 1;   // trailing
  /* a block
     comment */
  parameter Real k = 2*m;

  Rod rod(m = m, /* inside */ L = 1);
  Revolute j(parent = world, child = rod.a, axis = {0, 0, 1});
equation
  for i in 1:2 loop
    // in the loop
    potential = i*k*j.phi^2;
  end for;
  force(j.phi) = -k*der(j.phi);
end A;

// between
scene S
  model A(m = 2);
  stop_time = 1e-9;
end S;
"""


def test_statements_are_printed_and_comments_stay_where_they_were():
    assert format_source(UGLY) == FORMATTED


def test_a_long_statement_its_author_wrapped_stays_wrapped():
    long = "  output Real e = " + " + ".join(f"a{i}*b{i}" for i in range(12)) + ";"
    wrapped = long[:60] + "\n      " + long[60:].lstrip()
    params = "".join(f"  parameter Real a{i} = 1;\n  parameter Real b{i} = 2;\n" for i in range(12))
    text = f"model W\n{params}{wrapped}\nend W;\n"
    assert format_source(text) == text
    assert format_source(f"model W\n{params}{long}\nend W;\n").count("\n") == 27   # one line: not wrapped by us


def test_line_ends_of_the_file_are_kept():
    text = "model A\r\n  parameter Real m=1; // c\r\nend A;\r\n"
    assert format_source(text) == "model A\r\n  parameter Real m = 1; // c\r\nend A;\r\n"


def test_a_file_with_syntax_errors_is_not_formatted():
    with pytest.raises(MechError) as e:
        format_source("model A\n  parameter Real m = ;\nend A;\n")
    assert e.value.first.code == "E102"
    with pytest.raises(MechError):
        format_source("model A\n  parameter Real m = 1;\n")      # not closed yet
