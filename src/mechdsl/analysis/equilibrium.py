"""Equilibria and their stability.

At rest (qd = 0) Lagrange's equations read M(q) qdd = bias(q, 0, t) with

    bias(q, 0, t) = Q_nc(q, 0) - d(V - T0)/dq          (autonomous systems)

so one equation covers the three cases of the course:

- scleronomic systems (T = T2): the generalized forces vanish, Q_j = -dV/dq_j + Q_j^nc = 0;
- steady moving frames (a hoop spinning at a constant rate): T0 != 0 or T1 != 0 but the
  equations do not depend on t (checked numerically); relative equilibria of V_eff = V - T0;
- free systems under a constant resultant force: the equations are invariant along some
  translation directions N (numerically: d bias/dq N = 0 and dM/dq N = 0 at random states).
  Then we solve bias(q, 0) = M(q) N alpha with the gauge N'(q - q_start) = 0: alpha = 0 is
  an ordinary equilibrium (neutral along N), alpha != 0 the uniformly accelerated reference
  motion q(t) = q* + N alpha t^2/2 with the relative equilibrium q* about it.

Constrained models (g(q) = 0, scleronomic): bias(q, 0) = G(q)' lambda (+ M N alpha) with
g(q) = 0, the multipliers among the unknowns; guesses on the constraint manifold
(:mod:`.manifold`); stability from the Hessian of V + lambda'g on the tangent space of the
constraints (:mod:`.constraints`).

Solutions come from Levenberg-Marquardt (:mod:`.lm`, with the CasADi Jacobian) started
at the user's guesses and a deterministic spread (angles on a grid over [-pi, pi)).  Distinct
solutions are kept (angles compared modulo 2 pi) and classified by the Hessian K of the
(effective) potential in the directions transverse to N, with the linearized eigenvalues as the
second witness (Lyapunov's indirect method).

This module owns the search; the records are in :mod:`.equilibrium_record`, the classification in
:mod:`.equilibrium_classify`, when two solutions are one equilibrium in :mod:`.equilibrium_same`.
"""
from __future__ import annotations

import itertools
import math

import numpy as np

from ..diagnostics import Diagnostic, MechError, UsageError, did_you_mean
from ..eom import fold_inputs
from . import charts
from .constraints import constrained, least_squares_multipliers, setup
from .contacts_at_rest import contact_notes
from .core import dense, param_vector, parts, structure, wrap_angle
from .equilibrium_classify import classify, classify_in_chart, with_families
from .equilibrium_record import RUNAWAY, Equilibria, Equilibrium, Search, equilibria_result
from .equilibrium_same import distance, euler_same, joined, rotation_joined, same_point
from .lm import levenberg_marquardt
from .manifold import guesses as constrained_guesses
from .sampling import halton


__all__ = ["Equilibria", "Equilibrium", "Search", "equilibria", "nearest_equilibrium", "parse_guesses"]

MAX_GUESSES = 256
GRID_ANGLES = 8          # grid points per angle coordinate over [-pi, pi)


