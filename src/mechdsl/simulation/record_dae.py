"""What a constrained run records besides q and q': outputs, drift, multipliers, reactions.

Signals (Result.signals), in this order:
- the model's outputs (EOM.outputs; vector outputs as name[1], ...), all or those named
- "kinetic_energy", "potential_energy", "energy" (as the ODE simulator records them)
- "residual(<constraint name>)" for every constraint
- "constraint_drift"  ||g(q, t)||_inf over all constraints (redundant ones included)
- "velocity_drift"    ||G q' + g_t||_inf
- only when asked (option ``reactions=True``, or named in ``outputs``):
  "lambda[<constraint name>]" for every constraint (0 for a dropped redundant one; explicit
  constraint equations report |dg/dq| lambda, the reaction along -grad g: eom.multiplier_scales), and
  reaction signals: entries of ``EOM.reactions`` (name -> SX in q, q', t, p and EOM.lam),
  and for constraint names of the form
  "<joint>.force[i]" / "<joint>.torque[i]" (the convention of cut joints, whose
  multipliers are the reaction components in the joint frame) the signal of that name.

The multipliers are computed from the consistent state at each output time (augmented
system at acceleration level), the same way for every formulation.
"""
from __future__ import annotations

import re

import numpy as np

from ..diagnostics import UsageError, did_you_mean
from ..eom import multiplier_scales
from . import record as R
from .record import lam_symbol  # noqa: F401  (the one multiplier symbol)


REACTION_NAME = re.compile(r"(.+)\.(force|torque)\[(\d)\]")



def depends_on(expr, sym) -> bool:
    import casadi as ca

    if sym is None or sym.numel() == 0:
        return False
    return bool(ca.depends_on(ca.SX(expr), sym))


def reaction_sources(eom) -> dict[str, object]:
    """name -> SX in (q, qd, t, p, lam) for every reaction/multiplier signal of the model."""
    lam = lam_symbol(eom)
    scale = multiplier_scales(eom)
    out = {}
    for i, name in enumerate(eom.constraint_names):
        out[f"lambda[{name}]"] = scale[i] * lam[i]
        if REACTION_NAME.fullmatch(name):
            out[name] = lam[i]
    for name, expr in (getattr(eom, "reactions", None) or {}).items():
        out[name] = expr
    return out


def _alias(eom, name: str) -> str:
    """`lambda[c<k>]` (the name of an explicit constraint before it was named after its
    description) -> `lambda[<name>]`."""
    m = re.fullmatch(r"lambda\[(c\d+)\]", name)
    if m and eom.model is not None:
        for c in eom.model.constraints:
            if c.alias == m.group(1):
                return f"lambda[{c.name}]"
    return name


def select_signals(eom, outputs, reactions: bool) -> tuple[dict, bool]:
    """The signal expressions to record and whether multipliers are needed.

    Declared outputs are recorded as in the ODE simulator (all of them, or those named);
    one that uses reactions (depends on EOM.lam) is itself the request to compute the
    multipliers.  The raw multipliers ("lambda[...]"), cut-joint reaction signals and
    EOM.reactions are recorded only with reactions=True or when named in ``outputs``."""
    lam = lam_symbol(eom)
    react = reaction_sources(eom)
    if outputs is None:
        chosen = dict(eom.outputs)
        if reactions:
            chosen.update({k: v for k, v in react.items() if k not in chosen})
    else:
        if isinstance(outputs, str):
            outputs = (outputs,)
        chosen = {}
        for name in outputs:
            name = _alias(eom, name)
            if name in eom.outputs:
                chosen[name] = eom.outputs[name]
            elif name in react:
                chosen[name] = react[name]
            elif (name in eom.coords or name.startswith("der(") or name.startswith("residual(")
                  or name in ("constraint_drift", "velocity_drift", "kinetic_energy", "potential_energy", "energy")):
                continue   # always recorded
            else:
                hint = did_you_mean(name, list(eom.outputs) + list(react) + list(eom.coords))
                raise UsageError(f"no output named {name!r} in model {eom.name}" + (f"; {hint}" if hint else ""))
        if reactions:
            chosen.update({k: v for k, v in react.items() if k not in chosen})
    need = any(depends_on(v, lam) for v in chosen.values())
    return chosen, need


def constrained_signals(eom, chosen: dict, t, Q, QD, LAM, p, drift=None) -> dict[str, np.ndarray]:
    """What a constrained run records, in this order: the chosen model outputs, energies and
    residuals, the drift (``drift`` = (D, VD) measured by the integrator, or None: evaluated
    at the recorded states), then the multipliers and reactions chosen.  One recorder call
    (simulation/record.py); LAM (N, m) the multipliers (None: not computed)."""
    plain = {k: v for k, v in chosen.items() if k in eom.outputs}
    rest = {k: v for k, v in chosen.items() if k not in plain}
    cols = R.merged(plain, R.energies(eom), R.residuals(eom), {} if drift is not None else R.drift(eom), rest)
    sig = R.record(eom, cols, t, Q, QD, p, LAM=LAM)
    if drift is None:
        return sig
    out = {k: sig[k] for k in sig if k not in _names(eom, rest)}
    out["constraint_drift"] = np.asarray(drift[0], float)
    out["velocity_drift"] = np.asarray(drift[1], float)
    out.update({k: sig[k] for k in sig if k not in out})
    return out


def multipliers(system, t, Q, QD) -> np.ndarray:
    """The multipliers (N, m) at the recorded states, from the augmented system at
    acceleration level (0 for a constraint outside the active set)."""
    LAM = np.zeros((len(t), system.eom.m))
    for i in range(len(t)):
        _, lam = system.accel(Q[i], QD[i], t[i])
        LAM[i, list(system.active)] = lam
    return LAM


def _names(eom, cols: dict) -> set:
    """The signal names of these columns (vector columns expand to name[i])."""
    import casadi as ca

    out = set()
    for k, v in cols.items():
        k_n = int(ca.SX(v).numel())
        out |= {k} if k_n == 1 else {f"{k}[{i + 1}]" for i in range(k_n)}
    return out
