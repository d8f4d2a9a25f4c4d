"""The workspace of an equations-of-motion object: everything derived from it and kept.

``eom.EOM`` is frozen: nothing may set attributes on it once derived.  What the phases derive
from it and want to keep (CasADi Functions, the recorder's mapped Functions, the first-integral
search, the DAE's KKT systems, the analyses' Parts) lives here instead, in a ``Workspace`` that
belongs to one EOM object and dies with it (a weak-key registry: ``of(eom)``).  ``api.Model``
holds its workspace (``Model.workspace``) for as long as it holds its EOM.

Two levels:

- ``memo(key, build)``: values of *this* EOM object (Functions of its fields, results for its
  parameter values).  ``EOM.replace`` makes a new object and so starts afresh.
- ``shared(key, build)``: values keyed by symbolic content (ids of SX fields, active sets),
  shared by the copies ``EOM.replace`` makes of one derived EOM (``inherit``), so
  ``with_params`` does not rebuild the analyses' Functions.

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
        """The value for ``key`` shared with the EOM's ``replace`` copies (key by content)."""
        return self._shared.get(key, build)

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

    def recorder(self, key: Hashable, build: Callable[[], T]) -> T:
        """The recorder's Function for a key of column names and the identities of the
        symbolic fields it reads (simulation/record.py); shared with ``replace`` copies."""
        return self.shared(key, build)


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
