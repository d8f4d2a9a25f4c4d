"""``@record``: a frozen dataclass made cheaply (issue 12's cold start).

``@dataclass(frozen=True)`` compiles six methods per class (``exec`` of generated source) and
builds a docstring with ``inspect.signature``: about 0.4 ms a class, 13 ms for the 33 classes of
:mod:`mechdsl.model.ir`, which every run needs (the model cache unpickles an ``ir.Model``).  ``record``
makes the same class: frozen, ``__eq__`` and ``__hash__`` on the tuple of the fields,
``__repr__``, ``__match_args__`` and real ``dataclasses.Field`` objects in
``__dataclass_fields__``, so ``dataclasses.fields``, ``replace``, ``asdict`` and
``is_dataclass`` work as on a dataclass.  The methods are shared: ``__eq__``, ``__hash__``,
``__repr__``, ``__setattr__`` and ``__delattr__`` are one function each for every record (``__eq__``
and ``__hash__`` one closure per class over its key), and
``__init__`` is compiled once per signature (field names, which ones have a default factory)
and bound to each class's defaults.

``@record(frozen=False)`` is ``@dataclass`` (mutable, unhashable); ``@record(order=True)``
adds the comparisons of ``@dataclass(order=True)``; ``@record(eq=False)`` compares and hashes
by identity; ``@record(kw_only=True)`` is ``@dataclass(kw_only=True)``: keyword-only
``__init__``, and the fields of ``kw_only`` record bases inherited (first, in dataclass's order;
the front end's AST, 27 classes: 31 ms of a first run as dataclasses); ``__post_init__`` is
called as a dataclass calls it.  Supported: annotated fields with a plain
default or ``dataclasses.field(default=..., default_factory=..., repr=..., compare=...)``; a
record base class with no fields.  Anything else (``ClassVar``, ``InitVar``, fields
inherited from a base that is not a kw_only record, ``hash``/``init`` options, ``kw_only``
per field) is refused with TypeError: use ``@dataclass`` for those.
"""
from __future__ import annotations

import dataclasses
from operator import attrgetter
from reprlib import recursive_repr
from types import FunctionType

_MISSING = dataclasses.MISSING
_FIELD = dataclasses._FIELD            # the marker dataclasses.fields() selects on
_FACTORY = object()                    # default of an argument whose field has a default factory
_INITS: dict[tuple, object] = {}       # (names, factory flags) -> code of __init__


def _init_code(names: tuple[str, ...], factory: tuple[bool, ...], post: bool, kw_only: bool = False):
    key = (names, factory, post, kw_only)
    code = _INITS.get(key)
    if code is None:
        star = "*, " if kw_only else ""
        lines = [f"def __init__(self, {star}{', '.join(names)}):" if names else "def __init__(self):"]
        for n, fac in zip(names, factory):
            value = f"_f_{n}() if {n} is _FACTORY else {n}" if fac else n
            lines.append(f"    _set(self, {n!r}, {value})")
        if post:
            lines.append("    self.__post_init__()")
        if not names and not post:
            lines.append("    pass")
        ns: dict = {}
        exec("\n".join(lines), {}, ns)
        code = _INITS[key] = ns["__init__"].__code__
    return code


def _key(names: tuple[str, ...]):
    if len(names) >= 2:
        return attrgetter(*names)
    if len(names) == 1:
        get = attrgetter(names[0])
        return lambda self: (get(self),)
    return lambda self: ()


def _eq_hash(key):
    """__eq__ and __hash__ on the tuple ``key(self)`` (closures: no lookup of the key per call)."""
    def __eq__(self, other):
        if other.__class__ is self.__class__:
            return key(self) == key(other)
        return NotImplemented

    def __hash__(self):
        return hash(key(self))
    return __eq__, __hash__


def _order(test):
    def compare(self, other):
        if other.__class__ is self.__class__:
            key = self.__class__._record_key
            return test(key(self), key(other))
        return NotImplemented
    return compare


_ORDER = {"__lt__": _order(lambda a, b: a < b), "__le__": _order(lambda a, b: a <= b),
          "__gt__": _order(lambda a, b: a > b), "__ge__": _order(lambda a, b: a >= b)}


@recursive_repr()
def _repr(self):
    cls = self.__class__
    return f"{cls.__qualname__}(" + ", ".join(f"{n}={getattr(self, n)!r}" for n in cls._record_repr) + ")"


def _setattr(self, name, value):
    if "_record_frozen" in type(self).__dict__ or name in self.__dataclass_fields__:
        raise dataclasses.FrozenInstanceError(f"cannot assign to field {name!r}")
    object.__setattr__(self, name, value)


def _delattr(self, name):
    if "_record_frozen" in type(self).__dict__ or name in self.__dataclass_fields__:
        raise dataclasses.FrozenInstanceError(f"cannot delete field {name!r}")
    object.__delattr__(self, name)


def record(cls=None, /, *, frozen: bool = True, order: bool = False, eq: bool = True, kw_only: bool = False):
    """The class as a dataclass (frozen unless ``frozen=False``; see the module docstring)."""
    if cls is None:
        return lambda c: _make(c, frozen, order, eq, kw_only)
    return _make(cls, frozen, order, eq, kw_only)


