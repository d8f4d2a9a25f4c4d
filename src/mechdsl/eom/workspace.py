"""The workspace of an equations-of-motion object: everything derived from it and kept.

``eom.EOM`` is frozen: nothing may set attributes on it once derived.  What the phases derive
from it and want to keep (CasADi Functions, the recorder's mapped Functions, the first-integral
search, the DAE's KKT systems, the analyses' Parts) lives here instead, in a ``Workspace`` that
belongs to one EOM object and dies with it (a weak-key registry: ``of(eom)``).  ``api.Model``
holds its workspace (``Model.workspace``) for as long as it holds its EOM.

Two levels:

- ``memo(key, build)``: values of *this* EOM object (Functions of its fields, results for its
  parameter values).  ``EOM.replace`` makes a new object and so starts afresh.
- ``by_content(eom, fields, key, build)``: values shared by the copies ``EOM.replace`` makes
  of one derived EOM (``inherit``) as long as the fields they read are the same objects, so
  ``with_params`` and another model of the same structure rebuild nothing, while a copy with
  other equations (``Drive.close_eom``, ``fold_inputs``) builds its own.  (``shared(key,
  build)`` is the raw store: the key must name the content.)

Thread safety: distinct EOMs have distinct workspaces and never contend; on one workspace a
value is built outside the lock and the first one stored wins (a race builds twice, never
returns two different objects for one key).  Named accessors below give the cross-module
values a type and one place; phase-private caches use ``memo``/``shared`` with a key that
starts with the phase's name.
"""
from __future__ import annotations

import threading
import weakref
from typing import Callable, Hashable, TypeVar

T = TypeVar("T")

_REGISTRY: "weakref.WeakKeyDictionary[object, Workspace]" = weakref.WeakKeyDictionary()
_REGISTRY_LOCK = threading.Lock()


class _Store:
    """A dict with a lock: get-or-build with first-stored-wins."""

    __slots__ = ("_data", "_lock")

    def __init__(self):
        self._data: dict = {}
        self._lock = threading.Lock()

    def get(self, key: Hashable, build: Callable[[], T]) -> T:
        try:
            return self._data[key]
        except KeyError:
            pass
        value = build()                    # outside the lock: a build may use the workspace
        with self._lock:
            return self._data.setdefault(key, value)

    def peek(self, key: Hashable, default=None):
        return self._data.get(key, default)

    def items(self) -> list:
        with self._lock:
            return list(self._data.items())


class Workspace:
    """Derived values of one EOM (see the module docstring)."""

    __slots__ = ("_own", "_shared", "__weakref__")

    def __init__(self, shared: _Store | None = None):
        self._own = _Store()
        self._shared = _Store() if shared is None else shared

    # -- generic ---------------------------------------------------------------------------
    def memo(self, key: Hashable, build: Callable[[], T]) -> T:
        """The value for ``key`` of this EOM object, built once."""
        return self._own.get(key, build)

    def shared(self, key: Hashable, build: Callable[[], T]) -> T:
        """The value for ``key`` shared with the EOM's ``replace`` copies; the key must name
        the content it depends on (see ``by_content``)."""
        return self._shared.get(key, build)

    def by_content(self, eom, fields: tuple, key: Hashable, build: Callable[[], T], extra: tuple = ()) -> T:
        """A value shared with those ``replace`` copies whose ``fields`` (raw entries: lazy
        fields stay lazy) and ``extra`` objects are the same objects as this EOM's: a copy
        with other equations (``Drive.close_eom``, ``fold_inputs``) builds its own.  The
        entry holds the objects, so their ids stay unique while it lives."""
        objs = tuple(eom.__dict__.get(f) for f in fields) + tuple(extra)
        return self._shared.get((key, tuple(map(id, objs))), lambda: (objs, build()))[1]

    def peek_by_content(self, eom, fields: tuple, key: Hashable, default=None):
        """What ``by_content`` holds for these fields and key, without building (default: none)."""
        objs = tuple(eom.__dict__.get(f) for f in fields)
        hit = self._shared.peek((key, tuple(map(id, objs))))
        return default if hit is None else hit[1]

    # -- named accessors ---------------------------------------------------------------------
    def start_function(self, eom):
        """casadi.Function p -> (q0, qd0)."""
        import casadi as ca

        return self.memo("start", lambda: ca.Function("start", [eom.p], [eom.q0, eom.qd0]))

    def folded(self, key: Hashable, build: Callable[[], T]) -> T:
        """An EOM with the inputs folded into the parameters (``eom.fold_inputs``); key
        ``"base"`` is the structure, a tuple of input values one valued copy."""
        return self.memo(("folded", key), build)

    def folded_variants(self) -> list:
        """The valued folded copies built so far (the first-integral drift reads their searches)."""
        return [v for k, v in self._own.items()
                if isinstance(k, tuple) and len(k) == 2 and k[0] == "folded" and k[1] != "base"]

    def first_integrals(self, build: Callable[[], T] | None = None):
        """The first-integral Function (t, x, p) found for this EOM, or None.  Without
        ``build``: what was found so far (None when no search ran)."""
        if build is None:
            return self._own.peek("first_integrals")
        return self.memo("first_integrals", build)

    def stored_functions(self, eom, functions: dict | None = None) -> dict | None:
        """The CasADi Functions the model cache read for ``eom``'s structure (modelcache.py),
        by (name, outputs, sx); ``functions``: keep these.  Shared with the ``replace`` copies
        of the same structure (codegen's structure fields), never with other equations."""
        from .codegen import _STRUCTURE

        if functions is not None:
            return self.by_content(eom, _STRUCTURE, "stored_functions", lambda: functions)
        return self.peek_by_content(eom, _STRUCTURE, "stored_functions")

    def recorder(self, eom, fields: tuple, names: tuple, build: Callable[[], T], extra: tuple = ()) -> T:
        """The recorder's Function for a tuple of column names (simulation/record.py), shared
        with the ``replace`` copies whose ``fields`` it reads are the same objects."""
        return self.by_content(eom, fields, ("record", names), build, extra)


def of(eom) -> Workspace:
    """The workspace of ``eom`` (created on first use)."""
    ws = _REGISTRY.get(eom)
    if ws is None:
        with _REGISTRY_LOCK:
            ws = _REGISTRY.get(eom)
            if ws is None:
                ws = _REGISTRY[eom] = Workspace()
    return ws


def inherit(new, old) -> Workspace:
    """Give ``new`` (a ``replace`` copy of ``old``) a fresh workspace that shares ``old``'s
    content-keyed values."""
    shared = of(old)._shared
    with _REGISTRY_LOCK:
        ws = _REGISTRY[new] = Workspace(shared)
    return ws
