"""The model cache: a loaded model's resolved IR and derived equations on disk.

A second run of the same file (same text, same target, same structural settings, same
mechdsl, CasADi and Python) reads one file instead of parsing, analysing and deriving, so
it imports neither lark nor the front end nor the mechanics (issue 12's cold start).

    key(text, filename, units, target, items)      sha256 of everything the result depends on
    read(key) -> Entry | None                      None: no entry, or one that is not usable
    write(key, entry)                              atomic (temporary name, then rename)
    pack_eom(eom) / unpack_eom(data, model)        CasADi SX through one StringSerializer

The file is ``<cache_dir()>/models/<key>.pkl`` (``cache_dir`` of mechdsl.eom.codegen:
MECHDSL_CACHE, else XDG_CACHE_HOME/mechdsl, else ~/.cache/mechdsl): a header line with the
format, the full key and the SHA-256 of the payload, then the payload (a pickle of plain
data: the ir.Model, the ir.Scene, the front end's warnings and the packed equations).  The
key and the hash are checked before the payload is unpickled, so a truncated, replaced,
swapped (another model's) or foreign file is rebuilt, never trusted; any failure to read is
a miss, with its reason at DEBUG.  A pickle runs code when loaded: entries are read only
from a folder and file that no other user owns or can write (mechdsl.eom.cachefiles).

SX expressions are serialized together in one ``casadi.StringSerializer`` stream, which keeps
the symbols shared between them (q in T is the q of the EOM).  Fields the derivation had
not built when the entry was written (the lazy M and bias of the 'aba' route) and the
point/rotation callables are derived again on first use from the cached ir.Model and
substituted into the cached symbols, so they are the same functions of the same symbols.
"""
from __future__ import annotations

from ..digest import sha256
import os
import pickle
import sys
from dataclasses import field, fields
from pathlib import Path

from ..model.records import record

FORMAT = "mechdsl-model-cache 5"     # 5: the full key in the header
MAX_ENTRIES = 1000          # more: the entries written longest ago are removed
_CALLABLES = ("point_position", "point_velocity", "body_rotation")
_PER_MODEL = ("model", "param_values", "input_defaults")     # set again from the Model on load


@record(frozen=False)
class Entry:
    """What a cache file holds."""
    model: object                       # ir.Model
    scene: object | None                # ir.Scene
    target: tuple[str, str]
    warnings: list = field(default_factory=list)
    eom: dict | None = None             # pack_eom(...)


def directory() -> Path:
    from .codegen import cache_dir

    return cache_dir() / "models"


def key(text: str, filename: str, units: bool, target: tuple, items: tuple) -> str:
    """The cache key: the source, how it is read, which target, the structural overrides
    (``items``: (name, value) pairs in the order given), the limits in force and the versions."""
    import casadi

    from .. import __version__
    from ..frontend import limits

    parts = (FORMAT, __version__, code_fingerprint(), casadi.__version__, sys.version, filename, bool(units),
             tuple(target), tuple(items), tuple(sorted(limits.current().items())))
    h = sha256(repr(parts).encode("utf-8"))
    h.update(b"\0")
    h.update(text.encode("utf-8"))
    return h.hexdigest()


_FINGERPRINT: list = []


def code_fingerprint() -> str:
    """mechdsl's own code as the cache sees it: the names, sizes and modification times of its
    source files and grammar (an edited mechdsl under the same version number, as while
    developing, must not be served equations derived by the old code).  Once per process.

    One ``os.scandir`` walk on strings (pathlib's objects cost a warm run about 7 ms for the
    package's 370 files); the same entries, in the same order, as a walk by ``os.walk``."""
    if not _FINGERPRINT:
        here = os.path.dirname(os.path.dirname(os.path.realpath(__file__)))     # the mechdsl package
        root = os.path.dirname(os.path.dirname(here))                           # (its checkout)
        h = sha256()
        lines = []
        for f in (os.path.join(root, "grammar", "mech.lark"), os.path.join(here, "_grammar", "mech.lark")):
            lines.append(_stat_line(f, root))
        _walk_sources(here, root, lines)
        h.update("".join(line for line in lines if line).encode())
        _FINGERPRINT.append(h.hexdigest())
    return _FINGERPRINT[0]


def _stat_line(path: str, root: str) -> str:
    """"<path relative to the checkout>\0<size>\0<mtime ns>\n" of a file, "" if it cannot be read."""
    try:
        st = os.stat(path)
    except OSError:
        return ""
    rel = path[len(root) + 1:] if path.startswith(root + os.sep) else path
    return f"{rel}\0{st.st_size}\0{st.st_mtime_ns}\n"


