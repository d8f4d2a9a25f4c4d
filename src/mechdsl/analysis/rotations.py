"""Rotation symmetries in coordinate space (Noether): the angular momenta of models written in
Cartesian coordinates (Kepler in x, y; a particle in an axially symmetric field).

A linear vector field xi(q) = A q with A skew-symmetric (a rotation of the coordinates about
their origin, possibly of several coordinate pairs at once: both bodies of a two-body problem
turned about one axis) is a symmetry when, at every state,

    dL/dq . A q + dL/dqd . A qd = 0,     Q_tot . A q = 0,     G A q = 0

(L invariant under the rotation of positions and velocities, no generalized force and no
constraint against it).  Each condition is linear in the entries a_ij (i < j) of A, so the
symmetries are the null space of those rows stacked over deterministic random states, as for
translations in ``integrals``; Noether's conserved quantity is p . A q with p = dL/dqd, for a
single pair (x, y) with A = [[0, -1], [1, 0]]: x p_y - y p_x, the angular momentum about the
axis normal to the (x, y) plane.

Only rotations about the origin of the coordinates are sought (a centre elsewhere is not), and
only for models with at most ``MAX_COORDS`` coordinates (n (n - 1) / 2 unknowns).
"""
from __future__ import annotations

import numpy as np

from .core import N_PROBE, Probe, null_space, stacked_states


MAX_COORDS = 15
REL = 1e-9          # "identically zero", relative to the size of the stacked rows (as for translations)


def rotation_symmetries(eom, pt, pv) -> list[np.ndarray]:
    """Skew-symmetric n x n matrices A (a basis of the rotation symmetries; largest |a_ij| = 1,
    the first nonzero entry below the diagonal positive), in a deterministic order."""
    import casadi as ca

    n, m = eom.n, eom.m
    if n < 2 or n > MAX_COORDS:
        return []
    pairs = [(i, j) for i in range(n) for j in range(i + 1, n)]
    count = max(N_PROBE, len(pairs) + 4)      # the rows of L alone can reach full rank
    pr = Probe.states(n, count=count)
    G = ca.jacobian(eom.g, eom.q) if m else ca.SX.zeros(0, n)
    f = ca.Function("rot_probe", pt.args, [ca.gradient(pt.L, eom.q), ca.gradient(pt.L, eom.qd), pt.Qtot, G])
    # the states' rows at once (the same operations on the same values as state by state)
    Lq, Lv, Q, G = stacked_states(f, pr, pv)
    Lq, Lv, Q = Lq.T, Lv.T, Q.T                                  # (states, n)
    G = G.reshape(m, count, n).transpose(1, 0, 2) if m else np.zeros((count, 0, n))
    keep = (np.isfinite(Lq).all(axis=1) & np.isfinite(Lv).all(axis=1) & np.isfinite(Q).all(axis=1)
            & np.isfinite(G).all(axis=(1, 2)))
    Lq, Lv, Q, G, q, v = Lq[keep], Lv[keep], Q[keep], G[keep], pr.q[keep], pr.qd[keep]
    I, J = np.array([p[0] for p in pairs]), np.array([p[1] for p in pairs])
    with np.errstate(all="ignore"):     # huge values: products that overflow end the search
        # A_ji = a, A_ij = -a: (A q)_j = a q_i, (A q)_i = -a q_j
        rows0 = Lq[:, J] * q[:, I] - Lq[:, I] * q[:, J] + Lv[:, J] * v[:, I] - Lv[:, I] * v[:, J]
    if not np.all(np.isfinite(rows0)):
        return []
    # the size of the terms (not of their difference, which may be noise), over the states
    qmax, vmax = np.max(np.abs(q), axis=1, initial=0.0), np.max(np.abs(v), axis=1, initial=0.0)
    blocks = [rows0, Q[:, J] * q[:, I] - Q[:, I] * q[:, J],
              (G[:, :, J] * q[:, None, I] - G[:, :, I] * q[:, None, J]).reshape(-1, len(pairs))]
    sizes = [0.0, 0.0, 0.0]
    if len(q):
        sizes[0] = float(np.max(np.abs(Lq) * qmax[:, None] + np.abs(Lv) * vmax[:, None]))
        sizes[1] = float(np.max(np.max(np.abs(Q), axis=1) * qmax))
        if m:
            sizes[2] = float(np.max(np.max(np.abs(G), axis=(1, 2)) * qmax))
    if len(blocks[0]) < 2:
        return []
    if sizes[0] == 0.0:
        return []          # L depends on nothing: no claim
    # each block relative to the size of its terms; entries below REL of that are zero (noise of
    # cancelling terms), so an exact symmetry gives exact zero rows and no singular value at all
    rows = []
    for b, size in zip(blocks, sizes):
        if len(b) and size > 0:
            B = b / size
            rows.append(np.where(np.abs(B) > REL, B, 0.0))
    S = np.vstack(rows)
    if len(S) < len(pairs):
        return []
    N = null_space(S, rel=REL)
    out = []
    for col in N.T:
        w = col / np.max(np.abs(col))
        w = np.where(np.abs(w - np.round(w)) < 1e-9, np.round(w), w)
        w = np.where(np.abs(w) < 1e-12, 0.0, w)
        first = np.flatnonzero(w)[0]
        if w[first] < 0:
            w = -w
        A = np.zeros((n, n))
        A[J, I], A[I, J] = w, -w
        out.append(A)
    return out


def label(A: np.ndarray, coords) -> str:
    """`x:y` for the rotation of the pair (x, y); several pairs joined by `+` (weights other than
    1 written as factors): L_(x:y) means x p_y - y p_x.  No comma: the name is a CSV column
    (issue 23: `L_(bob.x,bob.y)` broke ordinary CSV readers)."""
    n = len(coords)
    parts = []
    for i in range(n):
        for j in range(i + 1, n):
            a = A[j, i]
            if a == 0:
                continue
            coef = "" if abs(a) == 1 else f"{abs(a):g}*"
            sign = "-" if a < 0 else ("+" if parts else "")
            parts.append(f"{sign}{coef}{coords[i]}:{coords[j]}")
    return "".join(parts)
