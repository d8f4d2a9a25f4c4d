"""Physical admissibility of the component values, with the parameter values in force.

``value_problems(model, env)`` is the entry: the mass properties (E508, E509) and the
degenerate values (E510-E512) below, judged on the numbers of the parameter values given
(default: the model's).  It runs when the model is analyzed, when `with_params` / `--set`
change a parameter, and in the start check (``mechdsl.eom.preflight``) of every simulation.

A negative mass or an inertia tensor no rigid body can have (not symmetric, a negative
principal moment, principal moments that break the triangle inequality I_a + I_b >= I_c)
makes the equations of motion meaningless without making them fail: the integrator runs
happily on a negative kinetic energy. So they are model errors (E508, E509), found when the
model is analyzed and again when `with_params` / `--set` change a parameter.

Degenerate values make the numbers fail instead (nan at the first step, a singular matrix in
a solver, a run that never ends), so they are named here with their component:

  E510  a component value that is not finite (a mass 1e308 * 10, a length 1/(r - r))
  E511  a negative length, radius or size of a body or a contact
  E512  a direction that is the zero vector (joint or body axis, contact normal)
"""
from __future__ import annotations

import math

import numpy as np

from ..model import exprs as X
from ..model import ir
from ..diagnostics import Diagnostic

REL_TOL = 1e-9


def _number(e: ir.Expr, env: dict[str, float]) -> float | None:
    """The value of a constant expression, None when it depends on the state or time."""
    if X.depends_on_state(e) or X.depends_on_time(e):
        return None
    try:
        with np.errstate(all="ignore"):
            v = X.evaluate(e, env)
    except Exception:  # noqa: BLE001 - an expression we cannot judge here is judged by the numerics
        return None
    return v if math.isfinite(v) else None


def value_problems(model: ir.Model, env: dict[str, float] | None = None) -> list[Diagnostic]:
    """Every problem of the component values (E508-E512), in declaration order per kind."""
    if env is None:
        env = parameter_env(model)
    found = degenerate_problems(model, env)
    bad = {d.span for d in found}         # a body with a non-finite mass is not judged again
    return found + [d for d in mass_property_problems(model, env) if d.span not in bad]


def parameter_env(model: ir.Model) -> dict[str, float]:
    return {p.name: p.value for p in model.parameters if p.value is not None}


def _raw(e: ir.Expr, env: dict[str, float]) -> float | None:
    """The value of a constant expression (inf and nan included), None when it depends on the
    state or time or cannot be evaluated here."""
    if X.depends_on_state(e) or X.depends_on_time(e):
        return None
    try:
        with np.errstate(all="ignore"):
            return float(X.evaluate(e, env))
    except ZeroDivisionError:
        return math.nan
    except OverflowError:
        return math.inf
    except Exception:  # noqa: BLE001 - an expression we cannot judge here is judged by the numerics
        return None


def _numerator(e: ir.Expr) -> ir.Expr:
    """c for a normalized component c / sqrt(...) (components.normalized), else e itself."""
    if isinstance(e, ir.Op) and e.op == "div" and isinstance(e.args[1], ir.Op) and e.args[1].op == "sqrt":
        return e.args[0]
    return e


DIRECTION_SPAN = 1e-8      # least ratio of a direction's nonzero components: ~ sqrt(machine epsilon)

_LENGTHS = {"rod": ("length L",), "disk": ("radius R",), "cylinder": ("radius R", "length L"),
            "sphere": ("radius R",), "box": ("size[1]", "size[2]", "size[3]")}


