"""The first-integrals search of a run, cached on disk: ``integral_function(eom, pv)``.

The search (0.05-0.2 s) gives the first integrals as one CasADi Function (t, x, p) or none.
It is kept under ``<cache_dir()>/integrals/<digest>.json`` by the SHA-256 of the serialized
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

import hashlib
import json

import numpy as np

VERSION = "3"          # 2: rotation symmetries (angular momenta, issue 17); 3: JSON with the full key
FORMAT = f"mechdsl-first-integrals {VERSION}"


def integral_function(eom, pv):
    """The first integrals of ``eom`` at parameter values ``pv`` as one Function, or None."""
    import casadi as ca

    from ..eom import cachefiles
    from ..eom.codegen import cache_dir

    path = key = None
    try:
        key = _key(eom, pv)
        path = cache_dir() / "integrals" / f"{key[:32]}.json"
    except Exception as e:  # noqa: BLE001 - no key (a model the serializer does not take): search
        cachefiles.miss("first-integrals", "this model", f"no key ({type(e).__name__})")
    if path is not None:
        data, why = cachefiles.read_bytes(path)
        f, why = (_entry(data, key, eom) if data is not None else (None, why))
        if why is None:
            cachefiles.hit("first-integrals", key[:16])
            return f
        cachefiles.miss("first-integrals", key[:16], why)
    try:
        from .integrals import integral_signals

        sig = integral_signals(eom, pv)
    except Exception:  # noqa: BLE001 - a failed search only means nothing extra is recorded
        sig = {}
    f = None
    if sig:
        x = ca.vertcat(eom.q, eom.qd)
        f = ca.Function("first_integrals", [eom.t, x, eom.p], list(sig.values()), ["t", "x", "p"], list(sig))
    if path is not None:
        entry = {"format": FORMAT, "key": key, "function": None if f is None else f.serialize()}
        cachefiles.write_bytes(path, json.dumps(entry).encode("utf-8"))
    return f


def _key(eom, pv) -> str:
    import casadi as ca

    from .. import __version__

    x = ca.vertcat(eom.q, eom.qd)
    parts = [ca.SX(eom.T), ca.SX(eom.V), ca.SX(eom.D), ca.SX(eom.Q),
             ca.SX(eom.g) if eom.g is not None else ca.SX(0, 1)]
    key_f = ca.Function("key", [eom.t, x, eom.p], parts)
    h = hashlib.sha256()
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
