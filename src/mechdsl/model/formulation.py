"""Which formulation a model compiles to, and why (``mech check`` prints this)."""
from __future__ import annotations

from . import exprs as X
from . import ir
from ..semantic.topology import counts

DEFAULT_DAE_FORMULATION = "projection"  # mechdsl.dae: index-1 ODE + projection onto both manifolds


ROUTE_TEXT = {
    "aba": "recursive articulated-body algorithm",
    "crba": "composite-rigid-body mass matrix and recursive Newton-Euler, solved by pivoting QR",
    "lagrange": "Lagrange's equations by automatic differentiation",
}


def recursive_ok(model: ir.Model) -> bool:
    """True when the recursive O(N) route applies: a tree of components whose joint variables are
    coordinates or functions of time, and no equation-layer kinetic terms."""
    if not model.bodies or any(t.kind == "kinetic" for t in model.terms):
        return False
    for j in model.joints:
        for v in j.variables:
            if v.coordinate is None and X.depends_on_state(v.motion):
                return False
    return True


def kind(model: ir.Model) -> str:
    """'ode' for trees without constraints, 'dae' otherwise."""
    return "ode" if not model.loops and not model.constraints else "dae"


def describe(model: ir.Model, route: str | None = None) -> str:
    """One line: counts and formulation.  ``route`` is the derived equations' route when known
    (mechanics decides it; without it the front end's estimate is shown)."""
    text = _describe(model, route)
    contacts = [k for k in model.contacts if k.kind != "fix"]
    fixes = [k for k in model.contacts if k.kind == "fix"]
    if contacts:
        text += (f"; {len(contacts)} unilateral contact{'s' * (len(contacts) != 1)} "
                 f"(event-driven impacts, Newton's restitution law)")
    if fixes:
        text += f"; {len(fixes)} fixation{'s' * (len(fixes) != 1)} (impulsive constraints)"
    return text


def _describe(model: ir.Model, route: str | None) -> str:
    c = counts(model)
    parts = []
    if c["bodies"]:
        parts.append(f"{c['bodies']} bod{'y' if c['bodies'] == 1 else 'ies'}")
    if c["joints"]:
        parts.append(f"{c['joints']} joint{'s' * (c['joints'] != 1)}")
    parts.append(f"{c['coordinates']} coordinate{'s' * (c['coordinates'] != 1)}")
    if kind(model) == "ode":
        topo = "tree" if model.bodies else "equation layer"
        if route is None:
            route = "aba" if recursive_ok(model) else ("lagrange" if not model.bodies else "crba")
        how = ROUTE_TEXT.get(route, route)
        return f"{model.name}: {', '.join(parts)}, {topo} -> ODE in minimal coordinates ({how})"
    why = []
    if model.loops:
        why.append(f"{len(model.loops)} loop{'s' * (len(model.loops) != 1)} "
                   f"(closed by {', '.join(lp.joint for lp in model.loops)})")
    if model.constraints:
        why.append(f"{len(model.constraints)} explicit constraint{'s' * (len(model.constraints) != 1)}")
    return (f"{model.name}: {', '.join(parts)}, {' and '.join(why)}, {c['constraints']} constraint equation{'s' * (c['constraints'] != 1)} "
            f"-> DAE with multipliers (index reduced; default formulation: {DEFAULT_DAE_FORMULATION})")
