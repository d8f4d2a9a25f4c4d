"""Vector start values of spatial joints (issue 17): `r(start = {..})`, `v(start = {..})` on a
Free joint and `omega(start = {..}, frame = "body" | "world")` on Spherical and Free joints.

They are converted here, as IR expressions in the parameters, into the start values and speeds
of the joint's own coordinates:

- `r`, `v`: the translation coordinates x, y, z and their speeds (the Free joint translates
  first, along the parent joint frame's axes, so they are the child point's position and
  velocity relative to the parent point, in parent axes).
- `omega`: the angular velocity of the child relative to the parent, in child body axes
  (`frame = "body"`) or in the parent's axes (`frame = "world"`; only for a joint whose parent
  is the world), turned into the chart's rates at the start orientation: for an Euler
  sequence abc (R = R_a(phi) R_b(theta) R_c(psi)) w_body = E(q) qd with the columns
  R_c^T R_b^T e_a, R_c^T e_b, e_c, solved by Cramer's rule (a gimbal-locked start, det E = 0, is
  refused by the flattener: E222); for a quaternion
  qd = G(q)^T w_body / 2 (w_body = 2 G qd / |q|^2, G G^T = |q|^2 1).
"""
from __future__ import annotations

from .. import exprs as X
from .. import ir
from .components import rodrigues

C = X.const
E = ((C(1.0), C(0.0), C(0.0)), (C(0.0), C(1.0), C(0.0)), (C(0.0), C(0.0), C(1.0)))
AXES = {"x": 0, "y": 1, "z": 2}


def _dot(a, b) -> ir.Expr:
    return X.add(X.add(X.mul(a[0], b[0]), X.mul(a[1], b[1])), X.mul(a[2], b[2]))


def _cross(a, b):
    return (X.sub(X.mul(a[1], b[2]), X.mul(a[2], b[1])), X.sub(X.mul(a[2], b[0]), X.mul(a[0], b[2])),
            X.sub(X.mul(a[0], b[1]), X.mul(a[1], b[0])))


def _mat_t_vec(R, v):
    """R^T v."""
    return tuple(_dot(tuple(R[i][j] for i in range(3)), v) for j in range(3))


def _matmul(A, B):
    return tuple(tuple(_dot(A[i], tuple(B[k][j] for k in range(3))) for j in range(3)) for i in range(3))


def _det(a, b, c) -> ir.Expr:
    return _dot(a, _cross(b, c))


def euler_rates(seq: str, angles, w, frame: str):
    """((phi', theta', psi'), det) of the intrinsic sequence `seq` at `angles` for the angular
    velocity w (child axes for frame 'body', parent axes for 'world'); det = det E(q), |det| <= 1,
    vanishes at gimbal lock."""
    a, b, c = (AXES[ch] for ch in seq)
    Ra, Rb, Rc = (rodrigues(E[k], ang) for k, ang in zip((a, b, c), angles))
    if frame == "world":
        w = _mat_t_vec(_matmul(_matmul(Ra, Rb), Rc), w)
    cols = (_mat_t_vec(Rc, _mat_t_vec(Rb, E[a])), _mat_t_vec(Rc, E[b]), E[c])
    det = _det(*cols)
    out = []
    for k in range(3):
        cs = list(cols)
        cs[k] = w
        out.append(X.div(_det(*cs), det))
    return tuple(out), det


def quaternion_rates(q, w, frame: str):
    """q' = G(q)^T w_body / 2 for the quaternion q = (q0, q1, q2, q3)."""
    q0, q1, q2, q3 = q
    if frame == "world":
        w = _mat_t_vec(_quat_matrix(q), w)
    G = ((X.neg(q1), q0, q3, X.neg(q2)), (X.neg(q2), X.neg(q3), q0, q1), (X.neg(q3), q2, X.neg(q1), q0))
    half = C(0.5)
    return tuple(X.mul(half, _dot(tuple(G[i][j] for i in range(3)), w)) for j in range(4))


def _quat_matrix(q):
    q0, q1, q2, q3 = q
    sq = lambda a: X.mul(a, a)  # noqa: E731
    two = lambda a, b: X.mul(C(2.0), X.mul(a, b))  # noqa: E731
    n2 = X.add(X.add(sq(q0), sq(q1)), X.add(sq(q2), sq(q3)))
    R = ((X.sub(X.add(sq(q0), sq(q1)), X.add(sq(q2), sq(q3))), X.sub(two(q1, q2), two(q0, q3)), X.add(two(q1, q3), two(q0, q2))),
         (X.add(two(q1, q2), two(q0, q3)), X.sub(X.add(sq(q0), sq(q2)), X.add(sq(q1), sq(q3))), X.sub(two(q2, q3), two(q0, q1))),
         (X.sub(two(q1, q3), two(q0, q2)), X.add(two(q2, q3), two(q0, q1)), X.sub(X.add(sq(q0), sq(q3)), X.add(sq(q1), sq(q2)))))
    return tuple(tuple(X.div(x, n2) for x in row) for row in R)
