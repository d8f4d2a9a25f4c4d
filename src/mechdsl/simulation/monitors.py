"""What a run watches besides its states: first integrals, energy drift, singularity monitors.

``compute_signals`` records an unconstrained run's signals (outputs, energies, residuals,
invariants, first integrals, singularity monitors) through the one recorder (record.py);
the first-integral search is kept in the EOM's workspace and on disk; ``is_conservative``
is the one answer to "does this model conserve its energy" (no D, no Q, T and V without t).
"""
from __future__ import annotations

import numpy as np

from .. import analysis  # its face: the first-integral search is imported when a run first searches
from ..eom import fold_inputs, integralcache
from . import record as R
from .accuracy import energy_drift, integral_drift_of, note_extremes, note_facts


def compute_signals(eom, t, X, pv, out_names, U=None) -> dict[str, np.ndarray]:
    """What an unconstrained run records (simulation/record.py: outputs, energies, residuals,
    invariants, first integrals, singularity monitors) on the sample times.  U: the inputs on
    the sample times (rows = times; None: the inputs' defaults)."""
    t = np.asarray(t, float).reshape(-1)
    N, n = len(t), eom.n
    if N == 0:
        return {}
    X = np.asarray(X, float).reshape(N, 2 * n)
    UT = (np.tile(np.asarray(eom.input_defaults, float).reshape(-1, 1), (1, N)) if U is None
          else np.asarray(U, float).reshape(N, -1).T)
    steady = UT[:, 0] if UT.size and np.all(UT == UT[:, :1]) else (UT[:, 0] if not UT.size else None)
    f, folded = _integral_search(eom, pv, steady)
    # the columns' expressions are built once per model, outputs and integrals (the recorder
    # keys its Function by their names; building them is a tenth of a small model's run)
    cols = eom.workspace.memo(("model_columns", tuple(out_names), id(f), folded),
                              lambda: (f, R.model_columns(eom, out_names, f, folded)))[1]
    return R.record(eom, cols, t, X[:, :n], X[:, n:], pv, UT.T, using=(f,))


def _recorded_columns(eom, pv, out_names):
    """(the first integrals' Function, the columns) a model without inputs records at ``pv``."""
    f, folded = _integral_search(eom, pv, np.zeros(0))
    cols = eom.workspace.memo(("model_columns", tuple(out_names), id(f), folded),
                              lambda: (f, R.model_columns(eom, out_names, f, folded)))[1]
    return f, cols


def recorder_function(eom, pv, out_names):
    """The recorder's Function (record.py) of a model without inputs at ``pv``: the Function
    ``signal_recorder`` evaluates (a setup compiles it beside the model's ode)."""
    f, cols = _recorded_columns(eom, np.array(pv, float), out_names)
    return R.recorder_function(eom, cols, using=(f,))


def signal_recorder(eom, pv, out_names, mapper=None):
    """``compute_signals`` of a model without inputs at the parameters ``pv`` as a function
    (t, X) -> signals, its first integrals and columns looked up once (a setup keeps it for its
    runs: the same numbers).  ``mapper``: (Function, its evaluator at many points) to use when
    the recorder's Function is that one (compiled code of it: the same bits)."""
    pv = np.array(pv, float)
    f, cols = _recorded_columns(eom, pv, out_names)
    n = eom.n
    evaluate = R.recorder(eom, cols, using=(f,), mapper=mapper)

    names = R.recorder_names(eom, cols, using=(f,))
    fast = mapper[1] if mapper is not None and mapper[0] is R.recorder_function(eom, cols, using=(f,)) else None

    def rec(t, X):
        t = np.asarray(t, float).reshape(-1)
        if not len(t):
            return {}
        X = np.asarray(X, float).reshape(len(t), 2 * n)
        got = fast.columns(t, X, n, pv) if fast is not None and names and fast.nout == len(names) else None
        if got is not None:       # the same values by column, their extremes from the same pass in C
            vals, extremes = got
            rows = [vals[i] for i in range(len(names))]
            if not note_extremes(vals, rows, extremes):
                note_facts(vals, rows)
            return dict(zip(names, rows))
        vals = fast.states(t, X, n, pv) if fast is not None and names else None
        if vals is not None:      # the compiled recorder reading the states in place (the same values)
            vals = np.ascontiguousarray(vals.T)      # each signal contiguous
            rows = [vals[i] for i in range(len(names))]
            note_facts(vals, rows)                    # drift and finiteness of all of them in one pass
            return dict(zip(names, rows))
        return evaluate(t, X[:, :n], X[:, n:], pv, np.zeros((len(t), 0)))
    rec.evaluate = evaluate
    return rec


