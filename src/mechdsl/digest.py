"""``sha256``: hashlib's SHA-256, without loading OpenSSL for small inputs.

``import hashlib`` loads OpenSSL's libcrypto: about 3.3 ms of a warm ``mech simulate``, which
hashes mostly small things (cache keys, the compiled libraries' records, the generated C).
CPython's own implementation (module ``_sha2`` from 3.12, ``_sha256`` before; what ``random``
uses for the same reason) gives the same digests but hashes 5-6x slower (3.8 ms a MB against
0.66 ms on the development machine), so an input of ``LARGE`` bytes or more (a big model's
cache entry), or any input once something else has imported hashlib, goes to OpenSSL.
"""
import sys

try:
    from _sha2 import sha256 as _builtin     # Python >= 3.12
except ImportError:                          # pragma: no cover - depends on the Python version
    try:
        from _sha256 import sha256 as _builtin   # Python 3.11
    except ImportError:
        _builtin = None

LARGE = 1 << 20     # bytes: from about here OpenSSL's speed pays for its import


def sha256(data: bytes = b""):
    """A SHA-256 hash object of ``data`` (``update``, ``digest``, ``hexdigest``, ``copy``)."""
    if _builtin is None or len(data) >= LARGE or "hashlib" in sys.modules:
        import hashlib

        return hashlib.sha256(data)
    return _builtin(data)


__all__ = ["sha256", "LARGE"]
