"""Execution back ends: where the chunks of a sweep run.

    vectorized   in this process; each chunk one mapped CasADi integrator, on threads
    processes    worker processes (spawned), one per core (pool.py: a lost worker's runs are retried)
    dask         a new distributed.LocalCluster (one worker process per core)
    tcp://...    an existing Dask cluster (its scheduler's address)

Each yields finished ``Chunk``s in completion order; the Store places them by run index.
Workers receive the Job once per chunk; the Model in it pickles by its source text and
is rebuilt once per worker (cached by the hash of that text and its settings).
"""
from __future__ import annotations

from ..diagnostics import UsageError
from .runs import run_chunk

NAMES = ("vectorized", "processes", "dask")


def check(scheduler: str) -> str:
    """The scheduler's name, or a Dask scheduler address checked before anything connects:
    ``tcp://HOST:PORT`` or ``tls://HOST:PORT`` (IPv6 hosts in brackets), TLS only with Dask's
    TLS settings in place."""
    s = str(scheduler)
    if s in NAMES:
        return s
    if s.startswith(("tcp://", "tls://")):
        address(s)
        return s
    from ..diagnostics import did_you_mean

    hint = did_you_mean(s, list(NAMES))
    raise UsageError(f"unknown scheduler '{s}' (vectorized, processes, dask or a Dask scheduler address "
                     "tcp://host:port)" + (f"; {hint}" if hint else ""))


HANDSHAKE_MAX = 65536     # bytes: a Dask scheduler's first message (its handshake) is about 60


def address(s: str) -> tuple[str, str, int]:
    """(scheme, host, port) of a Dask scheduler address, or a UsageError that says what is wrong."""
    from urllib.parse import urlsplit

    form = "tcp://HOST:PORT (IPv6: tcp://[::1]:PORT; a Dask scheduler listens on 8786 by default)"
    try:
        u = urlsplit(s)
        host, port = u.hostname, u.port
    except ValueError as e:
        what = "its port is not a number from 1 to 65535" if "port" in str(e).lower() else str(e)
        raise UsageError(f"the scheduler address {s!r} is not an address ({what}); expected {form}") from None
    if not host:
        raise UsageError(f"the scheduler address {s!r} has no host; expected {form}")
    if port is None or port == 0:
        raise UsageError(f"the scheduler address {s!r} has no port; expected {form}")
    if u.path not in ("", "/") or u.query or u.fragment or u.username or u.password:
        raise UsageError(f"the scheduler address {s!r} has more than a host and a port; expected {form}")
    if u.scheme == "tls" and not _tls_configured():
        raise UsageError(f"{s}: a TLS scheduler needs Dask's TLS settings (distributed.comm.tls.ca-file, "
                         "distributed.comm.tls.client.cert and .key in the Dask configuration); none are set")
    return u.scheme, host, port


def _tls_configured() -> bool:
    try:
        import dask

        tls = dask.config.get("distributed.comm.tls", default={}) or {}
    except ImportError:
        return False
    client = tls.get("client") or {}
    return bool(tls.get("ca-file") and client.get("cert"))


def probe(addr: str, timeout: float) -> None:
    """Check, before Dask connects, that a Dask scheduler answers at ``addr`` (tcp).

    A Dask scheduler sends its handshake first: an 8-byte length, then frames whose first is a
    small msgpack map ({"compression", "python", "pickle-protocol"}).  A port speaking another
    protocol made Dask read its first bytes as a length and allocate exabytes; here at most
    HANDSHAKE_MAX bytes are read, with ``timeout`` seconds for the connection and the answer."""
    import socket
    import struct

    _, host, port = address(addr)
    what = f"{addr} is not a Dask scheduler"
    try:
        with socket.create_connection((host, port), timeout=timeout) as c:
            c.settimeout(timeout)
            n = struct.unpack("=Q", _recv(c, 8))[0]
            if not 16 <= n <= HANDSHAKE_MAX:
                raise UsageError(f"{what}: it answered with bytes of another protocol "
                                 f"({_show(struct.pack('=Q', n))})")
            body = _recv(c, n)
    except socket.timeout:
        raise UsageError(f"{what}: it accepted the connection but said nothing within {timeout:g} s "
                         "(a Dask scheduler greets first)") from None
    except OSError as e:
        raise UsageError(f"cannot reach the Dask scheduler at {addr}: {e.strerror or e} (start one with "
                         "`dask scheduler` and `dask worker ADDRESS`, or use --scheduler dask for a local "
                         "cluster)") from None
    k = struct.unpack_from("=Q", body)[0]
    if not 1 <= k <= 64 or 8 + 8 * k > n:
        raise UsageError(f"{what}: its first message is not a Dask handshake")
    sizes = struct.unpack_from(f"={k}Q", body, 8)
    first = body[8 + 8 * k: 8 + 8 * k + sizes[0]]
    try:
        import msgpack

        hello = msgpack.loads(first, raw=False)
    except Exception:  # noqa: BLE001 - anything that is not msgpack: not a scheduler
        hello = None
    if not (isinstance(hello, dict) and "python" in hello and "pickle-protocol" in hello):
        raise UsageError(f"{what}: its first message is not a Dask handshake")


