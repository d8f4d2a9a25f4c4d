"""Mass properties a rigid body can have (E508, E509, W509), judged with the parameter values in
force (``physical.value_problems`` calls :func:`mass_property_problems`).

What is refused, and why (docs/language.md, "Inertia data"):

- a negative mass (E508) and an inertia tensor that is not symmetric or not positive
  semidefinite (a negative principal moment, E509): some motion would have a negative kinetic
  energy, so the equations of motion are meaningless although the integrator runs happily;
- principal moments that break the triangle inequality I1 + I2 >= I3 (no mass distribution has
  them) by more than ``ROUNDING`` = 1e-6 of I3 (E509, with a hint); up to that much it is the
  rounding of printed data (URDF files, CAD exports): accepted with a located warning that gives
  the amount (W509); below ``NOISE`` = 1e-12 of I3 silently (floating-point noise).  Where the
  mass's own moment about the body origin, m |r_cm|^2, is larger than I3 it is the reference
  instead (a tensor of 1e-20 on a 1 kg link is zero up to noise, whatever its shape);
- the triangle inequality is not judged for a body marked ``measured_inertia = true`` (measured
  data: the user takes responsibility), nor where it cannot matter: a body that turns about one
  fixed axis of its own only (a "planar" body, such as sympy's planar ``inertia(B, 0, 0, Izz)``
  on a hinge) feels only the moment about that axis, and a body that never turns feels none
  (:func:`turning_axes` decides this from the joints between the body and the world).
"""
from __future__ import annotations

import math

import numpy as np

from ..diagnostics import Diagnostic
from ..model import exprs as X
from ..model import ir

SYMMETRY_TOL = 1e-9       # relative to the largest entry
NEGATIVE_TOL = 1e-9       # a principal moment below -NEGATIVE_TOL * largest is negative
NOISE = 1e-12             # triangle excess below this (relative to I3): floating-point noise
ROUNDING = 1e-6           # up to this: rounding of the data, a warning
PARALLEL_TOL = 1e-9

ANY = "any"               # turning_axes: the body may turn about any axis


def _number(e: ir.Expr, env: dict[str, float]) -> float | None:
    if X.depends_on_state(e) or X.depends_on_time(e):
        return None
    try:
        with np.errstate(all="ignore"):
            v = X.evaluate(e, env)
    except Exception:  # noqa: BLE001 - an expression we cannot judge here is judged by the numerics
        return None
    return v if math.isfinite(v) else None


def _matrix(m, env) -> np.ndarray | None:
    vals = [[_number(e, env) for e in row] for row in m]
    if any(v is None for row in vals for v in row):
        return None
    return np.array(vals, dtype=float)


def _vector(v, env) -> np.ndarray | None:
    vals = [_number(e, env) for e in v]
    return None if any(x is None for x in vals) else np.array(vals, dtype=float)


def mass_property_problems(model: ir.Model, env: dict[str, float]) -> list[Diagnostic]:
    out: list[Diagnostic] = []
    turning = None                       # computed on the first body that needs it
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
        inertia = _matrix(b.inertia, env)
        if inertia is None:
            continue
        com = _vector(b.com, env)
        d = tensor_problem(b, inertia, (m or 0.0) * float(com @ com) if com is not None else 0.0)
        if d is not None and d.code == "E509" and d.message.startswith("no rigid body"):
            if turning is None:
                turning = turning_axes(model, env)
            if not isinstance(turning.get(b.name, ANY), str):
                d = None                  # a planar body (or one that never turns): I1 + I2 does not enter
        if d is not None:
            out.append(d)
    return out


