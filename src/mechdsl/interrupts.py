"""Ctrl-C that always stops: ``interrupt_guard()`` and ``check_interrupt()``.

CasADi polls for Ctrl-C while it integrates and turns the KeyboardInterrupt into a
RuntimeError (inside a solver callback, IDAS' residual or the rootfinder of the partitioned
right-hand side, into a recoverable failure), so the interrupt is lost and a run, or a
sweep's chunk, went on to the end.  For the duration of the guard (main thread only, when
Python's default handler is in place) the SIGINT handler is wrapped: it notes the signal and
then does what the default does; every integrator call (or sweep chunk) then calls
``check_interrupt()``, which raises the KeyboardInterrupt CasADi swallowed.  The previous
handler is restored on exit; a guard inside a guard leaves the outer one in charge.
"""
from __future__ import annotations

import contextlib

_SIGINT = {"seen": False}     # set by interrupt_guard's handler; read after every integrator call


def _sigint_is_ours() -> bool:
    """In the main thread with Python's default SIGINT handler in place (else another guard, or
    the application, handles Ctrl-C and a guard here leaves it alone)."""
    import _signal
    import threading

    return threading.current_thread() is threading.main_thread() and \
        _signal.getsignal(_signal.SIGINT) is _signal.default_int_handler


@contextlib.contextmanager
def interrupt_guard():
    # _signal: the signal module's C functions without its enum conversions (a tenth of a small
    # model's warm run went to them); the same handlers are installed and restored
    import _signal as signal

    if not _sigint_is_ours():
        yield                  # another guard (or the application) handles SIGINT
        return

    def handler(signum, frame):
        _SIGINT["seen"] = True
        signal.default_int_handler(signum, frame)

    _SIGINT["seen"] = False
    signal.signal(signal.SIGINT, handler)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, signal.default_int_handler)
        _SIGINT["seen"] = False


class Held:
    seen = False


@contextlib.contextmanager
def held_interrupt():
    """For commands (the application, main thread): a Ctrl-C inside the block is held until the
    block ends (a file write of bounded length finishes instead of losing the results);
    ``.seen`` says whether one came.  Elsewhere (another thread, another handler) it holds nothing."""
    import signal

    held = Held()
    if not _sigint_is_ours():
        yield held
        return

    def handler(signum, frame):
        held.seen = True

    signal.signal(signal.SIGINT, handler)
    try:
        yield held
    finally:
        signal.signal(signal.SIGINT, signal.default_int_handler)


def check_interrupt() -> None:
    """Raise the KeyboardInterrupt of a Ctrl-C that arrived (and was swallowed) since the last check."""
    if noted():
        raise KeyboardInterrupt


def noted() -> bool:
    """True (once: the note is cleared) when a Ctrl-C arrived since the last check: a failure
    CasADi reported after it is the interrupt, not a numerical failure."""
    seen, _SIGINT["seen"] = _SIGINT["seen"], False
    return seen


def in_main_thread() -> bool:
    """Ctrl-C arrives in the main thread only: code that can stop on it runs its work there."""
    import threading

    return threading.current_thread() is threading.main_thread()


def was_interrupt(e: BaseException) -> bool:
    """Whether the exception ``e`` is a Ctrl-C in disguise: CasADi's RuntimeError for one it
    swallowed (noted by the guard), or a SystemError raised while a KeyboardInterrupt was
    pending in a conversion of CasADi's (``np.array(DM)``)."""
    return (isinstance(e, KeyboardInterrupt) or noted() or isinstance(e.__cause__, KeyboardInterrupt)
            or isinstance(e.__context__, KeyboardInterrupt))
