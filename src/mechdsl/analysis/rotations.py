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

from .core import N_PROBE, Probe, at_states, null_space


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
    blocks: list[list[np.ndarray]] = [[], [], []]
    sizes = [0.0, 0.0, 0.0]        # the size of the terms (not of their difference, which may be noise)
    I, J = np.array([p[0] for p in pairs]), np.array([p[1] for p in pairs])
    for k, (Lq, Lv, Q, Gk) in enumerate(at_states(f, pr, pv)):
        if not all(np.all(np.isfinite(v)) for v in (Lq, Lv, Q, Gk)):
            continue
        q, v = pr.q[k], pr.qd[k]
        Lq, Lv, Q = Lq.ravel(), Lv.ravel(), Q.ravel()
        with np.errstate(all="ignore"):     # huge values: products that overflow end the search below
            finite = np.all(np.isfinite(Lq[J] * q[I] - Lq[I] * q[J] + Lv[J] * v[I] - Lv[I] * v[J]))
        if not finite:
            return []
        # A_ji = a, A_ij = -a: (A q)_j = a q_i, (A q)_i = -a q_j
        blocks[0].append(Lq[J] * q[I] - Lq[I] * q[J] + Lv[J] * v[I] - Lv[I] * v[J])
        sizes[0] = max(sizes[0], float(np.max(np.abs(Lq) * np.max(np.abs(q)) + np.abs(Lv) * np.max(np.abs(v)))))
        blocks[1].append(Q[J] * q[I] - Q[I] * q[J])
        sizes[1] = max(sizes[1], float(np.max(np.abs(Q)) * np.max(np.abs(q))))
        if m:
            Gk = Gk.reshape(m, n)
            blocks[2].extend(Gk[:, J] * q[I] - Gk[:, I] * q[J])
            sizes[2] = max(sizes[2], float(np.max(np.abs(Gk)) * np.max(np.abs(q))))
    if len(blocks[0]) < 2:
        return []
    if sizes[0] == 0.0:
        return []          # L depends on nothing: no claim
    # each block relative to the size of its terms; entries below REL of that are zero (noise of
    # cancelling terms), so an exact symmetry gives exact zero rows and no singular value at all
    rows = []
    for b, size in zip(blocks, sizes):
        if b and size > 0:
            B = np.vstack(b) / size
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
