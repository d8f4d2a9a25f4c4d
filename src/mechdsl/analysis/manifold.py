"""Starting guesses for equilibria on the constraint manifold g(q) = 0.

The configurations of a constrained model form a manifold whose connected components are the
assembly modes of a mechanism (a four-bar's open and crossed configurations).  The guesses
stay on the component of the start values:

- one degree of freedom: the curve through the (consistent) start is *traced*: steps along the
  unit tangent (null space of G, in coordinates scaled so that a step changes an angle by at
  most STEP rad and another coordinate by at most STEP times its size), each followed by the
  DAE's projection (``constraints.project``: minimal change in the mass metric), in both
  directions until the curve closes or ends.  Where the tangential force t'bias(q, 0) changes
  sign along the curve, both neighbours become guesses: the tangential force of a
  conservative model is -dV/ds, so every equilibrium on the curve is bracketed;
- more degrees of freedom: a grid (or Halton points) over the *independent* coordinates of a
  pivoted QR of G at the start, the dependent ones solved from the nearest guess already
  projected (continuation), the grid walked outwards from the start.

Guesses of the user are projected (all coordinates free) and may lie on any component.
"""
from __future__ import annotations

import itertools
import math

import numpy as np

from .constraints import Setup, independent_coordinates, project, tangent_basis
from .core import parts
from .matrices import sym
from .sampling import halton


STEP = 0.2             # tracing step: radians, or this fraction of a coordinate's size
MAX_TRACE = 600        # projections per traced curve


def guesses(s: Setup, user: list[np.ndarray], st, axes_of, max_guesses: int) -> list[np.ndarray]:
    """Guesses on the constraint manifold (see the module docstring); ``axes_of(i)`` gives the
    values tried for coordinate i in a grid."""
    eom, pv, t = s.eom, s.pv, s.t
    out: list[np.ndarray] = []

    def add(q):
        if q is None:
            return
        for o in out:
            if np.max(np.abs(o - q), initial=0.0) <= 1e-9 * (1.0 + np.max(np.abs(q), initial=0.0)):
                return
        out.append(np.asarray(q, float))

    for g in user:
        add(project(eom, g, t, pv))
    add(s.q_start)
    dof = eom.n - s.ma
    if dof == 1:
        for q in trace_brackets(s, st):
            add(q)
    elif dof > 1:
        for q in spread(s, st, axes_of, max_guesses):
            add(q)
    return out


def _scales(s: Setup, st) -> np.ndarray:
    q = s.q_start
    return np.array([1.0 if st.angles[i] else max(1.0, abs(q[i])) for i in range(len(q))])


def trace(s: Setup, st, max_steps: int = MAX_TRACE) -> list[np.ndarray]:
    """Points along the one-dof curve through the start, in order (closed curves end near
    the start again; open ones are traced both ways, the backward part first, reversed)."""
    eom, pv, t = s.eom, s.pv, s.t
    w = _scales(s, st)

    def tangent(q, prev):
        Z = tangent_basis(s.G_active(q) * w[None, :])[:, 0] * w        # unit step in scaled coordinates
        d = Z / np.max(np.abs(Z / w))
        return d if prev is None or d @ prev >= 0 else -d

    def close(a, b):
        d = a - b
        d = np.where(st.angles, np.remainder(d + math.pi, 2 * math.pi) - math.pi, d)
        return np.max(np.abs(d / w)) < 0.5 * STEP

    start = s.q_start
    t0 = tangent(start, None)
    branches = []
    for sign in (1.0, -1.0):
        pts, q, d = [], start, sign * t0
        for k in range(max_steps):
            qn = project(eom, q + STEP * d, t, pv)
            if qn is None or np.max(np.abs((qn - q) / w)) < 0.1 * STEP:
                break                                          # the curve ends (or the step stalled)
            pts.append(qn)
            if k >= 3 and close(qn, start):
                return [start] + pts                           # closed: traced once round
            d = tangent(qn, d)
            q = qn
        branches.append(pts)
    return branches[1][::-1] + [start] + branches[0]


def trace_brackets(s: Setup, st) -> list[np.ndarray]:
    """Neighbouring points of the traced curve between which the tangential force changes sign."""
    eom, pv, t = s.eom, s.pv, s.t
    pts = trace(s, st)
    pt = parts(eom)
    # the orthonormal tangent's sign is arbitrary: orient consecutive tangents alike
    out = []
    prevZ = None
    sgn = []
    for q in pts:
        Z = tangent_basis(s.G_active(q))[:, 0]
        if prevZ is not None and Z @ prevZ < 0:
            Z = -Z
        prevZ = Z
        _, bias = pt.M_bias(q, np.zeros(eom.n), t, pv)
        sgn.append(float(Z @ bias))
    for i in range(len(pts) - 1):
        if sgn[i] == 0.0 or sgn[i] * sgn[i + 1] < 0:
            out += [pts[i], pts[i + 1]]
    return out


def spread(s: Setup, st, axes_of, max_guesses: int) -> list[np.ndarray]:
    """Grid over the independent coordinates, dependent ones by continuation (module docstring)."""
    eom, pv, t = s.eom, s.pv, s.t
    n = eom.n
    M, _ = parts(eom).M_bias(s.q_start, np.zeros(n), t, pv)
    indep = independent_coordinates(eom, sym(M), s.G_active(s.q_start))
    axes = [axes_of(i) for i in indep]
    size = math.prod(len(a) for a in axes)
    if size <= max_guesses:
        pts = [np.array(c, float) for c in itertools.product(*axes)]
    else:
        lo = np.array([min(a) for a in axes])
        hi = np.array([max(a) for a in axes])
        pts = [lo + (hi - lo) * halton(j + 1, len(indep)) for j in range(max_guesses)]
    angles = [st.angles[i] for i in indep]

    def dist(a, b):
        d = a - b
        d = np.where(angles, np.remainder(d + math.pi, 2 * math.pi) - math.pi, d)
        return float(d @ d)

    base = s.q_start[list(indep)]
    pts.sort(key=lambda x: dist(x, base))
    done: list[tuple[np.ndarray, np.ndarray]] = [(base, s.q_start)]
    fixed = tuple(i in indep for i in range(n))
    out = []
    for x in pts:
        near = min(done, key=lambda d: dist(x, d[0]))[1]
        q = near.copy()
        q[list(indep)] = x
        qp = project(eom, q, t, pv, fixed=fixed)
        if qp is None:
            qp = project(eom, q, t, pv)
        if qp is not None:
            done.append((x, qp))
            out.append(qp)
    return out
