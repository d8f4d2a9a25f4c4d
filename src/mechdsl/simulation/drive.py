"""Driving a model's inputs during a run: ``build_drive(eom, spec, t0, t1, x0) -> Drive``.

Each declared ``input`` gets one signal (``inputs={"F": u}`` / ``--input F=...``):

    a number                 constant
    a table                  samples (t_k, u_k): an (N, 2) array, a pair (times, values), or
                             ``table(times, values, hold="zoh" | "linear")``; must cover the span
    a callable               ``u(t)`` or ``u(t, x)`` (state feedback), returning a number
    a casadi.Function        of (t) or (t, x), returning a scalar

and inputs nothing drives keep their declared default.  When every signal is constant the
back ends receive u as a constant vector (the integrators' parameter is [u; p]); otherwise
the ODE back end integrates the closed loop ``ode(t, x, U(t, x), p)``, an MX Function built
once here (Python callables enter through a ``casadi.Callback`` with finite-difference
derivatives), so every integrator plug-in runs it unchanged, and the back ends that read the
equations themselves (DAE, contacts, fixed step) get ``close_eom``: the equations with u
replaced by the SX expression U(t, x) (Python signals as call nodes).  The values are
recorded as signals named after the inputs.

Bounds: a constant or a table outside the declared ``min``/``max`` is an error (known
before the run); a callable's values are only known during the run, so leaving the bounds
there is a warning in the Result's metadata.
"""
from __future__ import annotations

import inspect
from dataclasses import field

import numpy as np

from ..diagnostics import UsageError, did_you_mean
from ..eom.codegen import TXUP, jacobian_of
from ..model.records import record


HOLDS = ("zoh", "linear")


@record
class Table:
    """Samples of one input: ``hold`` = "zoh" (zero-order hold, the default) or "linear"."""
    times: np.ndarray
    values: np.ndarray
    hold: str = "zoh"


def table(times, values, hold: str = "zoh") -> Table:
    """A table of samples for ``inputs={...}`` (times strictly increasing)."""
    t = np.asarray(times, float).ravel()
    v = np.asarray(values, float).ravel()
    if hold not in HOLDS:
        raise UsageError(f"hold must be one of {', '.join(HOLDS)} (got {hold!r})")
    if t.size != v.size or t.size < 1:
        raise UsageError(f"a table needs as many times as values, at least one (got {t.size} and {v.size})")
    if not (np.isfinite(t).all() and np.isfinite(v).all()):
        raise UsageError("a table's times and values must be finite numbers")
    if t.size > 1 and not (np.diff(t) > 0).all():
        raise UsageError("a table's times must be strictly increasing")
    return Table(t, v, hold)


def read_table(path, hold: str = "zoh", what: str = "input table") -> Table:
    """A table from a CSV file of (time, value) rows; a first line that is not numbers is a header."""
    import csv

    try:
        with open(path, newline="", encoding="utf-8") as fh:
            rows = [r for r in csv.reader(fh) if r and any(c.strip() for c in r)]
    except (OSError, UnicodeDecodeError) as e:
        raise UsageError(f"{what}: cannot read {path}: {getattr(e, 'strerror', None) or e}") from None
    data = []
    for i, r in enumerate(rows):
        try:
            vals = [float(c) for c in r]
        except ValueError:
            if i == 0:
                continue                     # a header
            raise UsageError(f"{what}: {path} line {i + 1} is not two numbers: {','.join(r)[:80]}") from None
        if len(vals) != 2:
            raise UsageError(f"{what}: {path} line {i + 1} has {len(vals)} columns; expected 2 (time, value)")
        data.append(vals)
    if not data:
        raise UsageError(f"{what}: {path} has no (time, value) rows")
    arr = np.array(data, float)
    try:
        return table(arr[:, 0], arr[:, 1], hold)
    except UsageError as e:
        raise UsageError(f"{what}: {path}: {e}") from None


HOLD_TIME = "<hold time>"     # the trailing parameter of close_eom(eom, hold_time=True)


@record(frozen=False)
class Signal:
    name: str
    kind: str                 # default | constant | table | callable | function
    value: float | None = None
    table: Table | None = None
    fn: object = None
    feedback: bool = False    # depends on the state