def equilibria(eom, guesses=None, *, t: float = 0.0, p=None, max_guesses: int = MAX_GUESSES
               ) -> Equilibria:
    """Distinct equilibria of the model, each classified (see the module docstring).

    guesses: None, a dict {coordinate: value} (missing coordinates take their start values),
    a list of such dicts, or arrays of shape (n,) / (k, n).  p: parameter overrides.
    Constrained models (scleronomic constraints g(q) = 0): see :mod:`.constraints`; each
    equilibrium carries its multipliers.
    """
    eom = fold_inputs(eom)          # inputs held at their defaults: trailing parameters
    pv = param_vector(eom, p)
    con = setup(eom, pv, t, "equilibrium analysis") if constrained(eom) else None
    st = structure(eom, pv)
    q0, _ = eom.start(pv)
    qref = q0 if con is None else con.q_start
    N = st.symmetry
    k = N.shape[1]
    ma = 0 if con is None else con.ma
    notes = [] if con is None else list(con.notes)
    blocks = charts.quaternion_blocks(eom)
    if blocks and con is not None:
        raise MechError(Diagnostic("E909", f"equilibria of '{eom.name}' are not sought: quaternion joints "
                                           f"({', '.join(j for j, _ in blocks)}) together with constraints are "
                                           "not supported by the analyses",
                                   help="use Euler angles for these joints, or simulate the model instead"))
    if not st.autonomous:
        notes.append(f"the equations depend explicitly on time: equilibrium at t = {t:g} only")
    if st.force_scale == 0.0:
        # no force at rest anywhere: every configuration is an equilibrium
        e = classify(eom, st, pv, qref, np.zeros(k), t, 0.0, notes + ["no generalized force acts at rest: "
                                                                       "every configuration is an equilibrium"],
                      con=con, lam=np.zeros(ma))
        return equilibria_result([e], Search(), contact_notes(eom, [e], pv, t))

    F, JF, rs, lam_scale = _residual(eom, st, con, blocks, t, N)
    tol = 1e-8 * max(st.force_scale, 1e-300)
    found: list[tuple[np.ndarray, np.ndarray, float]] = []
    search = Search()
    # rotation joints: solutions on one continuous family (a top turned about the vertical) merge
    families = con is None
    for g in _guesses(eom, guesses, q0, st, max_guesses, con):
        if blocks:
            g = charts.normalize_blocks(g, blocks, fallback=q0)
        search.guesses += 1
        x0 = np.concatenate([g, _start_multipliers(eom, con, g, t, pv, lam_scale), np.zeros(k)])
        sol = _solve(eom, st, con, blocks, F, JF, rs, x0, g, qref, pv, t, tol, search)
        if sol is not None:
            _keep(eom, st, blocks, F, qref, pv, t, tol, families, found, *sol)
    found.sort(key=lambda f_: tuple(np.round(f_[0], 9)))
    out = []
    for qs, rest, resid in found:
        locked = charts.locked_joints(eom, qs, t, pv) if con is None else []
        if blocks or locked:
            e = classify_in_chart(eom, st, pv, qs, rest[ma:], t, resid, list(notes), blocks, locked)
            if e is not None:       # None: a critical point of the Euler chart only (gimbal lock)
                out.append(e)
        elif families:
            st_f, a_f, more = with_families(eom, st, pv, qs, t, rest[ma:])
            out.append(classify(eom, st_f, pv, qs, a_f, t, resid, list(notes) + more))
        else:
            out.append(classify(eom, st, pv, qs, rest[ma:], t, resid, list(notes), con=con,
                                 lam=_clean(lam_scale * rest[:ma], lam_scale)))
    return equilibria_result(out, search, contact_notes(eom, out, pv, t))


def _residual(eom, st, con, blocks, t, N):
    """The residual Function F(w, q_ref, p), its Jacobian JF, the row scales rs and the
    multipliers' scales.  Unknowns w = (q, mu, alpha), lambda = lam_scale * mu; rows
    bias(q, 0, t) - G(q)' lambda - M(q) N alpha ; g(q) / |G row| ; N'(q - q_ref) ; |quaternion|^2 - 1."""
    import casadi as ca

    n, k = eom.n, N.shape[1]
    ma = 0 if con is None else con.ma
    scale = max(st.force_scale, 1e-300)
    w = ca.SX.sym("w", n + ma + k)
    qr = ca.SX.sym("qref", n)
    qw = w[:n]
    alpha = w[n + ma:]
    rest_bias = ca.substitute(eom.bias, eom.qd, ca.SX.zeros(n))
    r = ca.substitute(rest_bias, eom.q, qw)
    Mq = ca.substitute(eom.M, eom.q, qw)
    parts_ = [r]
    lam_scale = np.zeros(0)
    if con is not None:
        ga = ca.substitute(eom.g[list(con.active)], eom.q, qw)
        lam_scale = scale / con.row_norms
        lam = ca.SX(lam_scale) * w[n:n + ma]
        parts_ = [r - ca.mtimes(ca.jacobian(ga, qw).T, lam), ga / ca.SX(con.row_norms)]
    if k:
        parts_[0] = parts_[0] - ca.mtimes(Mq, ca.mtimes(N, alpha))
        parts_.append(ca.mtimes(N.T, qw - qr))
    for _, idx in blocks:       # unit quaternions: the norm is a constraint, |q| = 1
        parts_.append(ca.sumsqr(qw[idx]) - 1)
    r = ca.substitute(ca.vertcat(*parts_), eom.t, ca.SX(float(t)))
    args = [w, qr, eom.p]
    F = ca.Function("eq_res", args, [r])
    JF = ca.Function("eq_jac", args, [ca.jacobian(r, w)])
    rs = np.concatenate([st.scales(), np.ones(ma), np.full(k, scale), np.ones(len(blocks))])
    return F, JF, rs, lam_scale


