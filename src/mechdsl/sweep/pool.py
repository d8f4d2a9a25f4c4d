"""The ``processes`` scheduler: spawned worker processes that run chunks, and survive losing one.

Each worker gets the Job once (when it starts) and then chunks over its own pipe, so the
parent always knows which chunk a worker held when it died:

- a worker that dies (killed, out of memory, a crash in native code) loses only its chunk;
  the chunk is split in halves and run again on fresh workers, until the run that kills its
  worker is alone; a run alone that killed its worker ``MAX_DEATHS`` times is a failed row
  (cause "worker died", the signal or exit code in its detail);
- if workers keep dying without any chunk finishing (a broken installation), the sweep stops
  and the runs not done are failed rows saying why;
- Ctrl-C: the parent stops every worker at once (SIGTERM, then SIGKILL) and keeps the chunks
  that finished; workers ignore SIGINT, which the terminal sends to them too, so it is the
  parent's to handle.  (SIGINT is blocked while a worker starts, so none prints a traceback
  from its start-up.)
"""
from __future__ import annotations

import collections
import signal
import time

from .runs import Chunk, _invalid

MAX_DEATHS = 3          # a run alone whose worker died this often: a failed row
STORM = 8               # worker deaths in a row beyond those a search for one killing run takes: give up


def _worker(conn, job):
    """A worker process: chunks in, Chunks (or an error text) out, until None."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT})
    from . import runs

    while True:
        try:
            task = conn.recv()
        except EOFError:
            return
        if task is None:
            return
        first, values = task
        try:
            conn.send(("ok", runs.run_chunk(job, first, values)))
        except Exception as e:  # noqa: BLE001 - a bug: reported as failed rows, the sweep goes on
            conn.send(("error", f"{type(e).__name__}: {e}"))


class Pool:
    def __init__(self, workers: int):
        import multiprocessing

        self.ctx = multiprocessing.get_context("spawn")
        self.n = workers
        self.busy: dict = {}            # worker -> (first, values, deaths)
        self.idle: list = []
        self.notes: list[str] = []      # what happened to workers (the sweep's warnings)
        self._done: list = []           # chunks received while stopping

    def _start(self, job):
        from .schedulers import _sigint_blocked

        a, b = self.ctx.Pipe()
        p = self.ctx.Process(target=_worker, args=(b, job), daemon=True)
        with _sigint_blocked():
            p.start()
        b.close()
        return _Worker(p, a)

    def run(self, job, chunks):
        """Yield finished Chunks in completion order (failed rows for runs that keep killing
        their worker)."""
        from multiprocessing.connection import wait

        todo = collections.deque((first, values, 0) for first, values in chunks)
        biggest = max((len(next(iter(v.values()))) for _, v, _ in todo), default=1)
        deaths_in_a_row = 0
        while todo or self.busy:
            while todo and (self.idle or len(self.busy) + len(self.idle) < self.n):
                w = self.idle.pop() if self.idle else self._start(job)
                task = todo.popleft()
                try:
                    w.conn.send(task[:2])
                except OSError:          # died while idle: its task goes back
                    todo.appendleft(task)
                    w.close()
                    continue
                self.busy[w] = task
            ready = wait([w.conn for w in self.busy] + [w.proc.sentinel for w in self.busy], timeout=1.0)
            for w in list(self.busy):
                if w.conn in ready or w.proc.sentinel in ready:
                    msg = w.receive()
                    task = self.busy.pop(w)
                    if msg is not None:
                        deaths_in_a_row = 0
                        self.idle.append(w)
                        yield msg if isinstance(msg, Chunk) else _failed(job, task, "internal error", msg)
                        continue
                    if w.proc.is_alive():               # the pipe broke, the process lingers
                        w.kill()
                    why = w.death()
                    deaths_in_a_row += 1
                    k = len(next(iter(task[1].values())))
                    if k > 1:                           # find the run that kills: halves
                        h = k // 2
                        todo.appendleft((task[0] + h, {n: v[h:] for n, v in task[1].items()}, 0))
                        todo.appendleft((task[0], {n: v[:h] for n, v in task[1].items()}, 0))
                        self.notes.append(f"runs {task[0]}-{task[0] + k - 1}: their worker process {why}; "
                                          "run again on fresh workers")
                    elif task[2] + 1 >= MAX_DEATHS:
                        yield _failed(job, task, "worker died", f"the worker process running this run {why}, "
                                      f"{task[2] + 1} times")
                    else:
                        todo.appendleft((task[0], task[1], task[2] + 1))
                        self.notes.append(f"run {task[0]}: its worker process {why}; run again on a fresh worker")
                    # a single killing run costs log2(chunk) + MAX_DEATHS deaths in a row at most
                    if deaths_in_a_row >= STORM + MAX_DEATHS + biggest.bit_length() + self.n and todo:
                        text = (f"worker processes keep dying ({deaths_in_a_row} in a row, the last {why}); "
                                "the sweep stopped")
                        for t in list(todo) + list(self.busy.values()):
                            yield _failed(job, t, "worker died", text)
                        todo.clear()
                        self.busy.clear()
                        self.notes.append(text)

    def drain(self):
        """After Ctrl-C: stop every worker now; yield the chunks they had already sent."""
        for w in list(self.busy):
            if w.conn.poll(0):
                msg = w.receive()
                if isinstance(msg, Chunk):
                    yield msg
        self.close(cancel=True)

    def close(self, cancel: bool = False):
        workers = list(self.busy) + self.idle
        self.busy, self.idle = {}, []
        for w in workers:
            if cancel:
                w.proc.terminate()
            else:
                try:
                    w.conn.send(None)
                except OSError:
                    pass
        deadline = time.monotonic() + (1.0 if cancel else 10.0)
        for w in workers:
            w.proc.join(max(0.0, deadline - time.monotonic()))
            if w.proc.is_alive():
                w.kill()
            w.conn.close()


class _Worker:
    def __init__(self, proc, conn):
        self.proc, self.conn = proc, conn

    def receive(self):
        """The worker's answer: a Chunk, an error text, or None when it died first."""
        try:
            if not self.conn.poll(0):
                return None
            kind, payload = self.conn.recv()
        except (EOFError, OSError):
            return None
        return payload

    def kill(self):
        self.proc.kill()
        self.proc.join(5)

    def death(self) -> str:
        self.proc.join(5)
        code = self.proc.exitcode
        self.conn.close()
        if code is None:
            return "stopped answering"
        if code < 0:
            try:
                name = signal.Signals(-code).name
            except ValueError:
                name = f"signal {-code}"
            return f"was killed by {name}"
        return f"exited with code {code}"

    def close(self):
        self.kill()
        self.conn.close()


def _failed(job, task, cause: str, detail: str) -> Chunk:
    """Rows marked failed for the runs of ``task`` (no values)."""
    import numpy as np

    first, values, _ = task
    k = len(next(iter(values.values())))
    nt = len(job.grid)
    return Chunk(first, np.full((k, nt, len(job.states)), np.nan), np.full((k, nt, len(job.variables)), np.nan),
                 [dict(_invalid(detail), cause=cause) for _ in range(k)])
