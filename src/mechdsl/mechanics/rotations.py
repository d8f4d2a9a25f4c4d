"""Rotation matrices on CasADi SX: about an axis, Euler sequences, unit quaternions.

A rotation matrix E maps child axes to parent axes (x_parent = E x_child).
"""
from __future__ import annotations

import casadi as ca

from .spatial import skew

AXES = {"x": 0, "y": 1, "z": 2}


def unit_axis_index(a) -> int | None:
    """k when the SX 3-vector a is the constant unit vector e_k, else None."""
    if not all(a[i].is_constant() for i in range(3)):
        return None
    vals = [float(a[i]) for i in range(3)]
    for k in range(3):
        if vals[k] == 1.0 and all(vals[j] == 0.0 for j in range(3) if j != k):
            return k
    return None


def rot(a, phi) -> ca.SX:
    """Rotation by angle phi about the unit axis a (Rodrigues), sparse for coordinate axes."""
    k = unit_axis_index(a)
    c, s = ca.cos(phi), ca.sin(phi)
    if k is not None:
        i, j = (k + 1) % 3, (k + 2) % 3
        E = ca.SX(3, 3)
        E[k, k] = 1
        E[i, i] = c
        E[j, j] = c
        E[i, j] = -s
        E[j, i] = s
        return E
    ax = skew(a)
    return ca.SX.eye(3) + s * ax + (1 - c) * ca.mtimes(ax, ax)


def quat_matrix(q) -> ca.SX:
    """Rotation matrix of the quaternion q = (q0, q1, q2, q3) (q0 scalar), normalized:
    R(q / |q|), so a drifting norm never distorts the rigid body."""
    q0, q1, q2, q3 = q[0], q[1], q[2], q[3]
    n2 = q0 * q0 + q1 * q1 + q2 * q2 + q3 * q3
    R = ca.vertcat(
        ca.horzcat(q0 * q0 + q1 * q1 - q2 * q2 - q3 * q3, 2 * (q1 * q2 - q0 * q3), 2 * (q1 * q3 + q0 * q2)),
        ca.horzcat(2 * (q1 * q2 + q0 * q3), q0 * q0 - q1 * q1 + q2 * q2 - q3 * q3, 2 * (q2 * q3 - q0 * q1)),
        ca.horzcat(2 * (q1 * q3 - q0 * q2), 2 * (q2 * q3 + q0 * q1), q0 * q0 - q1 * q1 - q2 * q2 + q3 * q3))
    return R / n2


def quat_G(q) -> ca.SX:
    """G(q) (3x4) with w_body = 2 G(q) qdot / |q|^2, G q = 0, G G^T = |q|^2 1."""
    q0, q1, q2, q3 = q[0], q[1], q[2], q[3]
    return ca.vertcat(ca.horzcat(-q1, q0, q3, -q2),
                      ca.horzcat(-q2, -q3, q0, q1),
                      ca.horzcat(-q3, q2, -q1, q0))


def euler_sequence(seq: str) -> tuple[int, int, int]:
    seq = seq.strip().lower()
    if len(seq) != 3 or any(ch not in AXES for ch in seq) or seq[0] == seq[1] or seq[1] == seq[2]:
        raise ValueError(seq)
    return tuple(AXES[ch] for ch in seq)
