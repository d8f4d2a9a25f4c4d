"""What every run reports the same way: one statistics schema, the check for non-finite
values, invariant drift and the accuracy warning, and the error estimate by a second run.

Statistics schema (``Result.stats``; None where a back end cannot count):

    steps, rhs_evals, jac_evals, rejected_steps, events, points, cpu_time, wall_time,
    energy_drift, energy_drift_relative, invariant_drift {name: max |v - v(0)|},
    constraint_drift (max ||g|| over the run, constrained models)

Back ends may add their own keys beside these (e.g. ``nsteps`` from CVODES in DAE runs).
"""
from __future__ import annotations

import math
import sys

from ..output.result import Failure, Result


SCHEMA = ("steps", "rhs_evals", "jac_evals", "rejected_steps", "events", "points", "cpu_time", "wall_time",
          "energy_drift", "energy_drift_relative", "invariant_drift", "constraint_drift")
# a back end's name for a count -> the schema's name (first found wins)
ALIASES = {"steps": ("steps", "nsteps", "n_steps"),
           "rhs_evals": ("rhs_evals", "nfevals", "rhs_evaluations", "n_rhs"),
           "jac_evals": ("jac_evals", "njev", "n_call_jacF", "n_jac"),
           "rejected_steps": ("rejected_steps", "error_test_failures", "netfails", "n_reject",
                              "rejected_subsegments"),
           "constraint_drift": ("constraint_drift", "max_constraint_drift")}
# A recorded block's facts, worked out in one pass over all its signals (note_facts) instead of a
# few numpy calls per signal and question (the energy drift, the first integrals' drift, the
# invariants, the non-finite check each asked again: a fifth of a small model's warm run):
# id(signal) -> (weak reference, every value finite, max |v|, max |v - v[0]|).  A signal that
# is not the noted array (replaced, cut by check_finite) is asked directly, as before.
_FACTS: dict = {}
FACTS_KEPT = 256


def note_facts(block, rows) -> None:
    """Note the facts of the signals ``rows`` (the rows of ``block``, (k, N), as arrays)."""
    import numpy as np

    if block.ndim != 2 or block.shape[1] == 0 or len(rows) != block.shape[0]:
        return
    # from each row's max and min alone: max |v| = max(hi, -lo), and max |v - v0| = max(hi - v0,
    # v0 - lo) exactly (rounding is monotonic and symmetric: the largest rounded difference is the
    # rounded difference of the extreme); a NaN or an inf carries through both.  A row is all
    # finite exactly when its max |v| is.
    hi, lo = block.max(axis=1), block.min(axis=1)
    v0 = block[:, 0]
    amax = np.maximum(hi, -lo)
    finite = np.isfinite(amax).tolist()
    dmax = np.maximum(hi - v0, v0 - lo).tolist()
    amax = amax.tolist()
    _note([(v, finite[i], amax[i], dmax[i]) for i, v in enumerate(rows)])


def note_extremes(block, rows, extremes) -> bool:
    """note_facts' facts of the ``rows`` of ``block`` from each row's largest and smallest value
    (``extremes``: the k largest, the k smallest, k ambiguous-zero flags, as crk_map_cols gives
    them in the recorder's pass), the same numbers without a numpy pass over the block; False
    (nothing noted: the caller uses note_facts) where numpy's own order would decide the sign of
    a zero."""
    k = len(rows)
    if len(extremes) != 3 * k or any(extremes[2 * k:]):
        return False
    v0 = block[:, 0].tolist()
    facts = []
    for i, v in enumerate(rows):
        hi, lo, x0 = extremes[i], extremes[k + i], v0[i]
        amax, dmax = _maximum(hi, -lo), _maximum(hi - x0, x0 - lo)
        if amax is None or dmax is None:
            return False
        facts.append((v, math.isfinite(amax), amax, dmax))
    _note(facts)
    return True


def _maximum(a: float, b: float):
    """numpy.maximum of two floats (a NaN wins), None for two zeros of opposite signs."""
    if a != a:
        return a
    if b != b:
        return b
    if a == b and a == 0.0 and math.copysign(1.0, a) != math.copysign(1.0, b):
        return None
    return a if a >= b else b


