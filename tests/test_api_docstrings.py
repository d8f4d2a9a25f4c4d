"""The Python API as notebook users expect it (issue 27): every public function, class, method
and property has a docstring (``help(mechdsl.load)`` was empty), the examples in them run as
shown, and a Result shows itself in one line (its repr was 61-79 kB of numbers)."""
from __future__ import annotations

import doctest
import inspect

import mechdsl
import mechdsl.examples
from api_doc import CLASSES, _members, _obj
from mechdsl.api import Model


def public_api():
    """(dotted name, object) of everything docs/api.md documents."""
    for name in mechdsl.__all__:
        if name != "__version__":
            yield f"mechdsl.{name}", getattr(mechdsl, name)
    yield "mechdsl.examples", mechdsl.examples
    for name in mechdsl.examples.__all__:
        yield f"mechdsl.examples.{name}", getattr(mechdsl.examples, name)
    for path, _ in CLASSES:
        cls = _obj(path)
        yield path, cls
        for name, _, fn in _members(cls):
            yield f"{path}.{name}", fn


def test_the_walk_covers_what_was_missing():
    names = {n for n, _ in public_api()}
    assert {"mechdsl.load", "mechdsl.loads", "mechdsl.api.Model.equilibria", "mechdsl.api.Model.linearize",
            "mechdsl.api.Model.first_integrals", "mechdsl.output.result.Result.summary"} <= names
    assert len(names) > 90


def test_every_public_function_and_method_has_a_docstring():
    missing = [name for name, obj in public_api() if not (obj.__doc__ or "").strip()]
    assert not missing, "no docstring: " + ", ".join(missing)


def test_help_of_load_says_how_to_call_it():
    doc = inspect.getdoc(mechdsl.load)
    for word in ("path", "model, scene", "units", "cache", "MechError", "mechdsl.examples.path"):
        assert word in doc


def test_the_examples_in_the_docstrings_run_as_shown():
    for obj in (mechdsl.load, mechdsl.loads, Model.equilibria):
        runner = doctest.DocTestRunner(optionflags=doctest.ELLIPSIS)
        for test in doctest.DocTestFinder().find(obj, globs={"mechdsl": mechdsl}):
            runner.run(test)
        assert runner.tries >= 2 and runner.failures == 0, obj.__qualname__


def test_a_result_is_one_line():
    m = mechdsl.load(mechdsl.examples.path("pendulum"), scene="Swing")
    r = m.simulate(3.0, points=3001)
    text = repr(r)
    assert "\n" not in text and len(text) < 200
    assert text.startswith("<mechdsl.Result Pendulum, scene Swing: t = 0 .. 3 s, 3001 points, 1 coordinate, ")
    assert text.endswith("; ok>")
    assert "<table" in r._repr_html_()                        # the notebook display stays rich
    failed = mechdsl.loads("model Blow\n  coordinate Real x(start = 1, speed = 0);\nequation\n"
                           "  kinetic = 1/2*der(x)^2;\n  potential = -x^4;\nend Blow;\n").simulate(10.0)
    assert not failed.success and f"FAILED at t = {failed.failure.time:.6g}" in repr(failed)


def test_equations_say_their_count_and_form():
    p = mechdsl.load(mechdsl.examples.path("pendulum"))
    assert repr(p.equations()).startswith("<1 Lagrange equation: Eq(")
    assert repr(p.equations(form="hamilton")).startswith("<2 Hamilton equations: Eq(")