def singularity_report(eom, signals, t, meta, threshold):
    mons = getattr(eom, "singularity_monitors", None) or {}
    if not mons or len(t) == 0:
        return
    report = {}
    for name, spec in mons.items():
        thr = spec[1] if isinstance(spec, tuple) and len(spec) > 1 else threshold
        v = np.abs(signals[f"singularity({name})"])
        i = int(np.argmin(v))
        report[name] = {"closest": float(v[i]), "time": float(t[i]), "threshold": float(thr)}
        if v[i] < thr:
            meta["warnings"].append(
                f"the run came within {v[i]:.3g} of the singular configuration of {name} at t = {t[i]:.6g} "
                f"(Euler/Cardan angles lose a degree of freedom there; accuracy degrades; a quaternion "
                f"parametrization avoids this)")
    meta["singularity"] = report


MAX_INTEGRAL_SEARCH = 20   # coordinates: beyond this the search costs more than a typical run


def _integral_search(eom, pv, u=None):
    """(the first integrals' Function (t, x, p) or None, whether it is of the folded model):
    cyclic momenta and the Jacobi integral, recorded so their drift measures the integrator.
    The search is kept in the workspace (and on disk).  u: the inputs' constant values (None:
    time-varying, then no integrals are searched); with inputs the search runs on the model
    with them as trailing parameters."""
    if eom.inputs:
        if u is None:
            return None, False

        key = tuple(float(v) for v in u)
        folded = eom.workspace.folded(key, lambda: fold_inputs(eom, u))
        return _integral_search(folded, np.r_[pv, u])[0], True
    searchable = eom.n <= MAX_INTEGRAL_SEARCH and eom.model is not None and not eom.model.contacts

    def search():
        # shared by the EOM's replace copies with the same equations (other Models of the same
        # structure): one Function object, so the recorder's Function is shared too
        return eom.workspace.by_content(eom, ("q", "qd", "t", "p", "T", "V", "D", "Q", "g"),
                                        ("first_integrals", np.asarray(pv, float).tobytes()),
                                        lambda: _integral_function(eom, pv))

    return eom.workspace.first_integrals(search if searchable else lambda: None), False


def _integral_function(eom, pv):
    """The first integrals as one Function (t, x, p), or None: searched once, then kept on disk
    (mechdsl.eom.integralcache: an entry is checked against its full key and signature)."""
    import casadi as ca

    found, f = integralcache.lookup(eom, pv)
    if found:
        return f
    try:
        sig = analysis.integral_signals(eom, pv)
    except Exception:  # noqa: BLE001 - a failed search only means nothing extra is recorded
        sig = {}
    if sig:
        x = ca.vertcat(eom.q, eom.qd)
        f = ca.Function("first_integrals", [eom.t, x, eom.p], list(sig.values()), ["t", "x", "p"], list(sig))
    integralcache.store(eom, pv, f)
    return f


def integral_drift(signals, eom) -> dict:
    return integral_drift_of(signals, integral_names(eom))


def integral_names(eom) -> list[str]:
    """The names of the first integrals a run of ``eom`` records (the search's, kept)."""
    fs = [eom.workspace.first_integrals()]
    if eom.inputs:      # the integrals were searched on the model with constant inputs folded in
        fs = [v.workspace.first_integrals() for v in eom.workspace.folded_variants()]
    return [n for f in fs if f is not None for n in f.name_out()]


def energy_drift_stats(signals) -> dict:
    """accuracy.energy_drift without the keys it cannot fill (a back end's own statistics)."""
    return {k: v for k, v in energy_drift(signals).items() if v is not None}


def is_conservative(eom) -> bool:
    """D = 0, Q = 0 and T, V independent of time.  Builds Q when the recursive route has not
    yet: an answer that depended on whether another caller had built it would make the
    metadata and ``--emit problem`` depend on what ran before in the process."""
    def answer():
        import casadi as ca

        try:
            D, Q = ca.SX(eom.D), ca.SX(eom.Q)
            return bool(D.is_zero() and Q.is_zero()
                        and not ca.depends_on(ca.vertcat(ca.SX(eom.T), ca.SX(eom.V)), eom.t))
        except Exception:  # noqa: BLE001
            return False

    # kept for the EOM's copies with the same T, V, D, Q (every run asks, twice)
    return eom.workspace.by_content(eom, ("T", "V", "D", "Q", "t"), "is_conservative", answer)