def _recv(c, n: int) -> bytes:
    out = bytearray()
    while len(out) < n:
        part = c.recv(n - len(out))
        if not part:
            raise ConnectionError(0, "the connection was closed before a Dask handshake")
        out += part
    return bytes(out)


def _show(b: bytes) -> str:
    text = b.decode("ascii", "replace")
    return repr(text) if text.isprintable() else b.hex()


def _ignore_sigint():
    """In a worker process of our own LocalCluster: Ctrl-C is the parent's to handle (it cancels
    what has not finished and keeps the rest)."""
    import signal
    import threading

    if threading.current_thread() is threading.main_thread():
        signal.signal(signal.SIGINT, signal.SIG_IGN)


def _sigint_blocked():
    """A context in which this thread (and the processes and threads it starts) has SIGINT blocked."""
    import contextlib
    import signal

    @contextlib.contextmanager
    def blocked():
        old = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
        try:
            yield
        finally:
            signal.pthread_sigmask(signal.SIG_SETMASK, old)

    return blocked()


def in_process(job, chunks):
    for first, values in chunks:
        yield run_chunk(job, first, values)


class Dask:
    """A Dask client: a new LocalCluster ("dask") or an existing scheduler (its address)."""

    def __init__(self, address: str, workers: int, timeout: float = 10.0):
        try:
            from distributed import Client, LocalCluster
        except ImportError:
            raise UsageError("scheduler 'dask' needs dask.distributed: pip install 'mechdsl[dask]'") from None
        self.cluster = None
        try:
            if address == "dask":
                # the worker processes must not get the terminal's Ctrl-C (sent to the whole process
                # group: they died with tracebacks); they inherit SIGINT blocked, the parent stops them
                with _sigint_blocked():
                    self.cluster = LocalCluster(n_workers=workers, threads_per_worker=1, processes=True,
                                                dashboard_address=None)
                self.client = Client(self.cluster)
                self.client.run(_ignore_sigint)      # (Dask unblocks it in its workers)
            else:
                if address.startswith("tcp://"):
                    probe(address, timeout)
                self.client = Client(address, timeout=timeout)
        except UsageError:
            self.close()
            raise
        except Exception as e:  # noqa: BLE001 - connecting: OSError, TimeoutError, SSLError, Dask's own
            self.close()
            raise UsageError(f"cannot reach the Dask scheduler at {address}: {str(e).strip() or type(e).__name__} "
                             "(start one with `dask scheduler` and `dask worker ADDRESS`, or use --scheduler dask "
                             "for a local cluster)") from None

    def run(self, job, chunks):
        from distributed import as_completed

        remote = self.client.scatter(job, broadcast=True)
        self._futures = [self.client.submit(run_chunk, remote, first, values, pure=False)
                         for first, values in chunks]
        self._seen: set = set()
        for f in as_completed(self._futures):
            self._seen.add(f.key)
            yield f.result()

    def drain(self):
        """After Ctrl-C: cancel what has not finished; yield the finished chunks not yet yielded."""
        futures = getattr(self, "_futures", [])
        pending = [f for f in futures if f.status != "finished"]
        if pending:
            self.client.cancel(pending)
        seen = getattr(self, "_seen", set())
        for f in futures:
            if f.key not in seen and f.status == "finished":
                yield f.result()

    def close(self, cancel: bool = False):
        """Disconnect (and stop our own LocalCluster).  After Ctrl-C (``cancel``) without waiting
        for an orderly shutdown: the worker processes of our cluster are killed."""
        if cancel and getattr(self, "_futures", None):
            self.client.cancel(self._futures)
        if cancel and self.cluster is not None:
            _kill_workers(self.cluster)
        if getattr(self, "client", None) is not None:
            self.client.close(timeout=2 if cancel else 10)
        if self.cluster is not None:
            try:
                self.cluster.close(timeout=2 if cancel else None)
            except Exception:  # noqa: BLE001 - a slow shutdown after Ctrl-C: the processes are gone
                if not cancel:
                    raise


def _kill_workers(cluster) -> None:
    """SIGKILL the worker processes of our LocalCluster (their nannies then close at once)."""
    import os
    import signal

    for nanny in list(getattr(cluster, "workers", {}).values()):
        pid = getattr(getattr(nanny, "process", None), "pid", None)
        if pid:
            try:
                os.kill(pid, signal.SIGKILL)
            except OSError:
                pass
