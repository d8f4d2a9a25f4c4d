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

REACTION_NAME = re.compile(r"(.+)\.(force|torque)\[(\d)\]")


def lam_symbol(eom):
    """The EOM's multiplier symbol (created and stored on the EOM when it has none)."""
    import casadi as ca

    if getattr(eom, "lam", None) is None:
        eom.lam = ca.SX.sym("lam", eom.m)
    return eom.lam


def depends_on(expr, sym) -> bool:
    import casadi as ca

    if sym is None or sym.numel() == 0:
        return False
    return bool(ca.depends_on(ca.SX(expr), sym))


def reaction_sources(eom) -> dict[str, object]:
    """name -> SX in (q, qd, t, p, lam) for every reaction/multiplier signal of the model."""
    from ..eom import multiplier_scales

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


def evaluate_signals(eom, chosen: dict, t, Q, QD, LAM, p) -> dict[str, np.ndarray]:
    """Values of the chosen signals at the recorded states; a vector-valued output `v` becomes
    the signals v[1], v[2], ... (1-based, as the ODE simulator names them)."""
    import casadi as ca

    if not chosen:
        return {}
    def build():
        lam = lam_symbol(eom)
        names, exprs = [], []
        for k, v in chosen.items():
            v = ca.SX(v)
            if v.numel() == 1:
                names.append(k)
            else:
                names += [f"{k}[{i + 1}]" for i in range(v.numel())]
            exprs.append(ca.vec(v))
        return names, ca.Function("signals", [eom.q, eom.qd, eom.t, eom.p, lam], [ca.vertcat(*exprs)])

    # the signals of a name are the same expressions on every run of this EOM
    names, F = eom.cached(("signals", tuple(chosen)), build)
    N = len(t)
    if N == 0:
        return {k: np.zeros(0) for k in names}
    P = np.repeat(np.asarray(p, float).reshape(-1, 1), N, axis=1)
    L = LAM.T if LAM is not None and LAM.size else np.zeros((eom.m, N))
    vals = np.array(F.map(N)(Q.T, QD.T, np.asarray(t).reshape(1, -1), P, L), float).reshape(len(names), N)
    return {k: vals[i] for i, k in enumerate(names)}


def standard_signals(eom) -> dict[str, object]:
    """Energies and constraint residuals, recorded in every run."""
    return dict(eom.cached("standard_signals", lambda: _standard_signals(eom)))


def _standard_signals(eom) -> dict[str, object]:
    import casadi as ca

    out = {"kinetic_energy": eom.T, "potential_energy": eom.V, "energy": eom.T + eom.V}
    for i, name in enumerate(eom.constraint_names):
        out[f"residual({name})"] = ca.SX(eom.g)[i]
    return out
