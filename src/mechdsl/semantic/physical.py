"""Physical admissibility of the component values, with the parameter values in force.

``value_problems(model, env)`` is the entry: the mass properties (E508, E509, W509: inertia.py) and the
degenerate values (E510-E512) below, judged on the numbers of the parameter values given
(default: the model's).  It runs when the model is analyzed, when `with_params` / `--set`
change a parameter, and in the start check (``mechdsl.eom.preflight``) of every simulation.

A negative mass or an inertia tensor no rigid body can have (not symmetric, not positive
semidefinite; principal moments that break the triangle inequality beyond rounding, see
inertia.py) makes the equations of motion meaningless without making them fail: the integrator
runs happily on a negative kinetic energy. So they are model errors (E508, E509), found when the
model is analyzed and again when `with_params` / `--set` change a parameter.

Degenerate values make the numbers fail instead (nan at the first step, a singular matrix in
a solver, a run that never ends), so they are named here with their component:

  E510  a component value that is not finite (a mass 1e308 * 10, a length 1/(r - r))
  E511  a negative length, radius or size of a body, a shape or a contact
  E512  a direction that is the zero vector (joint, body or shape axis, contact normal)
"""
from __future__ import annotations

import math

import numpy as np

from ..model import exprs as X
from ..model import ir
from ..diagnostics import Diagnostic

def value_problems(model: ir.Model, env: dict[str, float] | None = None) -> list[Diagnostic]:
    """Every problem of the component values (E508-E512, and the warning W509), in declaration
    order per kind; ``errors`` keeps the errors."""
    from .inertia import mass_property_problems

    if env is None:
        env = parameter_env(model)
    found = degenerate_problems(model, env)
    bad = {d.span for d in found}         # a body with a non-finite mass is not judged again
    return found + [d for d in mass_property_problems(model, env) if d.span not in bad]


def errors(found: list[Diagnostic]) -> list[Diagnostic]:
    return [d for d in found if d.severity == "error"]


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
    """The diagnostics of values that make no physical sense once the parameters are known
    (E510 not finite, E511 negative lengths, E512 zero directions, E513 unresolvable ones)."""
    c = _Checks(env)
    c.bodies(model.bodies)
    c.shapes(getattr(model, "shapes", ()))
    for j in model.joints:
        if j.kind in ("revolute", "prismatic", "cylindrical", "planar"):
            c.zero_direction("the axis", f"joint '{j.name}'", j.axis, j.span)
    c.forces(model.forces)
    c.contacts(model.contacts)
    return c.out


class _Checks:
    """The checks of degenerate_problems, collecting their diagnostics in ``out``."""

    def __init__(self, env: dict[str, float]):
        self.env, self.out = env, []

    def not_finite(self, what: str, owner: str, values, span) -> bool:
        vals = [v for v in values if v is not None]
        if all(math.isfinite(v) for v in vals):
            return False
        shown = ", ".join(dict.fromkeys(f"{v:g}" for v in vals if not math.isfinite(v)))
        self.out.append(Diagnostic("E510", f"{what} of {owner} is not finite ({shown})", span,
                                   "check the parameter values it uses for overflow (a product of huge numbers) "
                                   "and division by zero"))
        return True

    def zero_direction(self, what: str, owner: str, vec, span) -> bool:
        # a parametric direction is stored normalized, c / sqrt(c . c): judge the numerators c
        vals = [_raw(_numerator(c), self.env) for c in vec]
        if any(v is None for v in vals):
            return False
        if self.not_finite(what, owner, vals, span):
            return True
        if all(v == 0 for v in vals):
            self.out.append(Diagnostic("E512", f"{what} of {owner} is the zero vector", span,
                                       "a direction needs a nonzero component, e.g. {0, 1, 0}; check the parameters "
                                       "it is built from"))
            return True
        sizes = [abs(v) for v in vals if v != 0]
        if min(sizes) < DIRECTION_SPAN * max(sizes):
            # {1e32, 0, 1}: the small component's square is below the rounding of the large one's,
            # so the direction is the large one to double precision while its tiny tilt still
            # makes a near-singular inertia (the falling rod's Planar joint ran for hours)
            self.out.append(Diagnostic("E513", f"the components of {what} of {owner} are more than "
                                               f"{1 / DIRECTION_SPAN:g} times apart (largest/smallest nonzero = "
                                               f"{max(sizes) / min(sizes):.3g}): the small ones are below what double "
                                               "precision resolves against the large ones", span,
                                       "set the tiny components to 0, or give the direction in numbers of "
                                       "comparable size"))
            return True
        return False

    def negative_lengths(self, kind: str, sizes, owner: str, span, hint: str) -> None:
        for name, e in zip(_LENGTHS.get(kind, ()), sizes):
            v = _raw(e, self.env)
            if v is None or self.not_finite(f"the {name}", owner, [v], span):
                continue
            if v < 0:
                self.out.append(Diagnostic("E511", f"the {name} of {owner} is negative ({v:g})", span, hint))

    def bodies(self, bodies) -> None:
        env = self.env
        for b in bodies:
            if b.kind not in ("point", "rigid"):
                continue
            owner = f"body '{b.name}'"
            if self.not_finite("the mass", owner, [_raw(b.mass, env)], b.span):
                continue
            if b.kind == "rigid":
                self.negative_lengths(b.shape, b.shape_size, owner, b.span,
                                      "lengths and radii are >= 0; reverse the body's axis instead of the sign of "
                                      "its length")
                if b.shape in ("rod", "disk", "cylinder") and self.zero_direction("the axis", owner, b.axis, b.span):
                    continue                       # (its inertia, built from the axis, says nothing more)
                self.not_finite("the inertia tensor", owner, [_raw(e, env) for row in b.inertia for e in row],
                                b.span)

    def shapes(self, shapes) -> None:
        for sh in shapes:
            owner = f"shape '{sh.name}'"
            self.negative_lengths(sh.kind, sh.size, owner, sh.span, "lengths and radii are >= 0")
            self.not_finite("the placement r", owner, [_raw(e, self.env) for e in sh.r], sh.span)
            if sh.kind in ("rod", "disk", "cylinder"):
                self.zero_direction("the axis", owner, sh.axis, sh.span)

    def forces(self, forces) -> None:
        for f in forces:
            if isinstance(f, ir.SpringDamper):
                self.not_finite("a coefficient (k, c, l0)", f"{f.kind} '{f.name}'",
                                [_raw(e, self.env) for e in (f.k, f.c, f.l0)], f.span)
                v = _raw(f.l0, self.env)
                if v is not None and math.isfinite(v) and v < 0:
                    self.out.append(Diagnostic("E511", f"the rest length l0 of {f.kind} '{f.name}' is negative "
                                                       f"({v:g})", f.span, "a rest length is a distance: >= 0"))

    def contacts(self, contacts) -> None:
        for c in contacts:
            owner = f"contact '{c.name}'"
            for key in ("radius", "surface_radius", "offset", "e"):
                e = c.get(key)
                if isinstance(e, ir.Expr):
                    v = _raw(e, self.env)
                    if v is None or self.not_finite(f"'{key}'", owner, [v], c.span):
                        continue
                    if key in ("radius", "surface_radius") and v < 0:
                        self.out.append(Diagnostic("E511", f"the {key.replace('_', ' ')} of {owner} is negative "
                                                           f"({v:g})", c.span, "a radius is >= 0"))
            normal = c.get("normal")
            if c.kind == "plane" and isinstance(normal, tuple):
                self.zero_direction("the normal", owner, normal, c.span)
