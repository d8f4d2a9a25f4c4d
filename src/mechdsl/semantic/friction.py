"""The `Friction` component lowered to a generalized force (issue 17)."""
from __future__ import annotations

from ..model import exprs as X
from ..model import ir
from ..model import units as U
from . import components as K
from .evaluate import fail


def friction_force(flat, name: str, f, span) -> ir.GeneralizedForce:
    """Regularized Coulomb friction: Q = -F tanh(der(q) / v_eps) (docs/language.md#friction);
    ``flat`` is the Flattener (for its unit checks), ``f`` the component's field values."""
    c = f["coordinate"]
    coord = c.expr.name
    F, v_eps = f["F"], f.get("v_eps")
    if isinstance(c.dim, U.Dim):
        flat.check_dim(F, U.ENERGY / c.dim, f"'F' of '{name}'", span)
        if v_eps is not None:
            flat.check_dim(v_eps, c.dim / U.TIME, f"'v_eps' of '{name}'", span)
    eps = K.as_expr(v_eps, "v_eps") if v_eps is not None else X.const(1e-3)
    if X.is_const(eps) and not eps.value > 0:
        fail("E241", f"the regularization speed v_eps of '{name}' must be positive, got {eps.value:g}", span,
             "v_eps > 0: friction is -F tanh(v / v_eps); a smaller v_eps is closer to dry friction, stiffer")
    Q = X.neg(X.mul(K.as_expr(F, "F"), X.func("tanh", X.div(ir.Speed(coord), eps))))
    return ir.GeneralizedForce(name, coord, Q, span, note=f"Coulomb friction on {coord}: -F tanh(der({coord})/v_eps)",
                               regularization=eps)
