"""Spatial (6D) algebra on CasADi SX, written with 3-vectors and 3x3 blocks.

Conventions (Featherstone, body coordinates):
- a motion vector is the pair (w, v): angular velocity and the velocity of the frame origin,
  both in the frame's axes; a force vector is (n, f): moment about the origin and force.
- a link frame i sits in its parent frame by (E, r): E maps child axes to parent axes and r
  is the child origin in parent coordinates.  ``motion_to_child`` is iX_parent,
  ``force_to_parent`` is parentX_i^*.
- a spatial inertia (rigid or articulated) is a symmetric 6x6 matrix [[A, B], [B^T, C]]
  acting on (w, v): I (w, v) = (A w + B v, B^T w + C v).  A rigid body of mass m, centre of
  mass c and inertia Ic about c has A = Ic - m [c]x^2, B = m [c]x, C = m 1.

Plain CasADi SX matrices are used; constant zeros and ones simplify away at the element
level (x*0 -> 0, x*1 -> x), so elementary joints cost only what their sparsity needs.
"""
from __future__ import annotations


import casadi as ca
from ..model.records import record


def vec(x) -> ca.SX:
    return ca.SX(x) if not isinstance(x, ca.SX) else x


def zeros3() -> ca.SX:
    return ca.SX.zeros(3, 1)


def cross(a, b):
    """a x b for 3x1 SX (elementwise, so structural zeros stay zeros)."""
    return ca.vertcat(a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0])


def skew(a):
    return ca.SX(ca.skew(a))


def vee(S):
    """The vector of the skew-symmetric part of a 3x3 matrix."""
    return 0.5 * ca.vertcat(S[2, 1] - S[1, 2], S[0, 2] - S[2, 0], S[1, 0] - S[0, 1])


def mul(A, x):
    return ca.mtimes(A, x)


@record(frozen=False)
class Inertia:
    """A symmetric spatial inertia [[A, B], [B^T, C]] (3x3 SX blocks)."""

    A: ca.SX
    B: ca.SX
    C: ca.SX

    @staticmethod
    def rigid(m, c, Ic) -> "Inertia":
        c = vec(c)
        cx = skew(c)
        A = Ic - m * ca.mtimes(cx, cx)
        return Inertia(A, m * cx, m * ca.SX.eye(3))

    @staticmethod
    def zero() -> "Inertia":
        return Inertia(ca.SX(3, 3), ca.SX(3, 3), ca.SX(3, 3))

    def times(self, w, v):
        return (ca.mtimes(self.A, w) + ca.mtimes(self.B, v),
                ca.mtimes(self.B.T, w) + ca.mtimes(self.C, v))

    def __add__(self, o: "Inertia") -> "Inertia":
        return Inertia(self.A + o.A, self.B + o.B, self.C + o.C)

    def to_parent(self, E, r) -> "Inertia":
        """parentX_i^* I iX_parent: the same inertia expressed in the parent frame."""
        A = ca.mtimes(ca.mtimes(E, self.A), E.T)
        B = ca.mtimes(ca.mtimes(E, self.B), E.T)
        C = ca.mtimes(ca.mtimes(E, self.C), E.T)
        if _is_zero(r):
            return Inertia(A, B, C)
        rx = skew(r)
        BrT = ca.mtimes(rx, B.T)               # [r] B^T ;  -B [r] is its transpose
        rC = ca.mtimes(rx, C)
        A2 = A + BrT + BrT.T - ca.mtimes(rC, rx)
        return Inertia(A2, B + rC, C)


def _is_zero(x) -> bool:
    """True when every entry of the SX x is a structural or constant zero."""
    return isinstance(x, ca.SX) and (x.nnz() == 0 or all(x[i].is_zero() for i in range(x.numel())))


def motion_to_child(E, r, w, v):
    """iX_parent (w, v): a parent-frame motion vector seen in the child frame."""
    wc = ca.mtimes(E.T, w)
    if _is_zero(r):
        return wc, ca.mtimes(E.T, v)
    return wc, ca.mtimes(E.T, v + cross(w, r))


def force_to_parent(E, r, n, f):
    """parentX_i^* (n, f): a child-frame force seen in the parent frame."""
    fp = ca.mtimes(E, f)
    npar = ca.mtimes(E, n)
    if not _is_zero(r):
        npar = npar + cross(r, fp)
    return npar, fp


def crm(w, v, w2, v2):
    """(w, v) x (w2, v2) for motion vectors."""
    return cross(w, w2), cross(w, v2) + cross(v, w2)


def crf(w, v, n, f):
    """(w, v) x* (n, f) for force vectors."""
    return cross(w, n) + cross(v, f), cross(w, f)


def inv_small(D):
    """Inverse of a small symmetric positive definite SX matrix (1x1 .. 3x3), explicit."""
    k = D.shape[0]
    if k == 1:
        return 1 / D
    if k == 2:
        det = D[0, 0] * D[1, 1] - D[0, 1] * D[1, 0]
        return ca.vertcat(ca.horzcat(D[1, 1], -D[0, 1]), ca.horzcat(-D[1, 0], D[0, 0])) / det
    if k == 3:
        a, b, c = D[0, 0], D[0, 1], D[0, 2]
        d, e, f = D[1, 0], D[1, 1], D[1, 2]
        g, h, i = D[2, 0], D[2, 1], D[2, 2]
        A, B, C = e * i - f * h, -(d * i - f * g), d * h - e * g
        det = a * A + b * B + c * C
        adj = ca.vertcat(ca.horzcat(A, -(b * i - c * h), b * f - c * e),
                         ca.horzcat(B, a * i - c * g, -(a * f - c * d)),
                         ca.horzcat(C, -(a * h - b * g), a * e - b * d))
        return adj / det
    raise ValueError("inv_small: size > 3")