def note_plain(signals) -> bool:
    """Note the facts of the ``signals`` (array.arrays of floats, none empty) in plain Python, the
    same numbers as note_facts (max of exact differences and magnitudes); False when a value is
    not finite (nothing noted)."""
    facts = []
    for v in signals:
        if not math.isfinite(sum(v)):          # (a nan or inf makes the sum non-finite; so may an overflow)
            return False
        v0 = v[0]
        facts.append((v, True, max(map(abs, v)), max(abs(x - v0) for x in v)))
    _note(facts)
    return True


def _note(facts) -> None:
    import weakref

    if len(_FACTS) + len(facts) > FACTS_KEPT:
        _FACTS.clear()
    ref = weakref.ref
    for v, finite, amax, dmax in facts:
        _FACTS[id(v)] = (ref(v), finite, amax, dmax)


def _facts(v):
    """(max |v|, max |v - v[0]|) of a noted signal whose values are all finite, else None."""
    hit = _FACTS.get(id(v))
    if hit is not None and hit[0]() is v and hit[1]:
        return hit[2], hit[3]
    return None


def drift_of(v) -> float | None:
    """max |v - v[0]| of a signal whose values are all finite (None otherwise or when empty)."""
    f = _facts(v)
    if f is not None:
        return f[1]
    if v is None or len(v) == 0:
        return None
    import numpy as np

    if not np.isfinite(v).all():
        return None
    return float(np.abs(v - v[0]).max())


DRIFT_FACTOR = 100.0   # invariant drift this many times the tolerance: the accuracy warning (drift_limit)
WARN_FACTOR = 30.0     # error estimate / tolerance class above this: the accuracy warning (estimate.py)
DRIFT_CAP = 0.05       # ... and never above this relative drift
STEP_LIMIT = 0.01      # a fixed step the user chose: the estimate above this fraction of the coordinate's size warns


def check_finite(r: Result) -> None:
    """A run whose state or a recorded signal (an output, an energy) became inf/nan fails at
    the first such time, naming it; the results before that time are kept.  A CSV never
    carries inf or nan from a run that says it succeeded."""
    import numpy as np

    _check_states(r)
    first = None
    for name, v in r.signals.items():
        if isinstance(v, np.ndarray) and v.ndim == 1 and v.dtype.kind == "f" and len(v) == len(r.t):
            if _facts(v) is not None or math.isfinite(np.add.reduce(v)):   # noted finite, or a finite sum
                continue
            idx = np.flatnonzero(~np.isfinite(v))
            if idx.size and (first is None or idx[0] < first[0]):
                first = (int(idx[0]), name, v[idx[0]])
    if first is None:
        return
    k, name, value = first
    t_bad = float(r.t[k])
    if r.failure is None:        # a run that failed already keeps its diagnosis (the nan follows from it)
        r.failure = Failure(time=t_bad, cause="non-finite output",
                            detail=f"{name} became {value} at t = {t_bad:.10g} (the model's expression for it, "
                                   "e.g. a square root of a negative number or a division by zero); results kept "
                                   + (f"up to t = {float(r.t[k - 1]):.10g}" if k else "from no time"))
    _truncate(r, k)


def _check_states(r: Result) -> None:
    import numpy as np

    if r.q.size == 0 and r.qd.size == 0:
        return
    b = r.q.base
    if (b is not None and b is r.qd.base and type(b) is np.ndarray and b.ndim == 2 and b.flags.c_contiguous
            and b.shape == (r.q.shape[0], r.q.shape[1] + r.qd.shape[1])):
        if math.isfinite(np.add.reduce(b, axis=None)):
            return                    # q and qd are the two halves of one block (a run's states): one sum
    elif math.isfinite(np.add.reduce(r.q, axis=None)) and math.isfinite(np.add.reduce(r.qd, axis=None)):
        return                        # a finite sum: every value finite
    X = np.hstack([r.q, r.qd])
    bad = ~np.isfinite(X)
    rows = np.flatnonzero(bad.any(axis=1))
    if rows.size == 0:
        return
    k = int(rows[0])
    names = list(r.coordinates) + [f"der({c})" for c in r.coordinates]
    col = int(np.flatnonzero(bad[k])[0])
    t_bad = float(r.t[k])
    value = X[k, col]
    if r.failure is None or r.failure.time > t_bad:
        r.failure = Failure(time=t_bad, cause="non-finite state",
                            detail=f"{names[col]} became {value} at t = {t_bad:.10g}; results kept "
                                   + (f"up to t = {float(r.t[k - 1]):.10g}" if k else "from no time"))
    _truncate(r, k)


