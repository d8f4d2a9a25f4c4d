"""The flattener's records: a declaration being evaluated (:class:`Entry`) and one element of a
component declaration (:class:`CompInst`), and what the concerns of the flattener share about them."""
from __future__ import annotations

from dataclasses import field

from ..frontend import ast
from ..model import ir
from . import components as K
from .mods import Mod
from .values import Arr, Val
from ..model.records import record

COORD_ATTRS = {"start", "speed", "fixed", "speed_fixed", "unit", "displayUnit", "min", "max"}


@record(frozen=False)
class Entry:
    decl: ast.Declaration
    kind: str                       # parameter input coordinate output variable component
    mod: Mod
    order: int
    cls: K.ComponentClass | None = None
    dims: tuple[int, ...] | None = None
    value: Val | None = None
    state: int = 0                  # 0 new, 1 busy, 2 done, 3 failed
    params: list[ir.Parameter] = field(default_factory=list)
    coords: list[ir.Coordinate] = field(default_factory=list)
    outputs: list[ir.Output] = field(default_factory=list)
    elements: list["CompInst"] = field(default_factory=list)
    cache: dict = field(default_factory=dict)   # evaluated array-level modifier values
    element_mods: dict = field(default_factory=dict)   # "q[2]" -> Mod: an override of one element (API, --set)


@record(frozen=False)
class CompInst:
    name: str
    entry: Entry
    k: int                          # element index (0-based), -1 for scalar components
    connections: dict[str, Val] = field(default_factory=dict)
    fields: dict[str, Val] = field(default_factory=dict)
    jointvars: list[ir.JointVar] | None = None
    coords: list[ir.Coordinate] = field(default_factory=list)
    built: K.Built | None = None
    busy: set = field(default_factory=set)

    @property
    def cls(self) -> K.ComponentClass:
        return self.entry.cls  # type: ignore[return-value]


class Failed(Exception):
    """An entry already reported an error; dependants stay quiet."""


def pick(val: Val, inst: CompInst, rank: int, each: bool) -> Val:
    """The value of an array-level modifier for one element (split or broadcast)."""
    if inst.k < 0 or each:
        return val
    n = len(inst.entry.elements)
    if isinstance(val, Arr) and len(val.items) == n and array_rank(val) == rank + 1:
        return val.items[inst.k]
    return val


def array_rank(val: Val) -> int:
    """Number of array levels, along the first elements (O(rank), unlike shape_of: once per element)."""
    r = 0
    while isinstance(val, Arr):
        r += 1
        if not val.items:
            break
        val = val.items[0]
    return r


def constval(e: ir.Expr) -> float:
    return e.value if isinstance(e, ir.Const) else 1.0