@record(frozen=False)
class Drive:
    names: tuple[str, ...]
    signals: list[Signal] = field(default_factory=list)
    bounds: tuple = ()        # (min, max) per input, None where not declared
    span: tuple = (-np.inf, np.inf)     # the run's times: signals are never called outside

    @property
    def constant(self) -> bool:
        return all(s.kind in ("default", "constant") for s in self.signals)

    def vector(self, t: float | None = None) -> np.ndarray:
        """u of a constant drive; with ``t``, also the value at t of every zero-order-hold table
        (held until its next sample); 0 for the other signals (closed into ``ode``)."""
        return np.array([_held(s, t) if _zoh(s) and t is not None else s.value if s.value is not None else 0.0
                         for s in self.signals], float)

    def breakpoints(self, t0: float, t1: float) -> np.ndarray:
        """The tables' sample times strictly inside (t0, t1): where a zero-order hold jumps and a
        linear table has a kink.  The ODE back end restarts its integrator there (an integrator
        stepping across a jump loses accuracy, and at tight tolerances fails)."""
        tol = 1e-12 * max(1.0, abs(t0), abs(t1))
        ts = [s.table.times for s in self.signals if s.kind == "table"]
        if not ts:
            return np.zeros(0)
        allt = np.unique(np.concatenate(ts))
        return allt[(allt > t0 + tol) & (allt < t1 - tol)]

    def describe(self) -> dict:
        out = {}
        for s in self.signals:
            if s.kind in ("default", "constant"):
                out[s.name] = f"{s.kind} {s.value!r}"
            elif s.kind == "table":
                out[s.name] = f"table of {s.table.times.size} samples ({s.table.hold})"
            else:
                out[s.name] = s.kind + (" u(t, x)" if s.feedback else " u(t)")
        return out

    def closed(self, funcs):
        """{"ode", "ode_jacobian"} of the closed loop ode(t, x, U(t, x), p), signature (t, x, u, p),
        where u carries only the zero-order-hold tables' current values (``vector(t)``: the back
        end integrates piece by piece between ``breakpoints``, so a step never sees a jump), or
        ``funcs`` itself when every signal is a constant or a zero-order hold."""
        if all(s.kind in ("default", "constant") or _zoh(s) for s in self.signals):
            return funcs             # zero-order holds come in through u, piece by piece (vector(t))

        def build():
            import casadi as ca

            ode = funcs["ode"]
            t = ca.MX.sym("t")
            x = ca.MX.sym("x", ode.size1_in(1))
            u = ca.MX.sym("u", ode.size1_in(2))
            p = ca.MX.sym("p", ode.size1_in(3))
            U = self.expression(t, x, held=u)
            closed = ca.Function("ode", [t, x, u, p], [ode(t, x, U, p)], TXUP, ["xdot"])
            return {"ode": closed, "ode_jacobian": jacobian_of(closed)}
        return _Closed(build, funcs, self)

    @property
    def tables_only(self) -> bool:
        """Every signal a constant or a table: the stepping loop reads the tables as data."""
        return all(s.kind in ("default", "constant", "table") for s in self.signals)

    def vector_at(self, t: float) -> np.ndarray:
        """u at t of a drive of constants and tables (linear tables interpolated)."""
        return np.array([_table_value(s, t) if s.kind == "table" else s.value if s.value is not None else 0.0
                         for s in self.signals], float)

    def expression(self, t, x, held=None, hold_time=None):
        """U(t, x) as a column of the type of ``t`` (MX or SX: in SX, Python signals and MX
        Functions enter as call nodes), one entry per input; ``held``: a column whose entries
        stand for the zero-order-hold tables (instead of their expression in t); ``hold_time``:
        the time at which the zero-order-hold tables are read (default ``t``)."""
        import casadi as ca

        sym = ca.SX if isinstance(t, ca.SX) else ca.MX
        if not self.signals:
            return sym(0, 1)
        th = t if hold_time is None else hold_time
        return ca.vertcat(*[held[j] if held is not None and _zoh(s) else
                            _expr(s, th if _zoh(s) else t, x, sym, self.span)
                            for j, s in enumerate(self.signals)])

    @property
    def holds(self) -> bool:
        """Whether a zero-order-hold table drives an input."""
        return bool(self.held_names)

    @property
    def held_names(self) -> list[str]:
        """The inputs driven by a zero-order-hold table."""
        return [s.name for s in self.signals if _zoh(s)]

    def close_eom(self, eom, hold_time: bool = False):
        """The equations with every input replaced by its signal U(t, x) (SX): for the back ends
        that read the equations themselves (DAE, contacts, fixed step), which then see the
        inputs as functions of time and state, as the ODE back end's closed loop does.

        ``hold_time``: the zero-order-hold tables read at a time of their own, a trailing
        parameter named ``HOLD_TIME`` (p' = [p; t_hold]), which the fixed-step back end sets to
        each step's midpoint, so that every stage of a step sees the value held over the step."""
        import casadi as ca

        u = eom.u
        th = ca.SX.sym("t_hold") if hold_time else None
        U = self.expression(eom.t, ca.vertcat(eom.q, eom.qd), hold_time=th)

        def sub(e):
            if e is None or isinstance(e, (int, float, np.ndarray)):
                return e
            v = ca.SX(e)
            return ca.substitute(v, u, U) if ca.depends_on(v, u) else e

        def subs(d):
            return {k: (tuple(sub(a) for a in v) if isinstance(v, tuple) else sub(v)) for k, v in (d or {}).items()}

        changes = {k: sub(getattr(eom, k)) for k in ("T", "V", "D", "Q", "M", "bias", "qdd", "g")}
        if th is not None:
            changes.update(p=ca.vertcat(eom.p, th), params=tuple(eom.params) + (HOLD_TIME,),
                           param_values=np.r_[np.asarray(eom.param_values, float).ravel(), 0.0])
        return eom.replace(**changes, outputs=subs(eom.outputs), reactions=subs(eom.reactions),
                           invariants=subs(eom.invariants), u=None, inputs=(), input_defaults=())

    def values(self, t: np.ndarray, X: np.ndarray) -> np.ndarray:
        """The inputs on the sample times: rows = times, columns = inputs."""
        N = len(t)
        if self.constant or N == 0:
            return np.tile(self.vector(), (N, 1))
        if self.tables_only:          # numpy lookups: a table is data (a CasADi pw_lin of 10^6 samples is not)
            t = np.asarray(t, float)
            return np.column_stack([_table_values(s, t) if s.kind == "table" else np.full(N, s.value)
                                    for s in self.signals])
        import casadi as ca

        tt = ca.MX.sym("t")
        xx = ca.MX.sym("x", X.shape[1])
        # a zero-order hold read as _held does: a time a round-off short of a sample (a fixed
        # step's t0 + k h) already shows the sample's value
        f = ca.Function("U", [tt, xx], [self.expression(tt, xx, hold_time=tt + 1e-12 * ca.fmax(1, ca.fabs(tt)))])
        return np.array(f.map(N)(t.reshape(1, -1), X.T), float).reshape(len(self.signals), N).T

    def signal_errors(self) -> list[str]:
        """What went wrong in Python signals during the run (each gave NaN from then on)."""
        return [s.fn.error for s in self.signals if s.kind == "callable" and getattr(s.fn, "error", None)]

    def check_bounds(self, U: np.ndarray) -> list[str]:
        """Warnings for recorded values outside the declared bounds (signals known only during a run)."""
        out = []
        for j, (s, (lo, hi)) in enumerate(zip(self.signals, self.bounds)):
            col = U[:, j]
            if lo is not None and col.size and col.min() < lo - 1e-12 * max(1.0, abs(lo)):
                out.append(f"input '{s.name}' went below its minimum {lo:g} (least value {col.min():.6g})")
            if hi is not None and col.size and col.max() > hi + 1e-12 * max(1.0, abs(hi)):
                out.append(f"input '{s.name}' went above its maximum {hi:g} (largest value {col.max():.6g})")
        return out