def _solve(eom, st, con, blocks, F, JF, rs, x0, g, qref, pv, t, tol, search: Search):
    """Levenberg-Marquardt from x0 (the guess g): (q, the other unknowns, the largest force
    residual) of a solution, or None (no convergence, a residual above the per-coordinate
    tolerance, a run-away to where the force decayed, off the constraints, a gimbal-lock
    artefact); the search's counts updated."""
    n = eom.n
    fscales = st.scales()
    tols = 1e-8 * fscales           # per coordinate: a stiff spring elsewhere does not hide a force
    try:
        x = levenberg_marquardt(lambda x: dense(F(x, qref, pv)).ravel() / rs,
                                lambda x: dense(JF(x, qref, pv)) / rs[:, None], x0)
    except (ValueError, np.linalg.LinAlgError, FloatingPointError):
        return None
    if x is None:
        return None
    res = dense(F(x, qref, pv)).ravel()
    if not np.all(np.isfinite(res)):
        return None
    resid = float(np.max(np.abs(res[:n])))
    if np.any(np.abs(res[:n]) > tols):
        _note_failure(search, x[:n], g, float(np.max(np.abs(res[:n]) / fscales)))
        return None
    if _decayed(x, g, n, JF, qref, pv, st):
        search.runaway += 1
        return None
    search.converged += 1
    qs = x[:n].copy()
    if blocks:
        qs = charts.normalize_blocks(qs, blocks)
        x = np.concatenate([qs, x[n:]])
        resid = float(np.max(np.abs(dense(F(x, qref, pv)).ravel()[:n])))
    if con is not None and np.max(con.distances(qs), initial=0.0) > 1e-9 * (1.0 + np.max(np.abs(qs))):
        return None
    for i in range(n):
        if st.periodic[i]:
            qs[i] = wrap_angle(qs[i])
    if con is None and eom.singularity_monitors and _lock_artefact(eom, qs, t, pv, tol):
        return None
    qs[np.abs(qs) <= 1e-15 * (1.0 + np.max(np.abs(qs), initial=0.0))] = 0.0    # round-off, not a value
    return qs, x[n:].copy(), resid


def _keep(eom, st, blocks, F, qref, pv, t, tol, families, found: list, qs, rest, resid) -> None:
    """Add a solution to ``found`` unless it is one already there (then the one with the smaller
    residual stays): the same point, the same Euler-angle rotation, joined by a path of
    solutions, or one rotation family."""
    tols = 1e-8 * st.scales()
    for i, f_ in enumerate(found):
        if same_point(qs, f_[0], st.periodic, blocks) or euler_same(eom, qs, f_[0], st) or \
                joined(F, qref, pv, qs, f_[0], rest, f_[1], tols, st.periodic, blocks, families) or \
                (families and rotation_joined(eom, qs, f_[0], t, pv, tol)):
            if resid < f_[2]:
                found[i] = (qs, rest, resid)
            return
    found.append((qs, rest, resid))


def _lock_artefact(eom, q, t, pv, tol) -> bool:
    """q is at gimbal lock and only a critical point of the Euler angles: the same configuration
    in quaternions has a force at rest (dV/d(angles) = J' grad V vanishes where J loses rank)."""
    locked = charts.locked_joints(eom, q, t, pv)
    if not locked:
        return False
    base, to_new = charts.quaternion_model(eom, locked)
    _, bias = parts(base).M_bias(to_new(q), np.zeros(base.n), t, pv)
    return not np.max(np.abs(bias), initial=0.0) <= tol


def _decayed(x, g, n, JF, qref, pv, st) -> bool:
    """A run that went far out (RUNAWAY / 2) to where both the force and its derivative have decayed
    below tolerance (V0 exp(-x) at x = 34) found no equilibrium, only a vanishing force."""
    size = 1.0 + float(np.max(np.abs(g), initial=0.0))
    if float(np.max(np.abs(x[:n]), initial=0.0)) <= 0.5 * RUNAWAY * size:
        return False
    J = dense(JF(x, qref, pv))[:n, :n]
    return float(np.max(np.abs(J), initial=0.0)) <= 1e-8 * max(st.stiffness_scale, 1e-300)


def _note_failure(search: Search, q, g, rel_resid: float) -> None:
    size = 1.0 + float(np.max(np.abs(g), initial=0.0))
    if float(np.max(np.abs(q), initial=0.0)) > RUNAWAY * size:
        search.runaway += 1
    if rel_resid < search.best_residual:
        search.best_residual, search.best_q = rel_resid, np.asarray(q, float).copy()