def degenerate_problems(model: ir.Model, env: dict[str, float]) -> list[Diagnostic]:
    out: list[Diagnostic] = []

    def not_finite(what: str, owner: str, values, span) -> bool:
        vals = [v for v in values if v is not None]
        if all(math.isfinite(v) for v in vals):
            return False
        shown = ", ".join(dict.fromkeys(f"{v:g}" for v in vals if not math.isfinite(v)))
        out.append(Diagnostic("E510", f"{what} of {owner} is not finite ({shown})", span,
                              "check the parameter values it uses for overflow (a product of huge numbers) "
                              "and division by zero"))
        return True

    def zero_direction(what: str, owner: str, vec, span) -> bool:
        # a parametric direction is stored normalized, c / sqrt(c . c): judge the numerators c
        vals = [_raw(_numerator(c), env) for c in vec]
        if any(v is None for v in vals):
            return False
        if not_finite(what, owner, vals, span):
            return True
        if all(v == 0 for v in vals):
            out.append(Diagnostic("E512", f"{what} of {owner} is the zero vector", span,
                                  "a direction needs a nonzero component, e.g. {0, 1, 0}; check the parameters "
                                  "it is built from"))
            return True
        sizes = [abs(v) for v in vals if v != 0]
        if min(sizes) < DIRECTION_SPAN * max(sizes):
            # {1e32, 0, 1}: the small component's square is below the rounding of the large one's,
            # so the direction is the large one to double precision while its tiny tilt still
            # makes a near-singular inertia (the falling rod's Planar joint ran for hours)
            out.append(Diagnostic("E513", f"the components of {what} of {owner} are more than "
                                          f"{1 / DIRECTION_SPAN:g} times apart (largest/smallest nonzero = "
                                          f"{max(sizes) / min(sizes):.3g}): the small ones are below what double "
                                          "precision resolves against the large ones", span,
                                  "set the tiny components to 0, or give the direction in numbers of comparable "
                                  "size"))
            return True
        return False

    for b in model.bodies:
        if b.kind not in ("point", "rigid"):
            continue
        owner = f"body '{b.name}'"
        if not_finite("the mass", owner, [_raw(b.mass, env)], b.span):
            continue
        if b.kind == "rigid":
            for name, e in zip(_LENGTHS.get(b.shape, ()), b.shape_size):
                v = _raw(e, env)
                if v is None or not_finite(f"the {name}", owner, [v], b.span):
                    continue
                if v < 0:
                    out.append(Diagnostic("E511", f"the {name} of {owner} is negative ({v:g})", b.span,
                                          "lengths and radii are >= 0; reverse the body's axis instead of "
                                          "the sign of its length"))
            if b.shape in ("rod", "disk", "cylinder") and zero_direction("the axis", owner, b.axis, b.span):
                continue                       # (its inertia, built from the axis, says nothing more)
            not_finite("the inertia tensor", owner, [_raw(e, env) for row in b.inertia for e in row], b.span)
    for j in model.joints:
        if j.kind in ("revolute", "prismatic", "cylindrical", "planar"):
            zero_direction("the axis", f"joint '{j.name}'", j.axis, j.span)
    for f in model.forces:
        if isinstance(f, ir.SpringDamper):
            not_finite("a coefficient (k, c, l0)", f"{f.kind} '{f.name}'",
                       [_raw(e, env) for e in (f.k, f.c, f.l0)], f.span)
            v = _raw(f.l0, env)
            if v is not None and math.isfinite(v) and v < 0:
                out.append(Diagnostic("E511", f"the rest length l0 of {f.kind} '{f.name}' is negative ({v:g})",
                                      f.span, "a rest length is a distance: >= 0"))
    for c in model.contacts:
        owner = f"contact '{c.name}'"
        for key in ("radius", "surface_radius", "offset", "e"):
            e = c.get(key)
            if isinstance(e, ir.Expr):
                v = _raw(e, env)
                if v is None or not_finite(f"'{key}'", owner, [v], c.span):
                    continue
                if key in ("radius", "surface_radius") and v < 0:
                    out.append(Diagnostic("E511", f"the {key.replace('_', ' ')} of {owner} is negative ({v:g})",
                                          c.span, "a radius is >= 0"))
        normal = c.get("normal")
        if c.kind == "plane" and isinstance(normal, tuple):
            zero_direction("the normal", owner, normal, c.span)
    return out


def mass_property_problems(model: ir.Model, env: dict[str, float] | None = None) -> list[Diagnostic]:
    if env is None:
        env = parameter_env(model)
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