class _Closed(dict):
    """The closed-loop Functions (built on first use: a run of the stepping loop reads the tables
    itself and never builds them), with the other Functions of the model passed through."""

    def __init__(self, build, base, drive):
        super().__init__()
        self._build, self.base, self.drive = build, base, drive
        self.tables_only = drive.tables_only
        self.compiled = getattr(base, "compiled", False)
        self.notes = list(getattr(base, "notes", []))

    def __missing__(self, key):
        if key in ("ode", "ode_jacobian"):
            if self._build is not None:
                self.update(self._build())
                self._build = None
            return dict.__getitem__(self, key)
        return self.base[key]


def _zoh(s: Signal) -> bool:
    return s.kind == "table" and s.table.hold == "zoh"


def _held(s: Signal, t: float) -> float:
    """A zero-order-hold table's value on [t, next sample): value k on [t_k, t_k+1)."""
    tb = s.table
    k = int(np.searchsorted(tb.times, t + 1e-12 * max(1.0, abs(t)), side="right")) - 1
    return float(tb.values[min(max(k, 0), tb.values.size - 1)])


def _table_value(s: Signal, t: float) -> float:
    return float(_table_values(s, np.array([t], float))[0])


def _table_values(s: Signal, t: np.ndarray) -> np.ndarray:
    """A table's values at the times t: the zero-order hold as ``_held``, a linear table
    interpolated (ends held)."""
    tb = s.table
    if tb.hold == "linear" or tb.times.size == 1:
        return np.interp(t, tb.times, tb.values)
    k = np.searchsorted(tb.times, t + 1e-12 * np.maximum(1.0, np.abs(t)), side="right") - 1
    return tb.values[np.clip(k, 0, tb.values.size - 1)]