def _walk_sources(folder: str, root: str, lines: list) -> None:
    """The .py and .lark files under ``folder`` (sorted by name; folders after the files of
    their parent, __pycache__ left out), as ``_stat_line``s."""
    try:
        with os.scandir(folder) as it:
            entries = sorted(it, key=lambda e: e.name)
    except OSError:
        return
    subdirs = []
    for e in entries:
        try:
            is_dir = e.is_dir(follow_symlinks=False)
        except OSError:
            continue
        if is_dir:
            if e.name != "__pycache__":
                subdirs.append(e.path)
        elif e.name.endswith((".py", ".lark")):
            lines.append(_stat_line(e.path, root))
    for d in subdirs:
        _walk_sources(d, root, lines)


def path_of(k: str) -> Path:
    return directory() / f"{k}.pkl"


def header(k: str, payload: bytes) -> bytes:
    """The entry's first line: the format, the full key and the SHA-256 of the payload."""
    return f"{FORMAT} {k} {sha256(payload).hexdigest()}\n".encode("ascii")


def read(k: str) -> Entry | None:
    """The entry under key ``k``, or None (missing, unreadable, corrupt, another key's, not
    trusted: rebuilt).  The key and the hash are checked before the payload is unpickled, and
    only from a folder and file no other user can write (mechdsl.eom.cachefiles)."""
    from . import cachefiles

    data, why = cachefiles.read_bytes(path_of(k))
    if data is None:
        cachefiles.miss("model", k[:16], why)
        return None
    head, sep, payload = data.partition(b"\n")
    parts = head.decode("ascii", "replace").rsplit(" ", 2)
    if not sep or len(parts) != 3 or parts[0] != FORMAT:
        cachefiles.miss("model", k[:16], "an entry of another format or version")
        return None
    if parts[1] != k:
        cachefiles.miss("model", k[:16], f"the entry holds another key ({parts[1][:16]}...): swapped or copied")
        return None
    if sha256(payload).hexdigest() != parts[2]:
        cachefiles.miss("model", k[:16], "the payload does not match its hash (truncated or changed)")
        return None
    try:
        entry = pickle.loads(payload)
    except Exception as e:              # a file written by another version of a dependency
        cachefiles.miss("model", k[:16], f"the payload does not load ({type(e).__name__})")
        return None
    if not isinstance(entry, Entry):
        cachefiles.miss("model", k[:16], "the payload is not a model-cache entry")
        return None
    cachefiles.hit("model", k[:16])
    return entry


def write(k: str, entry: Entry) -> bool:
    """Store ``entry`` atomically; False (and nothing left behind) if the cache is not writable."""
    from . import cachefiles

    try:
        payload = pickle.dumps(entry, protocol=pickle.HIGHEST_PROTOCOL)
    except Exception:                   # something in the model that does not pickle: no entry
        return False
    final = path_of(k)
    new = not final.exists()
    if not cachefiles.write_bytes(final, [header(k, payload), payload]):
        return False
    if new:
        trim(final.parent)
    return True


def trim(folder: Path, keep: int | None = None) -> None:
    """Keep the ``keep`` (default MAX_ENTRIES) entries written last; the cache never grows
    without bound (``mechdsl.loads`` of generated texts adds an entry per text)."""
    keep = MAX_ENTRIES if keep is None else keep
    try:
        found = [(e.stat().st_mtime_ns, e.name, e.path) for e in os.scandir(folder) if e.name.endswith(".pkl")]
    except OSError:
        return
    if len(found) <= keep:
        return
    for _, _, path in sorted(found)[: len(found) - keep]:
        try:
            os.unlink(path)
        except OSError:
            pass


# --------------------------------------------------------------------------- equations


def _is_lazy(v) -> bool:
    return hasattr(v, "fn") and hasattr(v, "value") and not isinstance(v, (list, dict, tuple))   # derive._Lazy


def _resolved(v, name):
    """A raw field value with a built lazy one replaced by what it built (else itself)."""
    if _is_lazy(v) and v.value is not None:
        r = v.value
        return (r[0] if name == "M" else r[1]) if name in ("M", "bias") and isinstance(r, tuple) else r
    return v


def _raw(eom, name):
    """A field's value without forcing a lazy one: (value, known)."""
    v = eom.__dict__.get(name)
    if type(v) is _Pending:
        return (v.value, True) if v.known else (None, False)
    if _is_lazy(v):
        return (None, False) if v.value is None else (_resolved(v, name), True)
    return v, True


