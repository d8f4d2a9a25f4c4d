"""The start vector of a run: the model's start values with overrides, one builder.

``state_key`` turns a start-value key (``"theta"`` or ``"der(theta)"``, read by
``model.names.split_state``) into its index in [q; qd];
``start_vector`` applies overrides (a full [q; qd] vector or {key: value}) to the model's
start values; ``parameter_vector`` (mechdsl.eom) does the same for parameters.
``fixed_start`` adds what a constrained run's consistent initialization needs: which
start values are fixed (the model's ``fixed`` attributes, and every overridden value).
"""
from __future__ import annotations

import numpy as np

from ..diagnostics import UsageError, did_you_mean
from ..model.names import split_state

__all__ = ["state_key", "start_vector", "fixed_start"]


def state_key(eom, key: str) -> int:
    """Index in [q; qd] of a start-value key: a coordinate name or ``der(name)``."""
    name, speed = split_state(key)
    if name not in eom.coords:
        hint = did_you_mean(name, list(eom.coords))
        raise UsageError(f"'{name}' is not a coordinate of {eom.name}" + (f"; {hint}" if hint else ""))
    return list(eom.coords).index(name) + (eom.n if speed else 0)


def start_vector(eom, x0, pv) -> np.ndarray:
    """[q0; qd0] of the model at parameters ``pv`` with the overrides ``x0`` applied."""
    n = eom.n
    q0, qd0 = eom.start(pv)
    base = np.r_[np.asarray(q0, float).ravel(), np.asarray(qd0, float).ravel()]
    if x0 is None:
        out = base
    elif isinstance(x0, dict):
        out = base.copy()
        for k, v in x0.items():
            out[state_key(eom, str(k))] = float(v)
    else:
        out = np.array(x0, float).ravel()
        if out.size != 2 * n:
            raise UsageError(f"x0 has {out.size} entries; expected {2 * n} (coordinates then their speeds)")
    if not np.isfinite(out).all():
        names = list(eom.coords) + [f"der({c})" for c in eom.coords]
        bad = [names[i] for i in np.flatnonzero(~np.isfinite(out))]
        raise UsageError(f"start values are not finite: {', '.join(bad)}")
    return out


def fixed_start(eom, x0, pv) -> tuple[np.ndarray, np.ndarray, tuple[bool, ...], tuple[bool, ...]]:
    """(q0, qd0, fixed_q, fixed_qd): ``start_vector`` split, with the fixed flags of the
    model's start values; a value overridden by name counts as fixed (a full vector keeps
    the model's flags)."""
    n = eom.n
    x = start_vector(eom, x0, pv)
    fq = list(eom.fixed_q) if len(eom.fixed_q) == n else [True] * n
    fqd = list(eom.fixed_qd) if len(eom.fixed_qd) == n else [True] * n
    if isinstance(x0, dict):
        for k in x0:
            i = state_key(eom, str(k))
            (fqd if i >= n else fq)[i % n] = True
    return x[:n].copy(), x[n:].copy(), tuple(fq), tuple(fqd)
