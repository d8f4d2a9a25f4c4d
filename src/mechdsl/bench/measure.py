"""Error norms against a reference and the drift of invariants, from a Result.

Errors are relative, component by component: the difference in component i is divided by
the size of that component in the reference, s_i = max over the reference times of |r_i|
(1 when the component is zero throughout).

    final error  = max_i |y_i(T) - r_i(T)| / s_i
    L2 error     = sqrt(mean over reference times t and components i of ((y_i(t) - r_i(t)) / s_i)^2)

Invariants (docs/internals/bench.md): the energy (relative drift, only when the model is
conservative), every first integral the simulator records (Result.stats
["first_integral_drift"], absolute), quaternion norms and constraint residuals
(max |value| over the run, absolute).
"""
from __future__ import annotations

import numpy as np


def component_scales(ref_values: dict[str, np.ndarray], columns) -> np.ndarray:
    s = np.array([float(np.max(np.abs(ref_values[c]))) if len(ref_values[c]) else 0.0 for c in columns])
    s[~(s > 0)] = 1.0
    return s


def extract(result, columns, rows: np.ndarray) -> np.ndarray:
    """Values of ``columns`` at the grid indices ``rows`` (n_rows, n_columns)."""
    return np.column_stack([np.asarray(result[c], float)[rows] for c in columns])


def errors(Y: np.ndarray, R: np.ndarray, scales: np.ndarray) -> dict[str, float]:
    """Relative final-time and L2 errors of Y against R (both (n_rows, n_columns))."""
    D = (Y - R) / scales[None, :]
    if not np.isfinite(D).all():
        return {"final": float("inf"), "l2": float("inf")}
    return {"final": float(np.max(np.abs(D[-1]))), "l2": float(np.sqrt(np.mean(D ** 2)))}


def invariants(result, conservative=None) -> dict[str, float]:
    """Drift measures of one run, by name (see the module docstring).  conservative: whether
    the energy is an invariant (default: the run's metadata says)."""
    out: dict[str, float] = {}
    st = result.stats or {}
    if conservative is None:
        conservative = (result.metadata or {}).get("conservative")
    if conservative:
        e = st.get("energy_drift_relative")
        if e is None:
            e = energy_drift_relative(result.signals)
        if e is not None:
            out["energy"] = float(e)
    for name, v in (st.get("first_integral_drift") or {}).items():
        if name != "energy":
            out[f"drift({name})"] = float(v)
    res = [k for k in result.signals if k.startswith("residual(")]
    if res:
        out["residual"] = max(_maxabs(result.signals[k]) for k in res)
    for k in result.signals:
        if k.endswith("quaternion_norm"):
            out[k] = _maxabs(result.signals[k])
    return out


def energy_drift_relative(signals) -> float | None:
    """max |E - E(0)| / max(|E(0)|, max T, max |V|) (as mechdsl.simulate records it), for
    results whose stats lack it."""
    E = signals.get("energy")
    if E is None or len(E) == 0 or not np.isfinite(E).all():
        return None
    scale = max(abs(float(E[0])), _maxabs(signals.get("kinetic_energy", [])), _maxabs(signals.get("potential_energy", [])),
                1e-300)
    return float(np.abs(E - E[0]).max()) / scale


def _maxabs(v) -> float:
    v = np.asarray(v, float)
    return float(np.max(np.abs(v))) if v.size else 0.0


def main_invariant(inv: dict[str, float]) -> tuple[str, float] | None:
    """The one drift shown in the printed table and the chart: constraint residual for
    constrained models, else the energy, else the largest first-integral drift."""
    for key in ("residual", "energy"):
        if key in inv:
            return key, inv[key]
    rest = [(k, v) for k, v in inv.items() if k.startswith("drift(")]
    if rest:
        return max(rest, key=lambda kv: kv[1])
    return None