def _expr(s: Signal, t, x, sym, span):
    import casadi as ca

    if s.kind in ("default", "constant"):
        return sym(s.value)
    if s.kind == "table":
        tb = s.table
        ts = ca.SX.sym("t")
        if tb.times.size == 1:
            expr = ca.SX(tb.values[0])
        elif tb.hold == "linear":
            expr = ca.pw_lin(ts, ca.DM(tb.times), ca.DM(tb.values))
        else:  # zero-order hold: value k on [t_k, t_k+1)
            expr = ca.pw_const(ts, ca.DM(tb.times[1:]), ca.DM(tb.values))
        return ca.Function(_fname("table", s.name), [ts], [expr])(t)
    f = s.fn
    # the user's function only at the run's times: integrators may look past the end, and the
    # fixed-step back end's structure probes (mechdsl.analysis.core) use times of their own
    tc = ca.fmin(ca.fmax(t, span[0]), span[1]) if np.isfinite(span).all() else t
    return f(tc, x) if s.feedback else f(tc)


def _fname(prefix: str, name: str) -> str:
    """A valid CasADi Function name for an input ("tau[2]" -> "input_tau_2")."""
    import re

    return re.sub(r"_+", "_", f"{prefix}_" + re.sub(r"[^A-Za-z0-9]", "_", name)).rstrip("_")


def build_drive(eom, spec, t0: float, t1: float, x0=None) -> Drive:
    """The Drive of one run (``spec``: {input name: signal}); raises UsageError for bad input."""
    names = tuple(eom.inputs)
    model = getattr(eom, "model", None)
    declared = {p.name: p for p in (model.inputs if model is not None else ())}
    bounds = tuple((getattr(declared.get(n), "min", None), getattr(declared.get(n), "max", None)) for n in names)
    spec = dict(spec or {})
    for k in spec:
        if k not in names:
            hint = did_you_mean(k, list(names))
            what = f"its inputs are {', '.join(names)}" if names else "it declares no inputs"
            raise UsageError(f"'{k}' is not an input of {eom.name} ({what})" + (f"; {hint}" if hint else ""))
    signals = []
    nx = 2 * eom.n
    x0 = np.zeros(nx) if x0 is None else np.asarray(x0, float).ravel()
    for j, name in enumerate(names):
        default = float(eom.input_defaults[j]) if j < len(eom.input_defaults) else 0.0
        if name not in spec or spec[name] is None:
            signals.append(Signal(name, "default", value=default))
            continue
        signals.append(_signal(name, spec[name], t0, t1, x0, nx))
    drive = Drive(names, signals, bounds, (float(t0), float(t1)))
    for s, (lo, hi) in zip(signals, bounds):
        vals = (np.array([s.value]) if s.kind in ("default", "constant") else
                s.table.values if s.kind == "table" else None)
        if vals is None:
            continue
        if (lo is not None and vals.min() < lo) or (hi is not None and vals.max() > hi):
            raise UsageError(f"input '{s.name}' = {vals.min() if lo is not None and vals.min() < lo else vals.max():g} "
                             f"is outside its declared bounds [{'-inf' if lo is None else f'{lo:g}'}, "
                             f"{'inf' if hi is None else f'{hi:g}'}]")
    return drive


