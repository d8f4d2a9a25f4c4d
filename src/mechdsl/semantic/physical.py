"""Physical admissibility of the mass properties, with the parameter values in force.

A negative mass or an inertia tensor no rigid body can have (not symmetric, a negative
principal moment, principal moments that break the triangle inequality I_a + I_b >= I_c)
makes the equations of motion meaningless without making them fail: the integrator runs
happily on a negative kinetic energy. So they are model errors (E508, E509), found when the
model is analyzed and again when `with_params` / `--set` change a parameter.
"""
from __future__ import annotations

import math

import numpy as np

from .. import exprs as X
from .. import ir
from ..diagnostics import Diagnostic

REL_TOL = 1e-9


def _number(e: ir.Expr, env: dict[str, float]) -> float | None:
    """The value of a constant expression, None when it depends on the state or time."""
    if X.depends_on_state(e) or X.depends_on_time(e):
        return None
    try:
        v = X.evaluate(e, env)
    except Exception:  # noqa: BLE001 - an expression we cannot judge here is judged by the numerics
        return None
    return v if math.isfinite(v) else None


def mass_property_problems(model: ir.Model) -> list[Diagnostic]:
    env = {p.name: p.value for p in model.parameters if p.value is not None}
    out: list[Diagnostic] = []
    for b in model.bodies:
        if b.kind not in ("point", "rigid"):
            continue
        m = _number(b.mass, env)
        if m is not None and m < 0:
            out.append(Diagnostic("E508", f"body '{b.name}' has a negative mass ({m:g})", b.span,
                                  "masses are positive; check the sign of its `m` and the parameters it uses"))
            continue
        if b.kind != "rigid":
            continue
        values = [[_number(e, env) for e in row] for row in b.inertia]
        if any(v is None for row in values for v in row):
            continue
        inertia = np.array(values, dtype=float)
        scale = max(float(np.max(np.abs(inertia))), 1e-300)
        if np.max(np.abs(inertia - inertia.T)) > REL_TOL * scale:
            out.append(Diagnostic("E509", f"the inertia tensor of body '{b.name}' is not symmetric", b.span,
                                  "I must equal its transpose: give I_21, I_31, I_32 once (or a symmetric I)"))
            continue
        moments = np.sort(np.linalg.eigvalsh(inertia))
        shown = ", ".join(f"{x:.6g}" for x in moments)
        if moments[0] < -REL_TOL * scale:
            out.append(Diagnostic("E509", f"the inertia tensor of body '{b.name}' has a negative principal moment "
                                          f"(principal moments {shown})", b.span,
                                  "moments of inertia are >= 0; check signs (products of inertia enter I with "
                                  "their sign as written)"))
        elif moments[0] + moments[1] < moments[2] - REL_TOL * scale:
            out.append(Diagnostic("E509", f"no rigid body has the inertia tensor of '{b.name}': its principal "
                                          f"moments ({shown}) break the triangle inequality I1 + I2 >= I3", b.span,
                                  "for any mass distribution each principal moment is at most the sum of the "
                                  "other two; check the values (a thin disk: I3 = I1 + I2)"))
    return out
