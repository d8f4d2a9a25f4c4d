"""When a model too large to compile up front has run long enough interpreted to pay for its compile.

The stepping loop runs a model of more than ``crk.COMPILE_OPS`` operations in the interpreter
(vm.c): its compile costs seconds of gcc (about 0.13 ms an operation at -O1, linear in the
size: docs/performance.md, item 3), which a first run of a few seconds would not earn back.
A model that keeps running interpreted pays about 1.2 ns an operation and evaluation more
than compiled code (1.6 against 0.4 ns, the 200-link chain, with the interpreter's blocks of
sxcode._grouped; 2.8 ns before them), so its compile has paid once it
has been evaluated PAYBACK_EVALS times interpreted -- whatever its size, both costs being
linear in it.  The rule is the rent-or-buy one: interpret until the interpretation has cost
what the compile costs, then compile; the total is then at most twice the best choice made
knowing the future (how many runs, how long), whatever it is.

The evaluations are counted across runs (in this process and on disk, next to the cached
translations of the Function: <cache>/sxcode/<key>.work) and within a run: the loop runs in
slices (crk.run_compiled), and between two slices an interpreted run whose count has reached
the threshold compiles and goes on compiled.  Both engines give the same bits (vm.c runs each
operation as the generated C does, in the same order) and a slice carries the whole state of
the stepping, so where the switch happens changes the run's cost, never its numbers: the
method, its steps and the results are those of the model and the options alone.

    Payback(ode, tag)      .compiled_now() -> Loop or None   (the count has reached it: compile/load)
                           .check(nfev)    -> Loop or None   (between slices, nfev of this run)
                           .record(nfev)                     (the run's interpreted evaluations)
"""
from __future__ import annotations

from ...eom import cachefiles, sxcode
from . import crk

PAYBACK_EVALS = 100_000     # interpreted evaluations after which the compile has paid (see above)
# gcc's cost that does not grow with the model (its processes' start, the link, the recorder's
# code compiled beside): about what 400 operations of the model cost it (at 0.13 ms an operation,
# ~0.05 s; the 12-link chain, 1289 operations: 0.35-0.55 s with its recorder)
FIXED_OPS = 400


def threshold(ode) -> int:
    """Interpreted evaluations of ``ode`` after which its compile has paid: PAYBACK_EVALS for a large
    model, more for a small one, whose compile costs gcc's fixed part on top of its size (compile
    ~ FIXED_OPS + ops, interpreting ~ ops an evaluation, in the same units): from the operation
    count alone."""
    ops = max(int(ode.n_instructions()) if ode.is_a("SXFunction") else 0, 1)
    return PAYBACK_EVALS + PAYBACK_EVALS * FIXED_OPS // ops


def paid(ode) -> bool:
    """Whether the interpreted evaluations of ``ode`` recorded so far have paid for its compile."""
    return recorded(ode) >= threshold(ode)


def buys(ode) -> bool:
    """Whether a model small enough to compile up front is compiled now rather than rented: it has
    paid, or this process has bought it (see _BOUGHT)."""
    return (bool(_BOUGHT) and _key(ode) in _BOUGHT) or paid(ode)

_COUNTS: dict = {}          # key -> evaluations recorded (this process; the disk holds the same)


def count_path(ode):
    """The cache file holding the interpreted evaluations of ``ode`` (a decimal number)."""
    return sxcode.entry_path(ode, "work")


_path = count_path


def recorded(ode) -> int:
    """Evaluations of ``ode`` made interpreted so far (this process and earlier ones, by the cache)."""
    try:
        path = _path(ode)
    except Exception:  # noqa: BLE001 - no cache folder: this process's count alone
        return 0
    if path in _COUNTS:
        return _COUNTS[path]
    data, _ = cachefiles.read_bytes(path)
    try:
        n = int(data.decode()) if data is not None else 0
    except ValueError:
        n = 0
    _COUNTS[path] = max(n, 0)
    return _COUNTS[path]


def add(ode, nfev: int) -> None:
    """Count ``nfev`` more interpreted evaluations of ``ode`` (written to the cache: losing a count
    only delays a compile)."""
    if nfev <= 0:
        return
    try:
        path = _path(ode)
    except Exception:  # noqa: BLE001
        return
    _COUNTS[path] = recorded(ode) + int(nfev)
    cachefiles.write_bytes(path, str(_COUNTS[path]).encode())


# A model small enough to compile up front that runs interpreted because the cache does not hold
# its code yet (``rented``: crk.build_loop) is bought (compiled) when the same run set-up runs it a
# second time in a process: a loop of runs (a script, a fit, a benchmark) is where the compile pays
# first, while a `mech simulate` process runs each set-up once (the run, its error estimate's
# companion) and rents by the count on disk alone.
_BOUGHT: set = set()        # keys of the rented models bought in this process
BOUGHT = [0]                # len(_BOUGHT) as a cheap mark: the kept set-ups (backends/ode.setup_environment)
#                             are built again, compiled, once it changes


class Payback:
    """The pay-back rule of one interpreted run of ``ode`` (see the module's text); ``rented``:
    a model small enough to be compiled up front that runs interpreted because the cache does not
    hold its code yet (RUNS_IN_PROCESS)."""

    def __init__(self, ode, tag: str, rented: bool = False, again: bool = False, extra: dict | None = None):
        self.ode, self.tag, self.rented, self.extra = ode, tag, rented, extra
        self.before = recorded(ode)
        self.limit = threshold(ode)
        if rented and again:                # its set-up runs a second time in this process: buy now
            self.limit = 0
            _BOUGHT.add(_key(ode))
            BOUGHT[0] = len(_BOUGHT)
        self.switched_at = None          # evaluations of the run when it went on compiled

    def _compiled(self):
        # (a rented model: with the Functions its set-up compiles beside it, the library the next set-up loads)
        loop, _ = crk.library(self.ode, tag=self.tag, engine="compiled", extra=self.extra)
        return loop

    def compiled_now(self):
        """The compiled loop when the evaluations recorded before the run have paid for it."""
        if self.before < self.limit:
            return None
        loop = self._compiled()
        if loop is not None:
            self.switched_at = 0
        return loop

    def check(self, nfev: int):
        """Between two slices of the run, ``nfev`` evaluations into it: the compiled loop to go on
        with, or None (not yet, or it could not be built: the run goes on interpreted)."""
        if self.switched_at is not None or self.before + nfev < self.limit:
            return None
        loop = self._compiled()
        self.switched_at = nfev if loop is not None else -1     # -1: tried, no compiled loop
        return loop

    def record(self, nfev: int) -> None:
        """The run is over after ``nfev`` evaluations: count those made interpreted."""
        done = nfev if self.switched_at is None or self.switched_at < 0 else self.switched_at
        add(self.ode, done)


def _key(ode):
    try:
        return count_path(ode)
    except Exception:  # noqa: BLE001 - no cache folder: this Function in this process
        return id(ode)
