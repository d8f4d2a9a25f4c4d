"""parse -> print -> parse gives the same AST, for every shipped model and tricky snippets."""
import pytest

from mechdsl.frontend.parser import parse
from mechdsl.frontend.printer import to_source

from conftest import model_files

SNIPPETS = [
    "model A parameter Real x = -2^-3^2; Real y = (-x)^2 + -x*-x - (x - (x - 1)); end A;",
    "model A Real y = a/(b*c) - (a - b) + a*(b*c) + (a + b)*c; end A;",
    "model A Real y = if a < 1 and not b >= 2 or c == 3 then {1, 2} elseif d <> 4 then {3, 4} else {i for i in 1:2:5}; end A;",
    'model A "doc with \\"quotes\\" and \\\\ backslash" parameter Real x(unit = "m", min = 0) = 1.5e-10 "d"; end A;',
    "model A Rod r[N](each m = 1, phi(start = {1, 2}), j1.phi(start = 2) = 3); extends B(x = 1); end A;",
    "model A equation kinetic = 1; potential = 2 \"v\"; dissipation = 3; force(q[1]) = 4; "
    "for i in 1:N loop for j in i:N loop connect(a[i].b, j[j], c); end for; end for; x^2 = 1 \"circle\"; end A;",
    "scene S \"doc\" model A(x = 1, y(start = 2)); stop_time = 1e3; outputs = {x, der(y), \"E\"}; end S;",
    "model A Real y = 1.0 + 2 + 0.5 + 1e999 + .5 + 3.; end A;",
    "model A Real y = f(g(1), {}, {{1, 2}, {3, 4}}) + a.b[1, 2].c; end A;",
]


@pytest.mark.parametrize("path", model_files(), ids=lambda p: p.name)
def test_shipped_models_round_trip(path):
    text = path.read_text()
    tree = parse(text, str(path))
    printed = to_source(tree)
    again = parse(printed, "printed")
    assert again == tree
    # printing is canonical: a second print is identical
    assert to_source(again) == printed


@pytest.mark.parametrize("text", SNIPPETS)
def test_snippets_round_trip(text):
    tree = parse(text)
    printed = to_source(tree)
    assert parse(printed) == tree, printed


def test_long_sum_round_trips():
    text = "model A equation x = " + " + ".join(["a"] * 300) + "; end A;"
    printed = to_source(parse(text))
    assert to_source(parse(printed)) == printed


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
def test_absurdly_long_sum_is_a_coded_error():
    from mechdsl.diagnostics import MechError

    text = "model A equation x = " + " + ".join(["a"] * 5000) + "; end A;"
    with pytest.raises(MechError) as e:
        parse(text)
    assert e.value.first.code == "E104"
