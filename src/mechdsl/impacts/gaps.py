"""Gap functions of unilateral contacts: gap(q, t, p) >= 0 is the allowed side.

One :class:`ContactGap` per contact, built from an ``ir.Contact`` (or written by hand in
CasADi SX for tests and the Python API).  Geometry (``point`` P with a sphere of radius r
around it; x_P its world position from ``EOM.point_position``):

    plane              gap = n . x_P - offset - r                (n = normal / |normal|)
    sphere, outside    gap = |x_P - x_C| - (R + r)              (C = center point, R = surface_radius)
    sphere, inside     gap = (R - r) - |x_P - x_C|
    point              gap = |x_P - x_C| - (r + R)              (another body's point or sphere)
    gap                gap = the expression given (equation-layer models without points)

Its Jacobian G = dgap/dq (a row) and the normal speed u = G q' + dgap/dt follow by
automatic differentiation in :mod:`mechdsl.impacts.contact_system`.
"""
from __future__ import annotations

from dataclasses import dataclass

from ..diagnostics import Diagnostic, MechError
from ..model import exprs as X
from ..model import ir


SURFACES = ("plane", "sphere", "point", "gap")


@dataclass(frozen=True, kw_only=True)
class ContactGap:
    """A unilateral contact ready for simulation.

    gap: CasADi SX scalar in the EOM's symbols q, t, p (not qd); e: restitution, a number
    or an SX in p.  ``points`` names the points involved (for reports).
    """

    name: str
    gap: object
    e: object = 1.0
    kind: str = "gap"
    points: tuple[str, ...] = ()
    span: object = None
    # sliding friction while closed (issue 17): the generalized force per unit normal force,
    # -mu J' v_t tanh(|v_t|/v_eps)/|v_t| (SX (n,) in q, qd, t, p), or None without friction
    friction: object = None
    v_eps: float = 0.0


@dataclass(frozen=True, kw_only=True)
class Fixation:
    """An impulsive constraint: at ``time`` the point ``point`` is suddenly fixed in space.

    From then on the point keeps the position it had at ``time`` (a bilateral constraint);
    the velocity jump follows from Lagrange's impact equations with e = 0.
    """

    point: str
    time: float
    name: str = ""
    span: object = None

    @property
    def label(self) -> str:
        return self.name or f"fix({self.point})"


def contact_gaps(eom, contacts=None) -> tuple[list[ContactGap], list[Fixation]]:
    """Split ``contacts`` (default ``eom.model.contacts``) into gaps and fixations.

    Entries may be ``ir.Contact`` (from a .mech file), :class:`ContactGap` or
    :class:`Fixation`.
    """
    if contacts is None:
        contacts = eom.model.contacts if eom.model is not None else ()
    gaps: list[ContactGap] = []
    fixes: list[Fixation] = []
    for c in contacts:
        if isinstance(c, ContactGap):
            gaps.append(c)
        elif isinstance(c, Fixation):
            fixes.append(c)
        elif isinstance(c, ir.Contact):
            if c.kind == "fix":
                fixes.append(fixation_from_ir(eom, c))
            else:
                gaps.append(gap_from_ir(eom, c))
        else:
            raise TypeError(f"not a contact: {c!r}")
    names = [g.name for g in gaps] + [f.label for f in fixes]
    dup = sorted({n for n in names if names.count(n) > 1})
    if dup:
        raise MechError(Diagnostic("E862", f"contact name '{dup[0]}' is used twice"))
    return gaps, fixes


# ----------------------------------------------------------------------------- from the IR


def _env(eom):
    return X.CasadiEnv(tuple(eom.coords), tuple(eom.params), eom.q, eom.qd, eom.t, eom.p, _query(eom))


def _query(eom):
    def query(n):
        if isinstance(n, ir.PointPos):
            return point_position(eom, n.point)[n.i]
        raise ValueError(f"{X.to_text(n)} cannot appear in a contact (positions only)")

    return query


def point_position(eom, name: str):
    if eom.point_position is None:
        raise MechError(Diagnostic("E862", f"the equations of '{eom.name}' carry no point kinematics, so a contact "
                                           f"cannot refer to the point '{name}'",
                                   help="give the contact a gap expression instead: Contact c(gap = ..., e = ...)"))
    return eom.point_position(name)


def _value(c: ir.Contact, key: str, default=None):
    v = c.get(key, default)
    return default if v is None else v