def _truncate(r: Result, keep: int) -> None:
    """Keep the first ``keep`` output times of the result (signals and events with them)."""
    import numpy as np

    r.t = r.t[:keep].copy()
    r.q = r.q[:keep].copy()
    r.qd = r.qd[:keep].copy()
    r.signals = {k2: (v[:keep].copy() if isinstance(v, np.ndarray) and v.ndim >= 1 and len(v) >= keep else v)
                 for k2, v in r.signals.items()}
    last = float(r.t[-1]) if keep else -math.inf
    r.events = [e for e in r.events if float(e.get("time", -math.inf)) <= last]


def normalize_stats(r: Result, cpu_time: float, wall_time: float) -> None:
    st = r.stats
    for key, names in ALIASES.items():
        if st.get(key) is None:
            st[key] = next((st[n] for n in names if st.get(n) is not None), None)
    ev = st.get("events")
    np = sys.modules.get("numpy")         # (not imported: the count is no numpy integer)
    st["events"] = int(ev) if isinstance(ev, int) or np is not None and isinstance(ev, np.integer) else len(r.events)
    st["points"] = int(len(r.t))
    st["cpu_time"] = float(cpu_time)            # both over the whole back-end call (set-up included)
    st["wall_time"] = float(wall_time)
    if st.get("energy_drift") is None:
        st.update(energy_drift(r.signals))
    for key in SCHEMA:
        st.setdefault(key, None)


def energy_drift(signals) -> dict:
    E = signals.get("energy")
    fe = None if E is None else _facts(E)
    if fe is not None:        # noted (all finite): the same numbers without asking the arrays again
        fk = _facts(signals.get("kinetic_energy", E))
        fp = _facts(signals.get("potential_energy", E))
        if fk is not None and fp is not None:
            dE = fe[1]
            scale = max(abs(float(E[0])), fk[0], fp[0], 1e-300)
            return {"energy_drift": dE, "energy_drift_relative": dE / scale}
    if E is None or len(E) == 0:
        return {"energy_drift": None, "energy_drift_relative": None}
    import numpy as np

    if not np.isfinite(E).all():
        return {"energy_drift": None, "energy_drift_relative": None}
    dE = float(np.abs(E - E[0]).max())
    scale = max(abs(float(E[0])), float(np.abs(signals.get("kinetic_energy", E)).max()),
                float(np.abs(signals.get("potential_energy", E)).max()), 1e-300)
    return {"energy_drift": dE, "energy_drift_relative": dE / scale}


def integral_drift_of(signals, names) -> dict:
    """{"first_integral_drift": {name: max |v - v(0)|}} of the first integrals ``names`` among
    the signals (finite ones only); {} when there is none."""
    out = {}
    for name in names:
        d = drift_of(signals.get(name))       # (the facts noted in one pass when there are)
        if d is not None:
            out[name] = d
    return {"first_integral_drift": out} if out else {}


def drift_limit(rtol: float) -> float:
    """The relative drift of an invariant (the energy of a conservative model, a first integral, a
    quaternion's norm) above which a run warns: DRIFT_FACTOR x rtol, never above DRIFT_CAP (a
    loose tolerance does not excuse 80 %).  The one rule for every back end (the DAE back end's
    energy check reads it too)."""
    return min(DRIFT_CAP, DRIFT_FACTOR * rtol)


def accuracy_report(r: Result, problem, fixed_step: bool) -> None:
    """Invariant drift of every run (r.stats["invariant_drift"], metadata["accuracy"]["invariants"]);
    a drift beyond what the tolerance suggests (adaptive methods: relative drift above
    drift_limit(rtol) and absolute drift above DRIFT_FACTOR x atol) is marked for the accuracy
    warning (accuracy_warning)."""
    s = problem.settings
    drift, report = {}, {}
    names = list(dict.fromkeys(list(problem.invariants) + list(r.stats.get("first_integral_drift") or {})))
    for name in names:
        v = r.signals.get(name)
        fv = None if v is None else _facts(v)
        if fv is None:
            if v is None or len(v) == 0:
                continue
            import numpy as np

            if not np.isfinite(v).all():
                continue
        d, scale = (fv[1], fv[0]) if fv is not None else (float(np.abs(v - v[0]).max()), float(np.abs(v).max()))
        if name == "energy":
            fk = _facts(r.signals.get("kinetic_energy", v))
            fp = _facts(r.signals.get("potential_energy", v))
            if fk is not None and fp is not None:
                scale = max(scale, fk[0], fp[0])
            else:
                import numpy as np

                scale = max(scale, float(np.abs(r.signals.get("kinetic_energy", v)).max()),
                            float(np.abs(r.signals.get("potential_energy", v)).max()))
        rel = d / scale if scale > 1e-300 else d
        drift[name] = d
        report[name] = {"drift": d, "relative": rel}
        if not fixed_step and rel > drift_limit(s.rtol) and d > DRIFT_FACTOR * s.atol:
            report[name]["warning"] = True
    r.stats["invariant_drift"] = drift
    r.metadata.setdefault("accuracy", {}).update({"invariants": report, "rtol": s.rtol, "atol": s.atol})