class Recorder:
    """A point/rotation callable of an EOM (``point_position(name)``, ...) that keeps its
    results by argument, so that the model cache stores those a run used (contact gaps, loop
    points, drawing) and a later run asks the mechanics only for new ones."""

    def __init__(self, fn, seen=None):
        self.fn = fn
        self.seen = dict(seen or {})

    def __call__(self, *args):
        try:
            hit = self.seen.get(args)
        except TypeError:               # an unhashable argument: not kept
            return self.fn(*args)
        if hit is None:
            hit = self.seen[args] = self.fn(*args)
        return hit


def record_callables(eom):
    """``eom`` with its point/rotation callables wrapped in Recorders (a copy: the EOM is
    frozen; the copies made of it share the Recorders)."""
    wrap = {name: Recorder(v) for name in _CALLABLES
            if (v := eom.__dict__.get(name)) is not None and not isinstance(v, Recorder)}
    return eom.replace(**wrap) if wrap else eom


def pending_fields(eom) -> list[str]:
    """The fields ``pack_eom`` would leave to be derived again (lazy ones not yet built;
    callables that record nothing)."""
    return [f.name for f in fields(eom) if f.name not in _PER_MODEL and
            (f.name in _CALLABLES and eom.__dict__.get(f.name) is not None
             and not isinstance(eom.__dict__.get(f.name), Recorder)
             or f.name not in _CALLABLES and not _raw(eom, f.name)[1]
             or f.name in _CALLABLES and type(eom.__dict__.get(f.name)) is _Pending)]


def _recorded(eom) -> dict:
    return {(name, args): e for name in _CALLABLES if isinstance(eom.__dict__.get(name), Recorder)
            for args, e in list(eom.__dict__[name].seen.items())}


def content(eom) -> tuple[frozenset, frozenset, frozenset]:
    """What an entry of ``eom`` would hold beyond the always-stored fields: (fields left to
    derive again, keys of the CasADi Functions built so far, callable results recorded).  An
    entry is rewritten when a run has built more (fewer pending fields, more Functions or
    more results)."""
    return frozenset(pending_fields(eom)), frozenset(_functions(eom)), frozenset(_recorded(eom))


def _functions(eom) -> dict:
    """The virtual-machine Functions mechdsl.eom.codegen built for ``eom``'s structure, by
    (name, outputs, sx); those read from the cache included."""
    from . import codegen

    out = dict(eom.workspace.stored_functions(eom) or {})
    objs = [_resolved(eom.__dict__.get(f), f) for f in codegen._STRUCTURE]
    for held, fs in list(codegen._SETS.values()):
        # the model's own Functions only (a constrained problem's set has another "ode": dae.functions)
        if type(fs) is not codegen.FunctionSet or fs.want_compiled or fs.fixed or not all(_resolved(a, f) is b for a, b, f in zip(held, objs, codegen._STRUCTURE)):
            continue
        for name, f in list(fs._cache.items()):
            # SX Functions only: they load in about a millisecond; an MX Function (the Jacobian
            # of ode) loads slower than it is built (N = 12 chain: 73 ms against 11-37 ms)
            if f.is_a("SXFunction"):
                out.setdefault((name, fs.outputs, fs.sx), f)
    return out


def pack_eom(eom) -> dict | None:
    """The equations as plain data (None when something in them cannot be stored)."""
    import casadi as ca

    ser = ca.StringSerializer()
    plain: dict = {}
    sx: list[tuple[str, object]] = []           # (field, key-or-None), in the order packed
    pending: list[str] = []
    for f in fields(eom):
        if f.name in _PER_MODEL:
            continue
        if f.name in _CALLABLES:
            v = eom.__dict__.get(f.name)
            if isinstance(v, Recorder):
                for args, e in list(v.seen.items()):
                    ser.pack(ca.SX(e))
                    sx.append((f.name, ("call", args)))
                plain.setdefault("_recorders", []).append(f.name)
            elif v is not None:
                pending.append(f.name)
            continue
        v, known = _raw(eom, f.name)
        if not known or type(v) is _Pending:
            pending.append(f.name)
        elif isinstance(v, ca.SX):
            ser.pack(v)
            sx.append((f.name, None))
        elif isinstance(v, dict) and v and all(isinstance(e, ca.SX) for e in v.values()):
            for name, e in v.items():
                ser.pack(e)
                sx.append((f.name, name))
        elif isinstance(v, (ca.MX, ca.Function)) or callable(v):
            return None
        else:
            plain[f.name] = v
    functions = _texts(_functions(eom))
    return {"plain": plain, "sx": sx, "stream": ser.encode(), "pending": pending, "functions": functions}


