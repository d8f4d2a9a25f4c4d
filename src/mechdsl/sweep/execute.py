"""Running a sweep's chunks (mechdsl.sweep): on the scheduler chosen, each finished chunk into
the store as it arrives, the progress bar moved; Ctrl-C stops the sweep and keeps what
finished (including the runs that finished meanwhile on other workers); the runs that never
ran become 'not run' rows."""
from __future__ import annotations


def run_chunks(job, chunks, scheduler: str, workers: int, connect_timeout: float, store, bar) -> tuple[bool, list]:
    """(interrupted, the scheduler's notes) after every chunk has run or Ctrl-C stopped them."""
    from ..interrupts import check_interrupt, interrupt_guard
    from . import schedulers as S

    engine = None
    interrupted = False
    try:
        with interrupt_guard():          # CasADi swallows Ctrl-C into a RuntimeError: noted here
            try:
                if not chunks:
                    it = iter(())
                elif scheduler == "vectorized":
                    it = S.in_process(job, chunks)
                elif scheduler == "processes":
                    from .pool import Pool

                    engine = Pool(workers)
                    it = engine.run(job, chunks)
                else:
                    engine = S.Dask(scheduler, workers, connect_timeout)
                    it = engine.run(job, chunks)
                for chunk in it:
                    store.put(chunk)
                    if bar is not None:
                        bar.update(len(chunk.status))
                    check_interrupt()
            except KeyboardInterrupt:
                interrupted = True
                for chunk in (engine.drain() if engine is not None else ()):     # the runs finished meanwhile
                    store.put(chunk)
    except BaseException:
        if engine is not None:
            engine.close(cancel=True)
        store.abandon()
        raise
    finally:
        if bar is not None:
            bar.close()
    if engine is not None:
        engine.close(cancel=interrupted)
    return interrupted, list(getattr(engine, "notes", []))


def mark_not_run(store) -> None:
    """The rows of runs that never ran (an interrupted sweep): 'not run', with the reason."""
    from .runs import _invalid

    for i, row in enumerate(store.status):
        if row is None:
            store.status[i] = dict(_invalid("the sweep was interrupted before this run"), cause="not run")
