"""The grammar is LALR(1) without conflicts or terminal collisions (lark strict mode)."""
import lark
import pytest

from mechdsl.frontend.parser import grammar_path


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
def test_grammar_is_strict_lalr():
    lark.Lark(grammar_path().read_text(), parser="lalr", lexer="basic", strict=True, propagate_positions=True)


def test_grammar_is_the_single_definition():
    # the package loads the repository's grammar (or the copy shipped in the wheel)
    assert grammar_path().name == "mech.lark"
