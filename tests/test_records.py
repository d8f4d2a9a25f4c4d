"""mechdsl.model.records.record: the same class as @dataclass(frozen=True), made cheaply (issue 12).
Each behaviour is compared with a real frozen dataclass of the same fields."""
import dataclasses
import math
import pickle

import pytest

from mechdsl.model import ir
from mechdsl.diagnostics import Span
from mechdsl.model.records import record


def pair(body, **options):
    """(record class, dataclass) from the same class body."""
    made = []
    for decorate in (record(**options), dataclasses.dataclass(**{"frozen": True, **options})):
        ns: dict = {}
        exec("from __future__ import annotations\nimport dataclasses, typing\nfrom mechdsl.diagnostics import Span\n"
             "class C:\n" + body, ns)
        made.append(decorate(ns["C"]))
    return tuple(made)


BODY = ("    name: str\n    i: int = 2\n    span: Span = dataclasses.field(default_factory=Span)\n"
        "    xs: tuple = ()\n")


def test_record_behaves_as_a_frozen_dataclass():
    R, D = pair(BODY)
    for args, kw in (((("a",)), {}), (("a", 3), {"xs": (1.0,)}), ((), {"name": "b", "i": 5})):
        r, d = R(*args, **kw), D(*args, **kw)
        assert repr(r) == repr(d)
        assert [(f.name, f.type, f.default, f.default_factory) for f in dataclasses.fields(r)] == \
               [(f.name, f.type, f.default, f.default_factory) for f in dataclasses.fields(d)]
        assert dataclasses.asdict(r) == dataclasses.asdict(d)
        assert hash(r) == hash(d)
        assert R.__match_args__ == D.__match_args__ and R.__doc__ == D.__doc__
        assert repr(R.__dataclass_params__) == repr(D.__dataclass_params__)
        r2 = dataclasses.replace(r, i=7)
        assert (type(r2), r2.i, r2.name, r2.span) == (R, 7, r.name, r.span) and r2 != r
        assert r == R(*args, **kw) and r != d and (r == d) is False
        for action in (lambda: setattr(r, "i", 1), lambda: setattr(r, "new", 1), lambda: delattr(r, "i")):
            with pytest.raises(dataclasses.FrozenInstanceError):
                action()
    assert dataclasses.is_dataclass(R) and R.i == 2 and "span" not in R.__dict__
    with pytest.raises(TypeError):
        R()
    with pytest.raises(TypeError):
        R("a", 1, Span(), (), 5)
    assert R("a").span is not R("a").span and R("a").span == Span()   # a factory call per instance


def test_record_equality_is_tuple_equality():
    """A NaN field: equal when it is the same object (tuple comparison), as in a dataclass."""
    nan = math.nan
    R, D = pair("    value: float\n")
    assert (R(nan) == R(nan)) == (D(nan) == D(nan)) is True
    assert (R(float("nan")) == R(float("nan"))) == (D(float("nan")) == D(float("nan")))
    assert hash(R(1.0)) == hash(D(1.0)) == hash((1.0,))
    E, F = pair("    pass\n")
    assert E() == E() and hash(E()) == hash(F()) == hash(()) and repr(E()) == repr(F())


def test_identity_equality_and_post_init_as_in_a_dataclass():
    R, D = pair("    a: int\n    b: dict = dataclasses.field(default_factory=dict)\n"
                "    def __post_init__(self):\n        object.__setattr__(self, 'b', {'a': self.a})\n", eq=False)
    r, d = R(1), D(1)
    assert r.b == d.b == {"a": 1} and repr(r) == repr(d) and R.__doc__ == D.__doc__
    assert r != R(1) and r == r and hash(r) == id(r) // 16 == object.__hash__(r) and D(1) != d
    assert repr(R.__dataclass_params__) == repr(D.__dataclass_params__)
    with pytest.raises(dataclasses.FrozenInstanceError):
        r.a = 2


def test_record_refuses_what_it_does_not_do():
    for body in ("    x: int = dataclasses.field(default=1, hash=True)\n",
                 "    x: int = 1\n    y: int\n",
                 "    x: typing.ClassVar[int] = 1\n"):
        with pytest.raises(TypeError):
            pair(body)


def test_mutable_ordered_and_uncompared_fields_as_in_a_dataclass():
    R, D = pair("    a: int\n    b: list = dataclasses.field(default_factory=list)\n", frozen=False)
    r, d = R(1), D(1)
    r.a, d.a = 2, 2
    r.b.append(3)
    d.b.append(3)
    assert repr(r) == repr(d) == "C(a=2, b=[3])" and r.b is not R(1).b and R.__hash__ is D.__hash__ is None
    assert r == R(2, [3]) and r != R(2) and R.__doc__ == D.__doc__
    assert repr(R.__dataclass_params__) == repr(D.__dataclass_params__)
    R, D = pair("    line: int = 0\n    col: int = 0\n", order=True)
    pairs = [(1, 2), (1, 3), (0, 9), (1, 2)]
    assert sorted(R(*p) for p in pairs) == sorted(R(*p) for p in sorted(pairs))
    assert [R(*a) < R(*b) for a in pairs for b in pairs] == [D(*a) < D(*b) for a in pairs for b in pairs]
    assert [R(*a) >= R(*b) for a in pairs for b in pairs] == [D(*a) >= D(*b) for a in pairs for b in pairs]
    R, D = pair("    a: int\n    note: object = dataclasses.field(default=None, repr=False, compare=False)\n")
    assert R(1, "x") == R(1, "y") and hash(R(1, "x")) == hash(D(1, "y")) and repr(R(1, "x")) == repr(D(1, "x"))


def test_ir_classes_are_records_with_their_methods():
    j = ir.Joint("j", "revolute", "a", "b", "A", "B", options=(("sequence", "zyx"),))
    assert j.option("sequence") == "zyx" and j.axis == (ir.ZERO, ir.ZERO, ir.ONE)
    m = ir.Model("m", coordinates=(ir.Coordinate("q"),))
    assert m.coordinate_names == ("q",) and m.coordinate("q").start == ir.ZERO
    assert repr(ir.Op("add", (ir.Param("a"), ir.Const(1.0)))) == \
        "Op(op='add', args=(Param(name='a'), Const(value=1.0)))"
    assert {ir.Coord("q"): 1}[ir.Coord("q")] == 1 and ir.Coord("q") != ir.Speed("q")
    assert ir.BodyOmega("b", 0).frame == "world" and isinstance(ir.Const(1.0), ir.Expr)
    back = pickle.loads(pickle.dumps(m))
    assert back == m and type(back.coordinates[0]) is ir.Coordinate and hash(back) == hash(m)
