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


def test_kw_only_records_inherit_fields_as_kw_only_dataclasses():
    """The front end's AST: keyword-only classes that inherit the span of their base (issue 24
    item 8: 27 dataclasses were 31 ms of a first run)."""
    made = []
    for deco in (record(kw_only=True), dataclasses.dataclass(frozen=True, kw_only=True)):
        ns: dict = {}
        exec("from __future__ import annotations\nimport dataclasses\nfrom mechdsl.diagnostics import Span\n"
             "class Node:\n    span: Span = dataclasses.field(default_factory=Span, compare=False, repr=False)\n"
             "class Expr(Node):\n    pass\n"
             "class Ref(Expr):\n    name: str\n    subs: tuple = ()\n"
             "    extra: Span = dataclasses.field(default_factory=Span, compare=False, repr=False)\n"
             "class Call(Expr):\n    f: Ref\n    label: str = dataclasses.field(default='x', compare=False)\n"
             "    args: tuple\n", ns)
        node = deco(ns["Node"])
        ns["Expr"].__bases__ = (node,)
        expr = deco(ns["Expr"])
        for k in ("Ref", "Call"):
            ns[k].__bases__ = (expr,)
        made.append((node, expr, deco(ns["Ref"]), deco(ns["Call"])))
    (N, E, R, C), (DN, DE, DR, DC) = made
    s1, s2 = Span("f", 1, 2, 1, 3), Span("g", 4, 5, 4, 6)
    for ours, theirs in ((R, DR), (C, DC), (E, DE)):
        assert [(f.name, f.default, f.default_factory, f.compare, f.repr, f.kw_only) for f in dataclasses.fields(ours)] \
            == [(f.name, f.default, f.default_factory, f.compare, f.repr, f.kw_only) for f in dataclasses.fields(theirs)]
        assert ours.__match_args__ == theirs.__match_args__ == ()
    r, d = R(name="a", span=s1), DR(name="a", span=s1)
    assert repr(r) == repr(d) == "Ref(name='a', subs=())"
    assert r == R(name="a", span=s2) and hash(r) == hash(d) == hash(R(name="a"))    # spans do not compare
    assert r != R(name="b") and r.subs == () and R(name="a").span == Span() and R(name="a").span is not R(name="a").span
    c, dc = C(f=r, args=(1,), span=s1), DC(f=d, args=(1,), span=s1)
    assert c.label == dc.label == "x" and dataclasses.asdict(c)["f"]["name"] == "a"
    assert c == C(f=r, args=(1,), label="other") and hash(c) == hash(C(f=R(name="a"), args=(1,)))
    c2 = dataclasses.replace(c, args=(2,))
    assert type(c2) is C and c2.args == (2,) and c2.span is s1 and c2 != c
    for bad in (lambda: R("a"), lambda: C(f=r), lambda: R(name="a", other=1)):
        with pytest.raises(TypeError):
            bad()
    with pytest.raises(dataclasses.FrozenInstanceError):
        r.name = "b"
    assert isinstance(c, E) and isinstance(c, N) and dataclasses.is_dataclass(C)


def test_a_record_inherits_fields_only_from_kw_only_records():
    @record
    class A:
        x: int = 1

    with pytest.raises(TypeError):
        @record(kw_only=True)
        class B(A):
            y: int = 2
