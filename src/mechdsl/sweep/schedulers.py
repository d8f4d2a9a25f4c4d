"""Execution back ends: where the chunks of a sweep run.

    vectorized   in this process; each chunk one mapped CasADi integrator, on threads
    processes    a local pool of worker processes (spawned), one per core
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
    s = str(scheduler)
    if s in NAMES or s.startswith("tcp://") or s.startswith("tls://"):
        return s
    from ..diagnostics import did_you_mean

    hint = did_you_mean(s, list(NAMES))
    raise UsageError(f"unknown scheduler '{s}' (vectorized, processes, dask or a Dask scheduler address "
                     "tcp://host:port)" + (f"; {hint}" if hint else ""))


def in_process(job, chunks):
    for first, values in chunks:
        yield run_chunk(job, first, values)


class Pool:
    """A local process pool; ``close(cancel=True)`` drops the runs not yet started."""

    def __init__(self, workers: int):
        import multiprocessing
        from concurrent.futures import ProcessPoolExecutor

        self.ex = ProcessPoolExecutor(max_workers=workers, mp_context=multiprocessing.get_context("spawn"),
                                      initializer=_ignore_sigint)

    def run(self, job, chunks):
        from concurrent.futures import as_completed

        self._futures = [self.ex.submit(run_chunk, job, first, values) for first, values in chunks]
        self._seen: set = set()
        for f in as_completed(self._futures):
            self._seen.add(f)
            yield f.result()

    def drain(self):
        """After Ctrl-C: drop the chunks not started, let the running ones finish, and yield
        every finished chunk not yet yielded."""
        self.ex.shutdown(wait=True, cancel_futures=True)
        yield from _finished(getattr(self, "_futures", []), getattr(self, "_seen", set()),
                             lambda f: f.done() and not f.cancelled() and f.exception() is None)

    def close(self, cancel: bool = False):
        self.ex.shutdown(wait=True, cancel_futures=cancel)


def _finished(futures, seen, ok):
    for f in futures:
        if f not in seen and ok(f):
            yield f.result()


def _ignore_sigint():
    """In a worker process: Ctrl-C is the parent's to handle (it cancels the runs not yet
    started and keeps the finished ones); the worker finishes its chunk."""
    import signal

    signal.signal(signal.SIGINT, signal.SIG_IGN)


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
                self.cluster = LocalCluster(n_workers=workers, threads_per_worker=1, processes=True,
                                            dashboard_address=None)
                self.client = Client(self.cluster)
            else:
                self.client = Client(address, timeout=timeout)
        except (OSError, TimeoutError) as e:
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
        if cancel and getattr(self, "_futures", None):
            self.client.cancel(self._futures)
        if getattr(self, "client", None) is not None:
            self.client.close()
        if self.cluster is not None:
            self.cluster.close()