def _signal(name, v, t0, t1, x0, nx) -> Signal:
    import casadi as ca

    if isinstance(v, bool):
        raise UsageError(f"input '{name}': expected a number, a table, a callable or a casadi.Function (got {v!r})")
    if isinstance(v, (int, float, np.floating, np.integer)):
        if not np.isfinite(float(v)):
            raise UsageError(f"input '{name}' = {v}: not a finite number")
        return Signal(name, "constant", value=float(v))
    if isinstance(v, ca.Function):
        return _function_signal(name, v, t0, x0, nx)
    if callable(v):
        return _callable_signal(name, v, t0, x0, nx)
    if not isinstance(v, Table):
        try:
            arr = np.asarray(v, float)
        except (TypeError, ValueError):
            raise UsageError(f"input '{name}': expected a number, a table, a callable or a casadi.Function "
                             f"(got {type(v).__name__})") from None
        if arr.ndim == 0:
            return _signal(name, float(arr), t0, t1, x0, nx)
        if arr.ndim == 2 and arr.shape[1] == 2:
            v = table(arr[:, 0], arr[:, 1])
        elif arr.ndim == 2 and arr.shape[0] == 2:
            v = table(arr[0], arr[1])
        else:
            raise UsageError(f"input '{name}': a table is an (N, 2) array of (time, value) rows (got shape {arr.shape})")
    span = (v.times[0], v.times[-1])
    tol = 1e-12 * max(1.0, abs(t0), abs(t1))
    if span[0] > t0 + tol or span[1] < t1 - tol:
        raise UsageError(f"the table of input '{name}' covers t = {span[0]:g} .. {span[1]:g} s, not the run's "
                         f"{t0:g} .. {t1:g} s; add samples at both ends")
    return Signal(name, "table", table=v)


def _function_signal(name, f, t0, x0, nx) -> Signal:
    if f.n_in() not in (1, 2) or f.n_out() != 1 or f.numel_in(0) != 1 or (f.n_in() == 2 and f.numel_in(1) != nx):
        raise UsageError(f"input '{name}': a casadi.Function signal takes (t) or (t, x) with x of {nx} entries "
                         f"and returns a scalar (got {f})")
    if f.numel_out(0) != 1:
        raise UsageError(f"input '{name}': the Function returns {f.size1_out(0)}x{f.size2_out(0)} values, not a scalar")
    return Signal(name, "function", fn=f, feedback=f.n_in() == 2)


def _callable_signal(name, fn, t0, x0, nx) -> Signal:
    try:
        params = [p for p in inspect.signature(fn).parameters.values()
                  if p.kind in (p.POSITIONAL_ONLY, p.POSITIONAL_OR_KEYWORD) and p.default is p.empty]
        feedback = len(params) >= 2
    except (TypeError, ValueError):
        feedback = False
    try:
        first = fn(t0, x0.copy()) if feedback else fn(t0)
    except Exception as e:  # noqa: BLE001 - the user's code: report, never a traceback
        raise UsageError(f"input '{name}': calling the signal at t = {t0:g} failed: {type(e).__name__}: {e}") from None
    arr = np.asarray(first, dtype=float) if _numeric(first) else None
    if arr is None or arr.size != 1:
        got = "a non-number" if arr is None else f"shape {arr.shape}"
        raise UsageError(f"input '{name}': the signal must return one number per call (got {got} at t = {t0:g})")
    return Signal(name, "callable", fn=_callback(name, fn, feedback, nx), feedback=feedback)


def _numeric(v) -> bool:
    try:
        np.asarray(v, dtype=float)
        return True
    except (TypeError, ValueError):
        return False


def _callback(name, fn, feedback, nx):
    """A casadi.Callback around a Python signal (finite differences for derivatives).

    A call that fails or returns anything but one number gives NaN (never a Python exception
    through CasADi, whose traceback would be printed): the back end stops the run there as
    for a non-finite right-hand side, and ``error`` keeps the first problem for the report."""
    import casadi as ca

    class PySignal(ca.Callback):
        def __init__(self):
            ca.Callback.__init__(self)
            self.error = None
            self.construct(_fname("input", name), {"enable_fd": True})

        def get_n_in(self):
            return 2 if feedback else 1

        def get_n_out(self):
            return 1

        def get_sparsity_in(self, i):
            return ca.Sparsity.dense(1, 1) if i == 0 else ca.Sparsity.dense(nx, 1)

        def eval(self, args):
            t = float(args[0])
            try:
                v = fn(t, np.array(args[1], float).ravel()) if feedback else fn(t)
                arr = np.asarray(v, dtype=float).ravel()
            except Exception as e:  # noqa: BLE001 - the user's code: reported with the run's failure
                return self._fail(t, f"calling the signal failed: {type(e).__name__}: {e}")
            if arr.size != 1:
                return self._fail(t, f"the signal returned {arr.size} values, not one number")
            return [ca.DM(float(arr[0]))]

        def _fail(self, t, what):
            if self.error is None:
                self.error = f"input '{name}' at t = {t:.6g}: {what}"
            return [ca.DM(float("nan"))]

    return PySignal()