def _clean(lam, lam_scale):
    """Multipliers whose force is below 1e-12 of the force scale are round-off: 0."""
    return np.where(np.abs(lam) <= 1e-12 * lam_scale, 0.0, lam)


def _start_multipliers(eom, con, q, t, pv, lam_scale) -> np.ndarray:
    """Scaled least-squares multipliers at a guess (the LM start for mu)."""
    if con is None:
        return np.zeros(0)

    _, bias = parts(eom).M_bias(q, np.zeros(eom.n), t, pv)
    lam = least_squares_multipliers(con, q, bias)
    out = lam / lam_scale
    return np.where(np.isfinite(out), out, 0.0)


# --------------------------------------------------------------------------- starting guesses

def parse_guesses(eom, guesses, q0: np.ndarray) -> list[np.ndarray]:
    """User guesses as full coordinate vectors (missing coordinates from the start values)."""
    if guesses is None:
        return []
    if isinstance(guesses, dict):
        guesses = [guesses]
    if isinstance(guesses, np.ndarray):
        guesses = [guesses] if guesses.ndim == 1 else list(guesses)
    out = []
    for g in guesses:
        if isinstance(g, dict):
            v = q0.copy()
            for name, val in g.items():
                if name not in eom.coords:
                    hint = did_you_mean(name, eom.coords)
                    raise UsageError(f"guess for unknown coordinate {name!r}" + (f"; {hint}" if hint else ""))
                v[eom.coords.index(name)] = float(val)
            out.append(v)
        else:
            v = np.asarray(g, float).ravel()
            if v.size != eom.n:
                raise UsageError(f"a guess needs {eom.n} coordinate values, got {v.size}")
            out.append(v)
    return out


def _guesses(eom, guesses, q0, st, max_guesses, con=None):
    user = parse_guesses(eom, guesses, q0)
    n = eom.n
    N = st.symmetry
    P = N @ N.T if N.size else np.zeros((n, n))
    qc = q0 if con is None else con.q_start

    def axis(i):
        e = np.zeros(n)
        e[i] = 1.0
        if np.linalg.norm(P @ e - e) < 1e-8:            # coordinate is a symmetry direction: pinned
            return [qc[i]]
        if st.angles[i]:
            return [-math.pi + 2 * math.pi * j / GRID_ANGLES for j in range(GRID_ANGLES)]
        s = max(1.0, abs(qc[i]))
        return sorted({qc[i], qc[i] - 0.5 * s, qc[i] + 0.5 * s, qc[i] - 2 * s, qc[i] + 2 * s, 0.0})

    if con is not None:
        return constrained_guesses(con, user, st, axis, max_guesses)
    axes = [axis(i) for i in range(n)]
    size = math.prod(len(a) for a in axes)
    spread = []
    if size <= max_guesses:
        spread = [np.array(c, float) for c in itertools.product(*axes)]
    else:
        lo = np.array([min(a) for a in axes])
        hi = np.array([max(a) for a in axes])
        for j in range(max_guesses):
            spread.append(lo + (hi - lo) * halton(j + 1, n))
    return user + [q0.copy()] + spread


def nearest_equilibrium(eom, guesses, t, pv, q0, notes: list, other: str):
    """The equilibrium nearest to the first guess (without guesses: to q0; angles compared
    modulo 2 pi), noted when there are several; E903 saying why and with the hint `other` when
    there is none."""
    eqs = equilibria(eom, guesses, t=t, p=pv)
    if not eqs:
        why = eqs.search.why_none(eom.coords)
        raise MechError(Diagnostic("E903", f"no equilibrium of '{eom.name}' was found" + (f": {why}" if why else ""),
                                   help=f"{other}; a steady motion (a circular orbit, a spinning top) is a "
                                        "relative equilibrium, not a rest state: linearize about a state on "
                                        "it with --at NAME=VALUE,der(NAME)=SPEED; or give a starting guess "
                                        "(--guess NAME=VALUE)"))
    periodic = structure(eom, pv).periodic
    user = parse_guesses(eom, guesses, q0)
    target, what = (user[0], "the guess") if user else (q0, "the start values")
    eq = min(eqs, key=lambda e: distance(e.q, target, periodic))
    if len(eqs) > 1:
        notes.append(f"{len(eqs)} equilibria found; linearized about the one nearest to {what}: "
                     + ", ".join(f"{c} = {v:.6g}" for c, v in eq.values.items()))
    return eq

