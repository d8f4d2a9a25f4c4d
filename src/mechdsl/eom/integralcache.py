"""The first-integrals search of a run, cached on disk: ``lookup(eom, pv)``, ``store(eom, pv, f)``.

The search (0.05-0.2 s, simulation/monitors.py) gives the first integrals as one CasADi
Function (t, x, p) or none; it is kept under ``<cache_dir()>/integrals/<digest>.json`` by the SHA-256 of the serialized
T, V, D, Q, g, the coordinates and the parameter values, so a repeated ``mech simulate`` of
the same model skips it.  The entry is JSON: {"format", "key" (the full key), "function"
(CasADi's text serialization, or null: no integrals)}.  A reader checks the format, the key
(a swapped entry is another model's) and that the Function is an SX Function named
``first_integrals`` of the signature (1, 2n, n_p) -> scalars, so an empty, truncated,
swapped or foreign entry is searched again and rewritten, never used.  An SX Function cannot
call out to a shared library, and the file is read only from a folder and file no other user
can write (mechdsl.eom.cachefiles).
"""
from __future__ import annotations

from ..digest import sha256
import json

import numpy as np

from . import cachefiles

VERSION = "3"          # 2: rotation symmetries (angular momenta, issue 17); 3: JSON with the full key
FORMAT = f"mechdsl-first-integrals {VERSION}"


def lookup(eom, pv):
    """(True, the cached Function or None) from a good entry, else (False, None): search."""
    path, key = _where(eom, pv)
    if path is None:
        return False, None
    data, why = cachefiles.read_bytes(path)
    f, why = (_entry(data, key, eom) if data is not None else (None, why))
    if why is None:
        cachefiles.hit("first-integrals", key[:16])
        return True, f
    cachefiles.miss("first-integrals", key[:16], why)
    return False, None


def store(eom, pv, f) -> None:
    """Keep the search's result (a Function, or None: no integrals) for the next run."""
    path, key = _where(eom, pv)
    if path is not None:
        entry = {"format": FORMAT, "key": key, "function": None if f is None else f.serialize()}
        cachefiles.write_bytes(path, json.dumps(entry).encode("utf-8"))


def _where(eom, pv):
    try:
        key = _key(eom, pv)
    except Exception as e:  # noqa: BLE001 - no key (a model the serializer does not take): search
        cachefiles.miss("first-integrals", "this model", f"no key ({type(e).__name__})")
        return None, None
    return cachefiles.cache_dir() / "integrals" / f"{key[:32]}.json", key


def _key(eom, pv) -> str:
    import casadi as ca

    from .. import __version__

    x = ca.vertcat(eom.q, eom.qd)
    parts = [ca.SX(eom.T), ca.SX(eom.V), ca.SX(eom.D), ca.SX(eom.Q),
             ca.SX(eom.g) if eom.g is not None else ca.SX(0, 1)]
    key_f = ca.Function("key", [eom.t, x, eom.p], parts)
    h = sha256()
    for piece in (FORMAT, __version__, ca.__version__, ",".join(eom.coords), key_f.serialize(),
                  np.asarray(pv, float).tobytes().hex()):
        h.update(str(piece).encode())
        h.update(b"\0")
    return h.hexdigest()


def _entry(data: bytes, key: str, eom):
    """(Function or None, None) from a good entry, else (None, why it is not used)."""
    import casadi as ca

    try:
        entry = json.loads(data.decode("utf-8"))
    except (UnicodeDecodeError, ValueError):
        return None, "not a JSON entry (empty, truncated or foreign)"
    if not isinstance(entry, dict) or entry.get("format") != FORMAT:
        return None, "an entry of another format or version"
    if entry.get("key") != key:
        return None, "the entry holds another key (swapped or copied)"
    text = entry.get("function")
    if text is None:
        return None, None
    if not isinstance(text, str):
        return None, "the entry's function is not text"
    try:
        f = ca.Function.deserialize(text)
    except Exception as e:  # noqa: BLE001 - CasADi's own message: a stream it cannot read
        return None, f"the function does not load ({type(e).__name__})"
    n, n_p = 2 * int(eom.q.numel()), int(eom.p.numel())
    ok = (f.is_a("SXFunction") and f.name() == "first_integrals" and f.n_in() == 3
          and [f.size_in(i) for i in range(3)] == [(1, 1), (n, 1), (n_p, 1)]
          and all(f.size_out(i) == (1, 1) for i in range(f.n_out())))
    return (f, None) if ok else (None, "the function has another signature (another model's)")