def accuracy_warning(r: Result, problem) -> str | None:
    """The one accuracy warning of a run (appended to metadata["warnings"] and kept in
    metadata["accuracy"]["warning"]): the error estimate above accuracy.WARN_FACTOR times the
    tolerance class and/or invariants drifting beyond drift_limit; None when neither."""
    s = problem.settings
    acc = r.metadata.setdefault("accuracy", {})
    parts = []
    ratio = acc.get("error_estimate_ratio")
    # a fixed step the user chose has no tolerance class to exceed (a step from rtol has)
    chosen_step = problem.kind == "canonical" and s.dt is not None
    unit = f" {acc['error_estimate_unit']}" if acc.get("error_estimate_unit") else ""
    relative = acc.get("error_estimate_relative")
    if chosen_step and acc.get("error_estimate") is not None and relative is not None and relative > STEP_LIMIT:
        where = acc["error_estimate_relative_coordinate"]
        parts.append(f"the estimated error of {where} is {relative:.2g} times its largest magnitude over the run "
                     f"(largest error {acc['error_estimate']:.2g}{unit}, in {acc['error_estimate_coordinate']}, at "
                     f"t = {acc['error_estimate_time']:.6g}): the step dt = {s.dt:g} sets the accuracy of a fixed-step "
                     "method; a shorter dt reduces it (as dt^order)")
    if acc.get("error_estimate") is not None and ratio is not None and ratio > WARN_FACTOR and not chosen_step:
        parts.append(f"the estimated error {acc['error_estimate']:.2g}{unit} (in {acc['error_estimate_coordinate']}, at "
                     f"t = {acc['error_estimate_time']:.6g}) is {ratio:.3g} times what rtol = {s.rtol:g} and "
                     f"atol = {s.atol:g} ask of it")
    drifted = [(k, v) for k, v in (acc.get("invariants") or {}).items() if v.get("warning")]
    for name, v in drifted:
        parts.append(f"{name} should stay constant but drifted by {v['relative']:.3g} (relative), "
                     f"{v['relative'] / s.rtol:.3g} times rtol")
    if not parts:
        acc.pop("warning", None)
        return None
    if chosen_step and not drifted:
        msg = "the results are less accurate than they may seem: " + "; ".join(parts)
    else:
        msg = ("the results are less accurate than the tolerance suggests: " + "; ".join(parts)
               + ". The tolerance bounds the error of each step; over a long or chaotic run the errors add up: "
                 "tighten rtol/atol (or shorten the run) until the estimate is what you need")
    acc["warning"] = msg
    r.metadata.setdefault("warnings", []).append(msg)
    return msg


def error_estimate(r: Result, tight: Result) -> dict:
    """Per recorded quantity: max |x - x_tight| over the common output points."""
    import numpy as np

    n = min(len(r.t), len(tight.t))
    out = {}
    if n == 0:
        return out
    for j, c in enumerate(r.coordinates):
        out[c] = float(np.abs(r.q[:n, j] - tight.q[:n, j]).max())
        out[f"der({c})"] = float(np.abs(r.qd[:n, j] - tight.qd[:n, j]).max())
    for name, v in r.signals.items():
        w = tight.signals.get(name)
        if isinstance(v, np.ndarray) and isinstance(w, np.ndarray) and v.ndim == 1 and w.ndim == 1 \
                and len(v) >= n and len(w) >= n:
            with np.errstate(invalid="ignore"):
                out[name] = float(np.nanmax(np.abs(v[:n] - w[:n]))) if n else 0.0
    return out