def gap_from_ir(eom, c: ir.Contact) -> ContactGap:
    import casadi as ca

    env = _env(eom)
    tr = lambda e: env.translate(e) if isinstance(e, ir.Expr) else ca.SX(float(e))  # noqa: E731
    surface = _value(c, "surface", c.kind)
    e = tr(_value(c, "e", 1.0))
    span = c.span
    if c.get("gap") is not None:
        expr = c.get("gap")
        if X.has_speed(expr):
            raise MechError(Diagnostic("E862", f"the gap of contact '{c.name}' may depend on coordinates and time, "
                                               "not on speeds", span))
        if _has_friction(c):
            raise MechError(Diagnostic("E862", f"contact '{c.name}' has friction (mu) but a gap expression: "
                                               "friction needs the contact's point", span,
                                       "give the contact a point and a surface, or put the friction on a "
                                       "coordinate with Friction(...)"))
        return ContactGap(name=c.name, gap=tr(expr), e=e, kind="gap", span=span)
    if surface not in SURFACES:
        raise MechError(Diagnostic("E862", f"contact '{c.name}': unknown surface '{surface}'", span,
                                   "surfaces: " + ", ".join(SURFACES)))
    point = _value(c, "point")
    if point is None:
        raise MechError(Diagnostic("E862", f"contact '{c.name}' needs a point (or a gap expression)", span))
    xp = point_position(eom, point)
    r = tr(_value(c, "radius", 0.0))
    if surface == "plane":
        n = ca.vertcat(*[tr(x) for x in _value(c, "normal", (ir.ZERO, ir.ONE, ir.ZERO))])
        n = n / ca.norm_2(n)
        gap = ca.dot(n, xp) - tr(_value(c, "offset", 0.0)) - r
        return ContactGap(name=c.name, gap=gap, e=e, kind="plane", points=(point,), span=span,
                          **_friction(eom, c, tr, n, point, None))
    center = _value(c, "center", "world")
    xc = point_position(eom, center)
    R = tr(_value(c, "surface_radius", 0.0))
    dist = ca.norm_2(xp - xc)
    inside = _value(c, "inside", 0.0)
    inside = X.evaluate(inside, param_env(eom)) if isinstance(inside, ir.Expr) else float(inside)
    if surface == "sphere" and inside:
        gap = (R - r) - dist
    else:
        gap = dist - (R + r)
    return ContactGap(name=c.name, gap=gap, e=e, kind=surface, points=(point, center), span=span,
                      **_friction(eom, c, tr, (xp - xc) / dist, point, center))


def _has_friction(c: ir.Contact) -> bool:
    mu = _value(c, "mu", 0.0)
    return not X.is_const(mu, 0.0) if isinstance(mu, ir.Expr) else float(mu) != 0.0


def _friction(eom, c: ir.Contact, tr, n, point: str, center: str | None) -> dict:
    """Regularized Coulomb friction of a persistent contact (fields mu, v_eps): the slip velocity
    v_t is the tangential part of the velocity of `point` relative to `center` (a sphere's
    rotation is not included: the contact point is taken to move with the point), and the force
    on the point is -mu N v_t tanh(|v_t|/v_eps)/|v_t| (N the normal force), the opposite on the
    center; returned per unit N as a generalized force."""
    import casadi as ca

    if not _has_friction(c):
        return {}
    mu = _value(c, "mu", 0.0)
    if eom.point_velocity is None:
        raise MechError(Diagnostic("E862", f"contact '{c.name}' has friction, which needs the point kinematics",
                                   c.span))
    mu, v_eps = tr(mu), tr(_value(c, "v_eps", 1e-3))
    eps_num = X.evaluate(_value(c, "v_eps", 1e-3), param_env(eom)) if isinstance(_value(c, "v_eps", 1e-3), ir.Expr) \
        else float(_value(c, "v_eps", 1e-3))
    if not eps_num > 0:
        raise MechError(Diagnostic("E862", f"the friction regularization speed v_eps of contact '{c.name}' must be "
                                           f"positive, got {eps_num:g}", c.span))
    v = eom.point_velocity(point)
    J = ca.jacobian(point_position(eom, point), eom.q)
    if center is not None and center != "world":
        v = v - eom.point_velocity(center)
        J = J - ca.jacobian(point_position(eom, center), eom.q)
    vt = v - n * ca.dot(n, v)
    s = ca.sqrt(ca.dot(vt, vt) + (1e-9 * v_eps) ** 2)
    force = -mu * vt * ca.tanh(s / v_eps) / s          # per unit normal force, world axes
    return {"friction": ca.mtimes(J.T, force), "v_eps": eps_num}


def fixation_from_ir(eom, c: ir.Contact) -> Fixation:
    t = c.get("time")
    if isinstance(t, ir.Expr):
        t = X.evaluate(t, param_env(eom))
    return Fixation(point=c.get("point"), time=float(t), name=c.name, span=c.span)


def param_env(eom) -> dict[str, float]:
    """Numeric parameter values by name (the EOM's vector p, plus Integer parameters)."""
    env = {p.name: p.value for p in eom.model.parameters} if eom.model is not None else {}
    env.update({n: float(v) for n, v in zip(eom.params, eom.param_values)})
    return env


def gap_jacobian(eom, contact: ContactGap):
    """G = d(gap)/dq (a 1 x n row) and the normal speed u = G q' + d(gap)/dt, as SX in q, qd, t, p."""
    import casadi as ca

    g = ca.SX(contact.gap)
    G = ca.jacobian(g, eom.q)
    return G, ca.mtimes(G, eom.qd) + ca.jacobian(g, eom.t)
