"""The one recorder: a trajectory -> the signals of a Result.

Every back end records through ``record(eom, columns, t, Q, QD, p, U, LAM)``: ``columns`` is
an ordered mapping name -> SX expression in (t, q, qd, u, p, lam); the recorder builds one
CasADi Function of (t, q, qd, u, p, lam) for that tuple of names, maps it over the time
points in one call, and splits the rows into signals (a vector column ``v`` becomes v[1],
v[2], ...: 1-based).  Function and map are kept in the EOM's workspace (shared by its
``replace`` copies, keyed by the identity of the symbolic fields), so a second run of the
same model, at any parameter values, builds nothing.

The column sets, in the order the back ends record them (a back end composes these and adds
only its own columns: contact gaps and forces, H and the canonical momenta, the multipliers
and reactions, the integrator's drift measures):

- ``outputs(eom, names)``        the model's outputs
- ``energies(eom)``              kinetic_energy, potential_energy, energy
- ``residuals(eom)``             residual(<constraint>) for every constraint
- ``invariants(eom)``            the declared drift measures (quaternion norms)
- ``integrals(eom, f, folded)``  the first integrals found by the search (simulate.py)
- ``monitors(eom)``              singularity(<joint>.gimbal)
- ``drift(eom)``                 constraint_drift ||g||_inf, velocity_drift ||G qd + g_t||_inf

Same names, order and values as the four recorders this replaces (simulate.compute_signals,
dae/record.evaluate_signals, impacts/simulate._signals, symplectic._signals).  Non-finite
values are judged once, after recording, by ``accuracy.check_finite`` in the run template.
"""
from __future__ import annotations

import threading

import numpy as np

from ..eom.codegen import singularity_monitors
from .backends.crk import mapped as _interpreted


ENERGY_NAMES = ("kinetic_energy", "potential_energy", "energy")
# the symbolic fields a column may read: the Functions are shared while these are the same objects
MAPS_KEPT = 8           # mapped Functions kept per recorder Function (by number of points)
_FIELDS = ("t", "q", "qd", "u", "p", "lam", "T", "V", "g", "outputs", "invariants", "singularity_monitors",
           "reactions")


def record(eom, columns: dict, t, Q, QD, p, U=None, LAM=None, using=(), keep: bool = True) -> dict[str, np.ndarray]:
    """Values of ``columns`` at the recorded states.

    t (N,), Q and QD (N, n), p the parameter vector, U (N, n_u) the inputs (None: their
    defaults), LAM (N, m) the multipliers (None: zeros; only reaction columns read them).
    ``using``: objects besides the EOM's fields the columns were built from (the first
    integrals' Function), part of the cache key.  keep=False: columns built afresh for this
    call only (not cached: the Function is built, used and dropped)."""
    names, F, maps = _function(eom, columns, tuple(using), keep)
    return _evaluate(names, F, maps, (eom.n, len(eom.inputs), lam_symbol(eom).numel(), eom.input_defaults),
                     t, Q, QD, p, U, LAM)


def recorder(eom, columns: dict, using=(), mapper=None):
    """``record`` of these columns as a function (t, Q, QD, p, U=None, LAM=None) -> signals, its
    Function looked up once (a run's setup keeps it: the same numbers, without the look-up).
    ``mapper``: (Function, evaluator at many points like crk.Mapped) used when the columns'
    Function is that one (its compiled code, crk.compiled_mapped: the same bits)."""
    names, F, maps = _function(eom, columns, tuple(using), True)
    sizes = (eom.n, len(eom.inputs), lam_symbol(eom).numel(), eom.input_defaults)
    if mapper is not None and mapper[0] is F and mapper[1] is not None:
        maps = {"interpreted": mapper[1]}         # this recorder's own: the shared maps stay as they are

    def call(t, Q, QD, p, U=None, LAM=None):
        return _evaluate(names, F, maps, sizes, t, Q, QD, p, U, LAM)
    call.names, call.function, call.sizes = names, F, sizes      # (what a prepared warm run keeps)
    return call


def recorder_function(eom, columns: dict, using=()):
    """The Function ``recorder(eom, columns, using)`` evaluates."""
    return _function(eom, columns, tuple(using), True)[1]


def recorder_names(eom, columns: dict, using=()) -> list:
    """The signal names of ``recorder(eom, columns, using)``, in the order of its Function's rows."""
    return _function(eom, columns, tuple(using), True)[0]


def _evaluate(names, F, maps, sizes, t, Q, QD, p, U, LAM) -> dict[str, np.ndarray]:
    t = np.asarray(t, float).reshape(-1)
    N = len(t)
    if not names:
        return {}
    if N == 0:
        return {k: np.zeros(0) for k in names}
    n, nu, m, defaults = sizes
    UT = (np.repeat(np.asarray(defaults, float).reshape(-1, 1), N, axis=1) if U is None
          else np.asarray(U, float).reshape(N, nu).T)
    LT = (np.asarray(LAM, float).reshape(N, m).T if LAM is not None and np.size(LAM) == N * m
          else np.zeros((m, N)))
    QT = np.asarray(Q, float).reshape(N, n).T
    QDT = np.asarray(QD, float).reshape(N, n).T
    P = np.asarray(p, float).reshape(-1)
    interp = maps.get("interpreted", False)
    if interp is False:                        # the runtime's interpreter (no compile), once per Function
        interp = maps["interpreted"] = _interpreted(F)
    if interp is not None:
        vals = interp(N, (t.reshape(N, 1), QT.T, QDT.T, UT.T, P, LT.T)).T
        return {k: vals[i] for i, k in enumerate(names)}
    mapped = maps.get(N)
    if mapped is None:
        # p shared by the points (reduce_in), called through a buffer (FastFunction): a plain
        # call converts every argument to DM and back, 2-3 times the evaluation itself
        mapped = _Mapped(F.map("record_map", "serial", N, [4], []))
        if len(maps) >= MAPS_KEPT:             # a few point counts per Function (runs that failed early)
            try:
                maps.pop(next(k for k in maps if isinstance(k, int)), None)
            except (RuntimeError, StopIteration):  # another thread changed it meanwhile: keep it
                pass
        maps[N] = mapped
    vals = np.reshape(mapped(t.reshape(1, N), QT, QDT, UT, P, LT), (len(names), N), order="F")
    return {k: vals[i] for i, k in enumerate(names)}