def _texts(funcs: dict) -> dict:
    """key -> serialization of the Functions ``funcs`` (key -> Function): each Function once, and
    shared with mechdsl.eom.sxcode's keys (the run's interpreter program, the compiled code),
    which serialize the same Functions (~50 ms for the 200-link chain's ode)."""
    from . import sxcode

    texts: dict = {}
    out = {}
    for k, f in funcs.items():
        t = texts.get(id(f))
        if t is None:
            t = texts[id(f)] = sxcode.text_of(f)
        out[k] = t
    return out


def unpack_eom(data: dict, model):
    """The EOM of ``pack_eom``'s data; ``model`` (ir.Model) serves the fields derived again."""
    import casadi as ca

    des = ca.StringDeserializer(data["stream"])
    values = dict(data["plain"])
    calls: dict = {name: {} for name in values.pop("_recorders", [])}
    for name, sub in data["sx"]:
        e = des.unpack()
        if sub is None:
            values[name] = e
        elif isinstance(sub, tuple) and sub[:1] == ("call",):
            calls[name][sub[1]] = e
        else:
            values.setdefault(name, {})[sub] = e
    for name in ("outputs", "singularity_monitors", "invariants", "reactions"):
        values.setdefault(name, {})
    values.update(model=model, param_values=None)      # the Model sets its own values (api.Model.eom)
    values.update({name: None for name in data["pending"]})
    again = _Again(values)
    values.update({name: _Pending(again, name) for name in data["pending"]})
    # results a run used; new arguments derive the model again
    values.update({name: Recorder(again.value(name), seen) for name, seen in calls.items()})
    eom = CachedEOM(**{k: v for k, v in values.items() if k in _FIELD_NAMES})
    # built Functions (codegen.FunctionSet takes them instead of building): the same algorithm,
    # so the same numbers bit for bit; kept in the EOM's workspace
    eom.workspace.stored_functions(eom, _functions_of(data["functions"]))
    return eom


def _functions_of(texts: dict) -> dict:
    """The stored Functions (key -> Function) from their serializations: one Function per text
    (the ode of the SX and of the default Function set is often the same text: read once), and
    the text's hash handed to mechdsl.eom.sxcode, whose keys would serialize it again."""
    import casadi as ca

    from . import sxcode

    by_text: dict = {}
    out = {}
    for k, text in texts.items():
        f = by_text.get(text)
        if f is None:
            f = by_text[text] = ca.Function.deserialize(text)
            sxcode.serialized(f, text)
        out[k] = f
    return out


from . import EOM  # noqa: E402  (after the helpers: eom imports ir, which the cache needs anyway)

_FIELD_NAMES = frozenset(f.name for f in fields(EOM))
_PENDABLE = frozenset(("M", "bias", "Q", "qdd", "g", "q0", "qd0", "lam", "u", *_CALLABLES))


class _Pending:
    """A field the cache did not hold; derived again on first use (see _Again) and kept here
    (the EOM is frozen: the field keeps this holder)."""

    def __init__(self, again: "_Again", name: str):
        self.again = again
        self.name = name
        self.value = None
        self.known = False

    def get(self):
        if not self.known:
            self.value = self.again.value(self.name)
            self.known = True
        return self.value


class _Again:
    """The model derived again once (mechdsl.mechanics), its results expressed in the cached
    EOM's symbols by substitution."""

    def __init__(self, values: dict):
        """values: the cached EOM's fields (None for those not held)."""
        self.syms = [s for s in (values.get(k) for k in ("q", "qd", "t", "p", "u", "lam")) if s is not None]
        self.model = values["model"]
        self.full = None

    def _derived(self):
        if self.full is None:
            from ..mechanics import derive

            self.full = derive(self.model)
        return self.full

    def _map(self, e):
        import casadi as ca

        full = self.full
        old = [s for s in (full.q, full.qd, full.t, full.p, full.u, full.lam) if s is not None]
        return ca.substitute(ca.SX(e), ca.vertcat(*old), ca.vertcat(*self.syms))

    def value(self, name):
        if name in _CALLABLES:          # stored only when not None: derived when first called
            return lambda *a: self._map(getattr(self._derived(), name)(*a))
        v = getattr(self._derived(), name)
        return None if v is None else self._map(v)


class CachedEOM(EOM):
    """An EOM read from the model cache; fields it did not hold are derived on first access."""

    def __getattribute__(self, name):
        if name in _PENDABLE:
            v = object.__getattribute__(self, "__dict__").get(name)
            if type(v) is _Pending:
                return v.get()
        return object.__getattribute__(self, name)
