"""When two solutions of the equilibrium search are one equilibrium (analysis.equilibrium): equal
coordinates (angles modulo 2 pi, quaternions up to sign), the same rotation in other Euler angles, or
joined by a path of equilibria (a continuous family, a rotation about a symmetry axis)."""
from __future__ import annotations

import numpy as np

from ..diagnostics import MechError
from . import charts
from .core import dense, parts, structure, wrap_angle


def same_point(a: np.ndarray, b: np.ndarray, periodic, blocks=()) -> bool:
    """a and b are one point: every coordinate within 1e-6 (relative), angles modulo 2 pi,
    quaternion blocks by their rotation distance."""
    quat = {i for _, idx in blocks for i in idx}
    for _, idx in blocks:
        if charts.block_distance(a, b, idx) > 1e-6:
            return False
    for i, (x, y, per) in enumerate(zip(a, b, periodic)):
        if i in quat:
            continue
        d = x - y
        if per:
            d = wrap_angle(d)
        if abs(d) > 1e-6 * (1.0 + abs(x)):
            return False
    return True


def euler_same(eom, a, b, st) -> bool:
    """a and b describe the same configuration through the other Euler angles of a joint's
    rotation, up to a shift along the symmetry directions (angles modulo 2 pi)."""
    eb = charts.euler_blocks(eom)
    if not eb:
        return False
    N = st.symmetry
    for block in eb:
        tw = charts.euler_twin(b, block)
        d = np.array([wrap_angle(x - y) if (per or i in block[0]) else x - y
                      for i, (x, y, per) in enumerate(zip(a, tw, st.periodic))])
        if N.size:
            d = d - N @ (N.T @ d)
            d = np.array([wrap_angle(x) if (per or i in block[0]) else x
                          for i, (x, per) in enumerate(zip(d, st.periodic))])
        if np.max(np.abs(d), initial=0.0) <= 1e-6 * (1.0 + np.max(np.abs(a), initial=0.0)):
            return True
    return False


def rotation_joined(eom, a, b, t, pv, tol) -> bool:
    """Euler-angle models: a and b are one configuration or on one family of equilibria as
    rotations: the same model in quaternions is at rest along the great circle between them
    (Euler coordinates cannot say so near gimbal lock, where a line of angles is one rotation)."""
    eb = charts.euler_blocks(eom)
    if not eb:
        return False
    try:
        base, to_new = charts.quaternion_model(eom, [blk[2] for blk in eb])
    except MechError:
        return False
    qa, qb = to_new(a), to_new(b)
    blocks = charts.quaternion_blocks(base)
    quat = [i for _, idx in blocks for i in idx]
    rest = [i for i in range(base.n) if i not in quat]
    per = structure(eom, pv).periodic
    da = np.zeros(base.n)
    for i in rest:
        c = base.coords[i]
        j = eom.coords.index(c)
        da[i] = wrap_angle(qa[i] - qb[i]) if per[j] else qa[i] - qb[i]
    if np.max(np.abs(da), initial=0.0) > 1e-3 * (1.0 + np.max(np.abs(qa[rest]), initial=0.0)):
        return False
    for _, idx in blocks:
        if np.dot(qa[idx], qb[idx]) < 0:
            qb[idx] = -qb[idx]
    pt = parts(base)
    for s in (0.0, 0.25, 0.5, 0.75, 1.0):
        w = qb + s * (qa - qb)
        w[rest] = qb[rest] + s * da[rest]
        for _, idx in blocks:
            nb = np.linalg.norm(w[idx])
            if nb < 1e-6:
                return False
            w[idx] = w[idx] / nb
        _, bias = pt.M_bias(w, np.zeros(base.n), t, pv)
        if not np.max(np.abs(bias), initial=0.0) <= tol:
            return False
    return True


def joined(F, q0, pv, a, b, alpha_a, alpha_b, tol, periodic, blocks=(), families=False) -> bool:
    """Two solutions of one degenerate equilibrium (slow convergence at a multiple root) or, with
    quaternion joints, of one continuous family (a rotation about the vertical): the residual
    stays below tol along the path between them (quaternion blocks: the great circle)."""
    d = np.array([wrap_angle(x - y) if per else x - y for x, y, per in zip(a, b, periodic)])
    quat = [i for _, idx in blocks for i in idx]
    if not (blocks or families) and np.max(np.abs(d), initial=0.0) > 1e-3 * (1.0 + np.max(np.abs(a), initial=0.0)):
        return False
    n = len(a)
    bb = np.array(b, float)
    for _, idx in blocks:     # the same sign for the path (q and -q are one rotation)
        if np.dot(a[idx], bb[idx]) < 0:
            bb[idx] = -bb[idx]
    d[quat] = (a - bb)[quat]
    for s in (0.25, 0.5, 0.75):
        w = np.concatenate([bb + s * d, alpha_b + s * (alpha_a - alpha_b)])
        for _, idx in blocks:
            nb = np.linalg.norm(w[idx])
            if nb < 1e-6:
                return False
            w[idx] = w[idx] / nb
        r = dense(F(w, q0, pv)).ravel()[:n]
        if not np.all(np.isfinite(r)) or np.any(np.abs(r) > tol):
            return False
    return True


def distance(a, b, periodic) -> float:
    """The squared distance of a and b, angle differences taken modulo 2 pi."""
    d = 0.0
    for x, y, per in zip(a, b, periodic):
        z = wrap_angle(x - y) if per else x - y
        d += z * z
    return d