class _Mapped:
    """A mapped recorder Function called through its buffer (FastFunction), one thread at a
    time; a concurrent caller (another thread's run) makes a plain call instead."""

    def __init__(self, f):
        from ..eom.codegen import FastFunction

        self.f, self.fast = f, FastFunction(f)
        self.lock = threading.Lock()

    def __call__(self, *args):
        if self.lock.acquire(blocking=False):
            try:
                return self.fast(*args)
            finally:
                self.lock.release()
        return np.array(self.f(*args), float)


def lam_symbol(eom):
    """The multipliers' symbol: EOM.lam (derive makes it for constrained models); an EOM
    built by hand without one gets a symbol kept in its workspace (no output reads it)."""
    import casadi as ca

    if eom.lam is not None:
        return eom.lam
    return eom.workspace.memo("lam", lambda: ca.SX.sym("lam", eom.m) if eom.m else ca.SX(0, 1))


def function(eom, columns: dict):
    """(column names, Function (t, q, qd, u, p, lam) -> the columns stacked): the recorder's own
    Function of these columns, kept as ``record`` keeps it (the trajectory Function of
    simulation/trajectory.py maps it inside its graph, so its derivatives are CasADi's)."""
    names, f, _ = _function(eom, columns, ())
    return names, f


def _function(eom, columns: dict, using: tuple, keep: bool = True):
    """(column names, Function (t, q, qd, u, p, lam) -> all columns stacked, its maps by
    number of points), built once."""
    def build():
        import casadi as ca

        names, exprs = [], []
        for k, v in columns.items():
            v = ca.SX(v)
            if v.numel() == 1:
                names.append(k)
            else:
                names += [f"{k}[{i + 1}]" for i in range(v.numel())]
            exprs.append(ca.vec(v))
        ins = [eom.t, eom.q, eom.qd, eom.u_sym, eom.p, lam_symbol(eom)]
        f = ca.Function("record", ins, [ca.vertcat(*exprs) if exprs else ca.SX(0, 1)],
                        ["t", "q", "qd", "u", "p", "lam"], ["signals"])
        return names, f, {}

    return eom.workspace.recorder(eom, _FIELDS, tuple(columns), build, using) if keep else build()


# --------------------------------------------------------------------------- column sets


def outputs(eom, names) -> dict:
    return {k: eom.outputs[k] for k in names}


def energies(eom) -> dict:
    return {"kinetic_energy": eom.T, "potential_energy": eom.V, "energy": eom.T + eom.V}


def residuals(eom) -> dict:
    if eom.g is None:
        return {}
    import casadi as ca

    g = ca.SX(eom.g)
    return {f"residual({c})": g[i] for i, c in enumerate(eom.constraint_names)}


def invariants(eom) -> dict:
    return dict(eom.invariants or {})


def monitors(eom) -> dict:
    return {f"singularity({k})": v for k, v in singularity_monitors(eom).items()}


def drift(eom) -> dict:
    """The constraint drift measures of a state: position level and velocity level."""
    import casadi as ca

    g = ca.SX(eom.g)
    return {"constraint_drift": ca.norm_inf(g),
            "velocity_drift": ca.norm_inf(ca.mtimes(ca.jacobian(g, eom.q), eom.qd) + ca.jacobian(g, eom.t))}


def integrals(eom, f, folded: bool = False) -> dict:
    """The first integrals of the Function f(t, x, p) (the search's result; None: none) as
    columns; ``folded``: f was found on the model with its constant inputs as trailing
    parameters (p' = [p; u])."""
    if f is None:
        return {}
    import casadi as ca

    if not f.is_a("SXFunction"):
        f = f.expand()
    p = ca.vertcat(eom.p, eom.u_sym) if folded else eom.p
    res = f(eom.t, ca.vertcat(eom.q, eom.qd), p)
    res = res if isinstance(res, (list, tuple)) else [res]
    return dict(zip(f.name_out(), res))


def model_columns(eom, out_names, integral_fn=None, folded: bool = False) -> dict:
    """What every unconstrained run records: outputs, energies, residuals (an ODE model with
    constraints), invariants, the first integrals (not replacing a name already there) and
    the singularity monitors."""
    cols = merged(outputs(eom, out_names), energies(eom), residuals(eom), invariants(eom))
    cols.update({k: v for k, v in integrals(eom, integral_fn, folded).items() if k not in cols})
    cols.update(monitors(eom))
    return cols


def merged(*sets: dict) -> dict:
    """Column sets in order; a later set's value replaces an earlier one of the same name in
    place (as the old recorders' dict updates did)."""
    out: dict = {}
    for s in sets:
        out.update(s)
    return out
