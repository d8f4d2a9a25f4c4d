"""Orientations: the built-ins ``rpy(r, p, y)`` and ``axis_angle(...)``, and the orientation a
point, joint or frame is given with ``rpy = {r, p, y}`` or ``R = ...`` (issue 26).

Conventions (docs/language.md, "Orientations"):

- ``rpy(r, p, y)`` is URDF's roll-pitch-yaw: fixed-axis X-Y-Z, i.e. first roll r about the
  fixed x axis, then pitch p about the fixed y axis, then yaw y about the fixed z axis:
  ``R = Rz(y) Ry(p) Rx(r)`` (the same matrix as the intrinsic z-y'-x'' sequence).
- ``axis_angle(axis, angle)`` is the right-handed rotation by ``angle`` about ``axis`` (any
  length, normalized), the same as ``rotation(axis, angle)``; ``axis_angle(v)`` takes a rotation
  vector (direction: the axis, length: the angle).
- An orientation ``R`` maps the coordinates of the oriented frame to those of the frame it is
  given in (its columns are the oriented frame's axes): a point's R is in its body's axes, a
  joint's in its parent point's axes, a Frame's in its parent's.

Constant angles give numbers (computed with ``math``), others IR expressions.
"""
from __future__ import annotations

import math

from ..model import exprs as X
from ..model import ir
from .components import as_expr, as_mat3, as_vec3, normalized, rodrigues
from .values import Arr, Scalar, ValError, Val

C = X.const
ROTATION_TOL = 1e-6      # a constant R further than this from a rotation (R^T R - 1, det - 1) is E318


def _cos_sin(a: ir.Expr) -> tuple[ir.Expr, ir.Expr]:
    if isinstance(a, ir.Const):
        return C(math.cos(a.value)), C(math.sin(a.value))
    return X.func("cos", a), X.func("sin", a)


def rpy_matrix(r: ir.Expr, p: ir.Expr, y: ir.Expr) -> ir.Mat3:
    """Rz(y) Ry(p) Rx(r) (URDF's rpy)."""
    cr, sr = _cos_sin(r)
    cp, sp = _cos_sin(p)
    cy, sy = _cos_sin(y)
    m, a, s, n = X.mul, X.add, X.sub, X.neg
    return ((m(cy, cp), s(m(m(cy, sp), sr), m(sy, cr)), a(m(m(cy, sp), cr), m(sy, sr))),
            (m(sy, cp), a(m(m(sy, sp), sr), m(cy, cr)), s(m(m(sy, sp), cr), m(cy, sr))),
            (n(sp), m(cp, sr), m(cp, cr)))


def axis_angle_matrix(axis: ir.Vec3, angle: ir.Expr | None = None) -> ir.Mat3:
    """The rotation about ``axis`` by ``angle``; without an angle ``axis`` is a rotation vector."""
    if angle is None:
        if all(isinstance(c, ir.Const) for c in axis):
            n = math.hypot(*(c.value for c in axis))  # type: ignore[union-attr]
            if n == 0.0:
                return ((C(1.0), C(0.0), C(0.0)), (C(0.0), C(1.0), C(0.0)), (C(0.0), C(0.0), C(1.0)))
            angle = C(n)
        else:
            angle = X.func("sqrt", X.vsum(X.mul(c, c) for c in axis))
    return rodrigues(normalized(axis, "the rotation axis"), angle)


def matrix_value(R: ir.Mat3) -> Arr:
    from ..model import units as U

    return Arr(tuple(Arr(tuple(Scalar(c, U.ONE) for c in row)) for row in R))


def call_rpy(args: list[Val]) -> Arr:
    """rpy(r, p, y) or rpy({r, p, y})."""
    if len(args) == 1:
        r, p, y = as_vec3(args[0], "the argument of rpy()")
    elif len(args) == 3:
        r, p, y = (as_expr(a, "an angle of rpy()") for a in args)
    else:
        raise ValError("E304", f"rpy() takes 3 angles (or one vector of 3), got {len(args)} arguments",
                       "rpy(roll, pitch, yaw) or rpy({roll, pitch, yaw})")
    _dimensionless(args)
    return matrix_value(rpy_matrix(r, p, y))


def call_axis_angle(args: list[Val]) -> Arr:
    """axis_angle(axis, angle) or axis_angle(rotation vector)."""
    if len(args) not in (1, 2):
        raise ValError("E304", f"axis_angle() takes an axis and an angle (or one rotation vector), "
                               f"got {len(args)} arguments", "axis_angle({0, 0, 1}, pi/2) or axis_angle({0, 0, pi/2})")
    _dimensionless(args)
    axis = as_vec3(args[0], "the axis of axis_angle()")
    angle = as_expr(args[1], "the angle of axis_angle()") if len(args) == 2 else None
    return matrix_value(axis_angle_matrix(axis, angle))


def _dimensionless(args: list[Val]) -> None:
    from . import values as V

    for a in args:
        for s in V.flatten(a) if isinstance(a, Arr) else [a]:
            if isinstance(s, Scalar):
                V.require_dimensionless(s.dim, "an angle", s.approx)


def given_orientation(fields: dict, owner: str) -> ir.Mat3 | None:
    """The orientation a component is given with ``rpy = {r, p, y}`` or ``R = ...`` (None:
    neither).  Both is E211; a constant R that is not a rotation is E318."""
    rpy, R = fields.get("rpy"), fields.get("R")
    if rpy is not None and R is not None:
        raise ValError("E211", f"give either rpy or R for '{owner}', not both", "remove one of them")
    if rpy is not None:
        return rpy_matrix(*as_vec3(rpy, "rpy"))
    if R is not None:
        m = as_mat3(R, "R")
        check_rotation(m, owner)
        return m
    return None


def check_rotation(m: ir.Mat3, owner: str) -> None:
    """A constant matrix must be a rotation: orthonormal with determinant +1 (to ROTATION_TOL)."""
    if not all(isinstance(c, ir.Const) for row in m for c in row):
        return
    import numpy as np

    a = np.array([[c.value for c in row] for row in m], float)  # type: ignore[union-attr]
    if not np.all(np.isfinite(a)):
        return                                        # E510's (a non-finite value) to say
    err = float(np.max(np.abs(a.T @ a - np.eye(3))))
    det = float(np.linalg.det(a))
    if err > ROTATION_TOL or det < 0:
        what = (f"its determinant is {det:.6g} (a reflection)" if det < 0 and err <= ROTATION_TOL
                else f"R^T R differs from the identity by {err:.3g}")
        raise ValError("E318", f"R of '{owner}' is not a rotation matrix: {what}",
                       "an orientation is orthonormal with determinant +1; build it with rpy(r, p, y), "
                       "axis_angle(axis, angle) or rotation(axis, angle)")


def compose(a: ir.Mat3 | None, b: ir.Mat3 | None) -> ir.Mat3 | None:
    """a b, with None for the identity."""
    if a is None:
        return b
    if b is None:
        return a
    return tuple(tuple(X.vsum(X.mul(a[i][k], b[k][j]) for k in range(3)) for j in range(3))
                 for i in range(3))  # type: ignore[return-value]


def transpose_times(R: ir.Mat3, v: tuple) -> tuple:
    """R^T v."""
    return tuple(X.vsum(X.mul(R[i][j], v[i]) for i in range(3)) for j in range(3))
