"""``sha256``: hashlib's SHA-256 without loading OpenSSL.

``import hashlib`` loads OpenSSL's libcrypto (about 3 ms of a warm ``mech simulate``, which
needs SHA-256 only for its cache keys and checks).  CPython's own implementation (the module
``_sha2`` from 3.12, ``_sha256`` before; what ``random`` uses for the same reason) gives the
same digests; hashlib's is the fallback where neither is built in.
"""
try:
    from _sha2 import sha256           # Python >= 3.12
except ImportError:                    # pragma: no cover - depends on the Python version
    try:
        from _sha256 import sha256     # Python 3.11
    except ImportError:
        from hashlib import sha256

__all__ = ["sha256"]
