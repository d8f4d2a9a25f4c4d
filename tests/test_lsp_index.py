"""The front-end pieces the language server stands on: the symbol index (semantic/symbols.py) and
the catalog of names (semantic/catalog.py), checked against the shipped models and against what
the compiler itself accepts."""
from __future__ import annotations

import pytest

from conftest import model_files
from lsp_client import where
from mechdsl import loads
from mechdsl.diagnostics import MechError
from mechdsl.frontend.parser import parse, parse_file
from mechdsl.semantic import SCENE_SETTINGS
from mechdsl.semantic import catalog as C
from mechdsl.semantic import components as K
from mechdsl.semantic.entries import COORD_ATTRS
from mechdsl.semantic.evaluate import ALL_FUNCS, BUILTIN_NAMES
from mechdsl.semantic.scalar_decls import PARAM_ATTRS
from mechdsl.semantic.symbols import SymbolIndex


def _text_at(lines: list[str], span) -> str:
    assert span.line == span.end_line, span
    return lines[span.line - 1][span.col - 1:span.end_col - 1]


@pytest.mark.parametrize("path", model_files(), ids=lambda p: p.name)
def test_every_name_of_a_shipped_model_is_found_and_resolved(path):
    text = path.read_text()
    lines = text.split("\n")
    ix = SymbolIndex(parse_file(path))
    assert ix.occurrences
    for o in ix.occurrences:
        assert _text_at(lines, o.span) == o.name, o              # every span covers its name
        if o.symbol is not None:
            assert o.symbol.name == o.name
            assert _text_at(lines, o.symbol.name_span) == o.name  # and so does its definition
    # the shipped models compile, so every name in them means something
    unresolved = [o for o in ix.occurrences if o.role in ("reference", "type") and o.symbol is None and o.owner is None]
    assert not unresolved, unresolved[:5]
    for o in ix.occurrences:
        if o.role == "member" and o.symbol is None:
            owner = o.owner or ""
            if owner.startswith("class:"):
                assert C.class_member(owner[6:], o.name) is not None, o
            elif owner.startswith("scalar:"):
                assert o.name in C.SCALAR_ATTRIBUTES, o
            else:
                assert owner in ("world", "point") and o.name in C.KINEMATIC, o
        if o.role == "setting":
            assert o.name in C.SETTINGS


SOURCE = """\
model Base "a base"
  parameter Real m(unit = "kg") = 2;
  coordinate Real x(start = 0.5);
equation
  kinetic = m/2*der(x)^2;
end Base;

model Link
  parameter Real L = 1;
  Rod rod(m = 1, L = L);
end Link;

model Top
  extends Base(m = 3);
  Link link(L = 2);
  Link chain[3](L = 1);
  output Real e = link.rod.b.x + m + chain[2].L;
  output Real w3 = link.rod.w_body[3];
equation
  for i in 1:3 loop
    potential = i*x;
  end for;
end Top;

scene S
  model Top(m = 4, link(L = 5));
  stop_time = m;
end S;
"""


def _occ(ix, text, needle, nth=0, delta=0):
    return ix.at(*where(text, needle, nth, delta))


def test_scopes_extends_instances_and_members():
    ix = SymbolIndex(parse(SOURCE))
    assert [s.name for s in ix.scope("Top").values()] == ["link", "chain", "e", "w3", "m", "x"]
    assert ix.scope("Top")["m"].container == "Base"                      # inherited through extends
    o = _occ(ix, SOURCE, "m + chain")
    assert o.role == "reference" and o.symbol.container == "Base" and o.symbol.kind == "parameter"
    o = _occ(ix, SOURCE, "Base(m = 3)", delta=5)                       # an extends modifier: Base's m
    assert o.role == "member" and o.symbol is ix.scope("Base")["m"]
    o = _occ(ix, SOURCE, "Link link(L = 2)", delta=10)                 # an instance modifier: Link's L
    assert o.symbol is ix.own("Link")["L"] and o.path == "link.L"
    o = _occ(ix, SOURCE, "link.rod.b.x", delta=5)                      # instance member: Link's rod
    assert o.symbol is ix.own("Link")["rod"] and o.path == "link.rod"
    o = _occ(ix, SOURCE, "link.rod.b.x", delta=9)                      # a Rod's named point
    assert o.owner == "class:Rod" and o.symbol is None
    assert _occ(ix, SOURCE, "link.rod.b.x", delta=11).owner == "point"  # a point's attribute
    assert _occ(ix, SOURCE, "w_body").owner == "class:Rod"
    assert _occ(ix, SOURCE, "chain[2].L", delta=9).symbol is ix.own("Link")["L"]
    o = _occ(ix, SOURCE, "i*x")
    assert o.symbol.kind == "loop variable" and o.symbol.name_span.line == 20
    o = _occ(ix, SOURCE, "model Top(m", delta=6)                        # a scene's model
    assert o.role == "type" and o.symbol is ix.units["Top"]
    assert _occ(ix, SOURCE, "link(L = 5)", delta=5).symbol is ix.own("Link")["L"]
    o = _occ(ix, SOURCE, "stop_time = m", delta=12)                    # a setting's value: the model's names
    assert o.symbol is ix.scope("Base")["m"]
    assert _occ(ix, SOURCE, "stop_time").owner == "setting"
    assert _occ(ix, SOURCE, "der(").owner == "function"
    assert _occ(ix, SOURCE, "Rod rod").owner == "class:Rod"
    assert _occ(ix, SOURCE, 'unit = "kg"').owner == "scalar:parameter"
    assert _occ(ix, SOURCE, "start = 0.5").owner == "scalar:coordinate"
    # a cursor just after a name finds it
    o = _occ(ix, SOURCE, "Link link", delta=4)
    assert o is not None and o.name == "Link"