def tensor_problem(b: ir.Body, inertia: np.ndarray, offset_moment: float = 0.0) -> Diagnostic | None:
    """What is wrong with one body's tensor (None: nothing), the planar exemption aside.

    Tolerances are relative to the body's own scale of moments: the largest entry of I, or
    ``offset_moment`` = m |r_cm|^2 (what the mass adds about the body's frame origin) when that is
    larger, so that a link whose tensor is zero up to rounding noise (1e-35 beside a mass of 1 kg
    off its origin) is judged as the zero tensor it stands for."""
    scale = max(float(np.max(np.abs(inertia))), offset_moment, 1e-300)
    if np.max(np.abs(inertia - inertia.T)) > SYMMETRY_TOL * scale:
        return Diagnostic("E509", f"the inertia tensor of body '{b.name}' is not symmetric", b.span,
                          "I must equal its transpose: give I_21, I_31, I_32 once (or a symmetric I)")
    moments = np.sort(np.linalg.eigvalsh(0.5 * (inertia + inertia.T)))
    shown = ", ".join(f"{x:.6g}" for x in moments)
    if moments[0] < -NEGATIVE_TOL * scale:
        return Diagnostic("E509", f"the inertia tensor of body '{b.name}' has a negative principal moment "
                                  f"(principal moments {shown}): it is not positive semidefinite", b.span,
                          "moments of inertia are >= 0; check signs (products of inertia enter I with "
                          "their sign as written: I_21 is the tensor entry -sum(m x y), URDF's ixy)")
    if b.measured or moments[2] <= 0:
        return None
    ref = max(float(moments[2]), offset_moment)
    excess = (moments[2] - moments[0] - moments[1]) / ref
    if excess <= NOISE:
        return None
    amount = f"I3 - (I1 + I2) = {moments[2] - moments[0] - moments[1]:.3g}, {excess:.3g} of " + (
        "I3" if ref == moments[2] else f"m |r_cm|^2 = {ref:.3g}, the mass's moment about the body origin")
    if excess <= ROUNDING:
        shown = ", ".join(f"{x:.10g}" for x in moments)
        return Diagnostic("W509", f"the principal moments of '{b.name}' ({shown}) break the triangle inequality "
                                  f"I1 + I2 >= I3 by rounding ({amount}); accepted", b.span,
                          "printed data lose digits; give the moments with more digits to silence this",
                          "warning")
    return Diagnostic("E509", f"no rigid body has the inertia tensor of '{b.name}': its principal "
                              f"moments ({shown}) break the triangle inequality I1 + I2 >= I3 ({amount})",
                      b.span,
                      "each principal moment is at most the sum of the other two for any mass distribution "
                      f"(rounding is accepted up to {ROUNDING:g} of I3); check the values (a thin disk: "
                      "I3 = I1 + I2); for measured data you stand by, add measured_inertia = true to the body"
                      + ("; a planar inertia (moments about one axis only) is accepted where the body turns "
                         "about that axis only (a Revolute), not here" if moments[1] <= NOISE * moments[2] else ""))


# ----------------------------------------------------------------------------- planar bodies


def turning_axes(model: ir.Model, env: dict[str, float]) -> dict[str, object]:
    """For every body, how it can turn relative to the world along the joints that attach it
    (the spanning tree, declaration order): None (it never turns), a unit vector n in body axes
    (it turns about n only: a planar body), or ANY.  Unknown numbers give ANY."""
    parent = _tree_joints(model)
    kinds = {b.name: b.kind for b in model.bodies}
    return {b.name: _turning(b.name, parent, kinds, env) for b in model.bodies}


def _tree_joints(model: ir.Model) -> dict[str, ir.Joint]:
    reached, parent = {"world"}, {}
    pending = [j for j in model.joints if j.parent_body != j.child_body and j.child_body != "world"]
    changed = True
    while changed:
        changed = False
        for j in list(pending):
            if j.parent_body in reached:
                pending.remove(j)
                if j.child_body not in reached:
                    reached.add(j.child_body)
                    parent[j.child_body] = j
                changed = True
    return parent


def _turning(body: str, parent: dict[str, ir.Joint], kinds: dict[str, str], env) -> object:
    M = np.eye(3)                        # coordinates of the current frame -> body coordinates
    n = None
    b = body
    for _ in range(len(parent) + 1):
        if b == "world":
            return n
        j = parent.get(b)
        if j is None:
            return ANY
        P = np.eye(3) if j.parent_R is None else _matrix(j.parent_R, env)
        C = np.eye(3) if j.child_R is None else _matrix(j.child_R, env)
        if P is None or C is None:
            return ANY
        axes, R = _joint_turns(j, kinds.get(j.child_body) == "point", env)
        if axes is ANY:
            return ANY
        for a in axes:
            a_b = M @ C @ a
            norm = float(np.linalg.norm(a_b))
            if norm == 0:
                return ANY
            a_b = a_b / norm
            if n is None:
                n = a_b
            elif np.linalg.norm(np.cross(n, a_b)) > PARALLEL_TOL:
                return ANY
        # a rotation about the axes found fixes them: later (parent) axes must be parallel to them
        M = M @ C @ R.T @ P.T
        b = j.parent_body
    return ANY


def _joint_turns(j: ir.Joint, point_child: bool, env):
    """(rotation axes in the joint frame, constant rotation of the joint) or (ANY, None)."""
    eye = np.eye(3)
    if j.kind in ("prismatic", "fixed"):
        return [], eye
    if j.kind in ("revolute", "cylindrical") or (j.kind == "planar" and not point_child):
        a = _vector(j.axis, env)
        return ([a], eye) if a is not None else (ANY, None)
    if j.kind in ("planar", "free") and point_child:
        return [], eye
    if j.kind == "frame":
        R = eye if j.frame_R is None else _matrix(j.frame_R, env)
        return ([], R) if R is not None else (ANY, None)
    return ANY, None