def _inherited(cls) -> dict:
    """The fields of the record bases of ``cls`` (kw_only records), in dataclass's order."""
    out: dict[str, dataclasses.Field] = {}
    for base in cls.__mro__[-1:0:-1]:
        own = base.__dict__.get("__dataclass_fields__")
        if own:
            if "_record_kw_only" not in base.__dict__:
                raise TypeError(f"record {cls.__name__}: fields inherited from {base.__name__}, not a "
                                "kw_only record: use @dataclass")
            out.update(own)
    return out


def _make(cls, frozen: bool, order: bool, eq: bool = True, kw_only: bool = False):
    if getattr(cls, "__dataclass_fields__", None) and not kw_only:
        raise TypeError(f"record {cls.__name__}: fields inherited: use @dataclass")
    if order and not eq:
        raise ValueError("eq must be true if order is true")
    fields: dict[str, dataclasses.Field] = _inherited(cls) if kw_only else {}
    defaults: list = []
    globs = {"_set": object.__setattr__ if frozen else setattr, "_FACTORY": _FACTORY}
    for f in fields.values():               # (kw_only: the inherited fields' defaults)
        if f.default_factory is not _MISSING:
            globs[f"_f_{f.name}"] = f.default_factory
    for name, kind in cls.__dict__.get("__annotations__", {}).items():
        if "ClassVar" in str(kind) or "InitVar" in str(kind):
            raise TypeError(f"record {cls.__name__}.{name}: ClassVar/InitVar: use @dataclass")
        value = cls.__dict__.get(name, _MISSING)
        f = value if isinstance(value, dataclasses.Field) else dataclasses.field(default=value)
        if not (f.init and f.hash is None and f.kw_only in (False, _MISSING)):
            raise TypeError(f"record {cls.__name__}.{name}: field options: use @dataclass")
        f.name, f.type, f._field_type = name, kind, _FIELD
        if kw_only:
            f.kw_only = True
        fields[name] = f
        if f.default_factory is not _MISSING:
            globs[f"_f_{name}"] = f.default_factory
            defaults.append(_FACTORY)
        elif f.default is not _MISSING:
            defaults.append(f.default)
        elif defaults and not kw_only:
            raise TypeError(f"record {cls.__name__}: non-default field {name!r} after a default")
        if isinstance(value, dataclasses.Field):
            if f.default is _MISSING:
                delattr(cls, name)
            else:
                setattr(cls, name, f.default)
    names = tuple(fields)
    code = _init_code(names, tuple(f.default_factory is not _MISSING for f in fields.values()),
                      hasattr(cls, "__post_init__"), kw_only)
    if kw_only:                       # keyword-only: the defaults by name, any field order
        init = FunctionType(code, globs, "__init__")
        init.__kwdefaults__ = {n: _FACTORY if f.default_factory is not _MISSING else f.default
                               for n, f in fields.items()
                               if f.default_factory is not _MISSING or f.default is not _MISSING} or None
        cls._record_kw_only = True
    else:
        init = FunctionType(code, globs, "__init__", tuple(defaults) or None)
    init.__qualname__ = f"{cls.__qualname__}.__init__"
    cls.__init__ = init
    cls.__dataclass_fields__ = fields
    cls.__match_args__ = () if kw_only else names
    cls._record_key = _key(tuple(n for n, f in fields.items() if f.compare))
    cls._record_repr = tuple(n for n, f in fields.items() if f.repr)
    eq_, hash_ = _eq_hash(cls._record_key)
    methods = {"__repr__": _repr, **({"__eq__": eq_} if eq else {}), **(_ORDER if order else {})}
    if frozen:
        cls._record_frozen = True
        methods.update(__setattr__=_setattr, __delattr__=_delattr)
    for k, fn in methods.items():
        if k not in cls.__dict__:
            setattr(cls, k, fn)
    if eq and ("__hash__" not in cls.__dict__ or cls.__dict__["__hash__"] is None):
        cls.__hash__ = hash_ if frozen else None    # (eq=False: object's, by identity)
    cls.__dataclass_params__ = _params(frozen, order, eq)
    if cls.__doc__ is None:             # dataclass's docstring: the signature of __init__
        cls.__doc__ = f"{cls.__name__}({'*, ' if kw_only and fields else ''}" \
                      f"{', '.join(_shown(f) for f in fields.values())})"
    return cls


def _shown(f: dataclasses.Field) -> str:
    """A parameter as inspect.signature shows it (the annotations are strings here)."""
    if isinstance(f.type, str):
        text = f"{f.name}: {f.type!r}"
    else:
        import inspect

        text = f"{f.name}: {inspect.formatannotation(f.type)}"
    if f.default_factory is not _MISSING:
        return text + " = <factory>"
    return text if f.default is _MISSING else f"{text} = {f.default!r}"


_PARAMS: dict[tuple[bool, bool, bool], object] = {}


def _params(frozen: bool, order: bool, eq: bool):
    """The ``__dataclass_params__`` of @dataclass(frozen=, order=, eq=) (dask reads it)."""
    p = _PARAMS.get((frozen, order, eq))
    if p is None:
        cls = dataclasses._DataclassParams
        given = dict(init=True, repr=True, eq=eq, order=order, unsafe_hash=False, frozen=frozen,
                     match_args=True, kw_only=False, slots=False, weakref_slot=False)
        p = _PARAMS[(frozen, order, eq)] = cls(**{k: v for k, v in given.items() if k in cls.__slots__})
    return p