def test_a_file_with_cyclic_extends_and_unknown_names_is_indexed():
    src = "model A\n  extends B;\n  Real y = nothere.x;\nend A;\nmodel B\n  extends A;\nend B;\n"
    ix = SymbolIndex(parse(src))
    assert list(ix.scope("A")) == ["y"]
    o = _occ(ix, src, "nothere")
    assert o.role == "reference" and o.symbol is None
    assert _occ(ix, src, "nothere.x", delta=8).symbol is None


# ----------------------------------------------------------------------------- the catalog


def test_catalog_names_what_the_compiler_knows():
    assert set(C.FUNCTIONS) == set(ALL_FUNCS)
    assert set(C.BUILTIN_VALUES) == set(BUILTIN_NAMES)
    assert set(C.SETTINGS) == set(SCENE_SETTINGS)
    assert set(C.SCALAR_ATTRIBUTES) == set(PARAM_ATTRS) | set(COORD_ATTRS)
    for cls in K.CLASSES.values():
        names = [m.name for m in C.modifier_members(cls.name)]
        assert [f.name for f in cls.fields] == names[:len(cls.fields)]


def _outputs(m) -> set[str]:
    return {o.name.split("[")[0] for o in m.model.outputs}      # o[3] is o[1], o[2], o[3]


_SHAPE = {"r": "[3]", "v": "[3]", "a": "[3]", "w": "[3]", "w_body": "[3]", "alpha": "[3]", "R": "[3, 3]",
          "axis": "[3]", "r_cm": "[3]", "I": "[3, 3]", "size": "[3]"}


@pytest.mark.parametrize("cls", ["Rod", "Body", "Cylinder"])
def test_every_member_the_catalog_offers_after_a_dot_compiles(cls):
    """Completion offers c.NAME for a body: each one, written in an output, compiles (a named
    point through its x)."""
    fields = {"Rod": "m = 1, L = 2", "Body": "m = 1, I = diagonal({1, 1, 1})", "Cylinder": "m = 1, R = 0.1, L = 1"}
    outs = []
    for k, m in enumerate(C.class_members(cls)):
        if m.kind == "point":
            outs.append(f"  output Real o{k} = c.{m.name}.x;")
        elif m.kind in ("field", "attribute"):
            if m.kind == "field" and m.name.startswith("I_"):
                continue                           # Body's I_11 ... are not set when I is given
            if m.kind == "field" and m.name in ("shape", "size", "measured_inertia"):
                continue                           # drawing and data flags: a string, unset, a boolean
            outs.append(f"  output Real o{k}{_SHAPE.get(m.name, '')} = c.{m.name};")
    src = (f"model M\n  {cls} c({fields[cls]});\n  Revolute j(parent = world, child = c, axis = {{0, 0, 1}});\n"
           + "\n".join(outs) + "\nend M;\n")
    assert len(_outputs(loads(src))) == len(outs) > 8


def test_joint_variables_and_world_attributes_compile():
    outs = [f"  output Real w{k}{_SHAPE.get(m.name, '')} = world.{m.name};" for k, m in enumerate(C.world_members())]
    outs += [f"  output Real j{k} = j.{m.name};" for k, m in enumerate(C.role_members(K.CLASSES["Planar"]))
             if not m.name.startswith("q")]
    src = ("model M\n  Rod c(m = 1, L = 2);\n  Planar j(parent = world, child = c.a);\n" + "\n".join(outs)
           + "\nend M;\n")
    assert len(_outputs(loads(src))) == len(outs)
    with pytest.raises(MechError) as e:      # and a name the catalog does not offer does not
        loads("model M\n  Rod c(m = 1, L = 2);\n  Revolute j(parent = world, child = c.a);\n"
              "  output Real o = c.nothing;\nend M;\n")
    assert e.value.first.code == "E219"
