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

Solutions come from Levenberg-Marquardt (scipy least_squares with the CasADi Jacobian) started
at the user's guesses and a deterministic spread (angles on a grid over [-pi, pi)).  Distinct
solutions are kept (angles compared modulo 2 pi) and classified by the Hessian K of the
(effective) potential in the directions transverse to N, with the linearized eigenvalues as the
second witness (Lyapunov's indirect method).
"""
from __future__ import annotations

import itertools
import math
from dataclasses import dataclass, field

import numpy as np

from ..diagnostics import Diagnostic, MechError, UsageError, did_you_mean
from ..eom import fold_inputs, multiplier_units
from ..model.units import coordinate_units, matrix_units
from ..output import display as _display
from . import charts
from .charts import chart, locked_joints, quaternion_blocks, quaternion_model
from .charts import tangent_basis as zbasis
from .constraints import constrained, least_squares_multipliers, setup, tangent_basis
from .contacts_at_rest import contact_notes
from .core import dense, named_multipliers, null_space, param_vector, parts, structure, wrap_angle
from .manifold import guesses as constrained_guesses
from .matrices import complement, reduced_first_order, second_order, sym
from .sampling import halton


MAX_GUESSES = 256
GRID_ANGLES = 8          # grid points per angle coordinate over [-pi, pi)


@dataclass
class Equilibrium:
    """One equilibrium: coordinate values, kind, stability and the eigenvalues that decide it.

    kind: 'static' (scleronomic), 'relative' (steady moving frame, V_eff = V - T0),
    'accelerated-reference' (relative equilibrium about a uniformly accelerated motion whose
    acceleration is ``acceleration``).
    ``hessian_eigenvalues``: eigenvalues of the stiffness K (Hessian of the effective potential)
    transverse to the symmetry directions (``symmetry_directions``), ascending.  Constrained
    models: K is the Hessian of V + lambda'g and the eigenvalues are those of its restriction
    to the tangent space of the constraints (``tangent_basis``); ``multipliers`` / ``lambdas``
    are the constraint forces at rest.
    """

    coords: tuple[str, ...]
    q: np.ndarray
    stable: bool | None
    hessian_eigenvalues: np.ndarray
    kind: str = "static"
    residual: float = 0.0
    reason: str = ""
    hessian: np.ndarray | None = None
    acceleration: np.ndarray | None = None
    linear_eigenvalues: np.ndarray | None = None
    symmetry_directions: np.ndarray | None = None
    t: float = 0.0
    notes: list[str] = field(default_factory=list)
    # constrained models: multipliers of every constraint (0 for dropped redundant ones), the
    # constraints that were kept, and the orthonormal basis Z of the tangent space the
    # classification used (hessian_eigenvalues are those of Z'(K + sum lambda_l d2g_l/dq2)Z)
    multipliers: np.ndarray | None = None
    constraint_names: tuple[str, ...] = ()
    active_constraints: tuple[str, ...] = ()
    # the unit of each multiplier (eom.multiplier_units: N, N.m, N/m, ...; None: unknown)
    multiplier_units: tuple = ()
    tangent_basis: np.ndarray | None = None
    admissible: bool = True          # False: the state penetrates one of the model's contacts (notes)
    # rotation joints: the classification was made in a chart (analysis.charts) whose
    # coordinates are these; hessian, symmetry_directions and the eigenvalues refer to them
    chart_coords: tuple[str, ...] = ()

    @property
    def lambdas(self) -> dict[str, float]:
        """Multipliers by constraint name (empty for unconstrained models), unscaled, each in its
        unit (``multiplier_units``; docs/constraints.md)."""
        return named_multipliers(self.constraint_names, self.multipliers)

    @property
    def lambda_units(self) -> dict[str, str | None]:
        """The unit of each multiplier, by constraint name."""
        return dict(zip(self.constraint_names, self.multiplier_units))

    @property
    def values(self) -> dict[str, float]:
        """The coordinates' values at the equilibrium, by name."""
        return {c: float(v) for c, v in zip(self.coords, self.q)}

    _repr_html_ = _display.equilibrium_html          # notebook displays (mechdsl.output.display)
    _repr_markdown_ = _display.equilibrium_markdown

    def __repr__(self) -> str:
        """One line: kind, stability and where (the HTML display and ``to_dict()`` hold the rest)."""
        where = ", ".join(f"{c} = {v:.6g}" for c, v in list(self.values.items())[:6])
        more = f", ... ({len(self.coords) - 6} more)" if len(self.coords) > 6 else ""
        return f"<Equilibrium {self.kind}, {self.stability}: {where}{more}>"

    @property
    def stability(self) -> str:
        """"stable", "unstable" or "undetermined" (``stable`` True, False or None; ``reason`` says why)."""
        return {True: "stable", False: "unstable", None: "undetermined"}[self.stable]

    def __getitem__(self, name: str) -> float:
        return self.values[name]

    def to_dict(self) -> dict:
        """Plain JSON types: kind, values, stability and reason, eigenvalues, Hessian, notes, ..."""
        d = {"kind": self.kind, "values": self.values, "stable": self.stable, "admissible": self.admissible,
             "stability": self.stability, "reason": self.reason,
             "hessian_eigenvalues": [float(v) for v in self.hessian_eigenvalues],
             "residual": float(self.residual), "t": float(self.t), "notes": list(self.notes)}
        if self.hessian is not None:
            d["hessian"] = self.hessian.tolist()
        if self.acceleration is not None:
            d["acceleration"] = {c: float(v) for c, v in zip(self.coords, self.acceleration)}
        if self.linear_eigenvalues is not None:
            d["linear_eigenvalues"] = [[float(v.real), float(v.imag)] for v in self.linear_eigenvalues]
        if self.symmetry_directions is not None and self.symmetry_directions.size:
            d["symmetry_directions"] = [{c: float(v) for c, v in zip(self.chart_coords or self.coords, col)}
                                        for col in self.symmetry_directions.T]
        if self.chart_coords:
            d["chart_coordinates"] = list(self.chart_coords)
        if self.multipliers is not None:
            d["multipliers"] = self.lambdas
            d["multiplier_units"] = self.lambda_units
            d["active_constraints"] = list(self.active_constraints)
            d["tangent_basis"] = [{c: float(v) for c, v in zip(self.coords, col)} for col in self.tangent_basis.T]
        return d


@dataclass
class Search:
    """How the search went, for saying why nothing was found: starting guesses tried, how many
    converged, the smallest force at rest reached (relative to the force scale) and where, and
    how many runs ran off to coordinates far beyond their start (a force that decays without
    vanishing, as a central attraction's)."""

    guesses: int = 0
    converged: int = 0
    best_residual: float = math.inf
    best_q: np.ndarray | None = None
    runaway: int = 0

    def why_none(self, coords) -> str:
        """The reason no equilibrium was found, in words (empty when nothing is known)."""
        if not self.guesses:
            return ""
        out = f"none of {self.guesses} starting guesses converged"
        if self.best_q is not None and math.isfinite(self.best_residual):
            where = ", ".join(f"{c} = {v:.4g}" for c, v in zip(coords, self.best_q))
            out += (f"; the smallest force at rest reached was {self.best_residual:.3g} of the force "
                    f"scale (at {where})")
        if self.runaway:
            out += (f"; {self.runaway} of the searches ran off to coordinates more than {RUNAWAY:g} times "
                    "farther out than their start: the force at rest decays without vanishing, so the model "
                    "has no static equilibrium (a central attraction, e.g. the Kepler problem, has none: "
                    "bodies released at rest fall towards each other)")
        return out


class Equilibria(list):
    """The equilibria found (a list of :class:`Equilibrium`) with ``search``, a :class:`Search`, and
    ``notes`` on the search as a whole (contacts that are not equilibrium conditions)."""

    search: Search
    notes: list


def equilibria(eom, guesses=None, *, t: float = 0.0, p=None, max_guesses: int = MAX_GUESSES
               ) -> Equilibria:
    """Distinct equilibria of the model, each classified (see the module docstring).

    guesses: None, a dict {coordinate: value} (missing coordinates take their start values),
    a list of such dicts, or arrays of shape (n,) / (k, n).  p: parameter overrides.
    Constrained models (scleronomic constraints g(q) = 0): see :mod:`.constraints`; each
    equilibrium carries its multipliers.
    """
    eom = fold_inputs(eom)          # inputs held at their defaults: trailing parameters
    import casadi as ca

    pv = param_vector(eom, p)
    n = eom.n
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
        e = _classify(eom, st, pv, qref, np.zeros(k), t, 0.0, notes + ["no generalized force acts at rest: "
                                                                       "every configuration is an equilibrium"],
                      con=con, lam=np.zeros(ma))
        return _result([e], Search(), contact_notes(eom, [e], pv, t))

    # unknowns w = (q, mu, alpha), lambda = lam_scale * mu:
    # bias(q, 0, t) - G(q)' lambda - M(q) N alpha ; g(q) / |G row| ; N'(q - q_ref)
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
    fscales = st.scales()
    rs = np.concatenate([fscales, np.ones(ma), np.full(k, scale), np.ones(len(blocks))])

    tol = 1e-8 * scale
    tols = 1e-8 * fscales           # per coordinate: a stiff spring elsewhere does not hide a force
    found: list[tuple[np.ndarray, np.ndarray, float]] = []
    search = Search()
    # rotation joints: solutions on one continuous family (a top turned about the vertical) merge
    families = con is None
    for g in _guesses(eom, guesses, q0, st, max_guesses, con):
        if blocks:
            g = charts.normalize_blocks(g, blocks, fallback=q0)
        search.guesses += 1
        x0 = np.concatenate([g, _start_multipliers(eom, con, g, t, pv, lam_scale), np.zeros(k)])
        try:
            x = levenberg_marquardt(lambda x: dense(F(x, qref, pv)).ravel() / rs,
                                    lambda x: dense(JF(x, qref, pv)) / rs[:, None], x0)
        except (ValueError, np.linalg.LinAlgError, FloatingPointError):
            continue
        if x is None:
            continue
        res = dense(F(x, qref, pv)).ravel()
        if not np.all(np.isfinite(res)):
            continue
        resid = float(np.max(np.abs(res[:n])))
        if np.any(np.abs(res[:n]) > tols):
            _note_failure(search, x[:n], g, float(np.max(np.abs(res[:n]) / fscales)))
            continue
        if _decayed(x, g, n, JF, qref, pv, st):
            search.runaway += 1
            continue
        search.converged += 1
        qs = x[:n].copy()
        if blocks:
            qs = charts.normalize_blocks(qs, blocks)
            x = np.concatenate([qs, x[n:]])
            resid = float(np.max(np.abs(dense(F(x, qref, pv)).ravel()[:n])))
        if con is not None and np.max(con.distances(qs), initial=0.0) > 1e-9 * (1.0 + np.max(np.abs(qs))):
            continue
        for i in range(n):
            if st.periodic[i]:
                qs[i] = wrap_angle(qs[i])
        if con is None and eom.singularity_monitors and _lock_artefact(eom, qs, t, pv, tol):
            continue
        qs[np.abs(qs) <= 1e-15 * (1.0 + np.max(np.abs(qs), initial=0.0))] = 0.0    # round-off, not a value
        for i, f_ in enumerate(found):
            if _same(qs, f_[0], st.periodic, blocks) or _euler_same(eom, qs, f_[0], st) or \
                    _joined(F, qref, pv, qs, f_[0], x[n:], f_[1], tols, st.periodic, blocks, families) or \
                    (families and _rotation_joined(eom, qs, f_[0], t, pv, tol)):
                if resid < f_[2]:
                    found[i] = (qs, x[n:].copy(), resid)
                break
        else:
            found.append((qs, x[n:].copy(), resid))

    found.sort(key=lambda f_: tuple(np.round(f_[0], 9)))
    out = []
    for qs, rest, resid in found:
        locked = charts.locked_joints(eom, qs, t, pv) if con is None else []
        if blocks or locked:
            e = _classify_in_chart(eom, st, pv, qs, rest[ma:], t, resid, list(notes), blocks, locked)
            if e is not None:       # None: a critical point of the Euler chart only (gimbal lock)
                out.append(e)
        elif families:
            st_f, a_f, more = _with_families(eom, st, pv, qs, t, rest[ma:])
            out.append(_classify(eom, st_f, pv, qs, a_f, t, resid, list(notes) + more))
        else:
            out.append(_classify(eom, st, pv, qs, rest[ma:], t, resid, list(notes), con=con,
                                 lam=_clean(lam_scale * rest[:ma], lam_scale)))
    return _result(out, search, contact_notes(eom, out, pv, t))


def chart_of(eom, q, t, pv):
    """(EOM in the chart about q, its structure, chart reference point, basis Z with dq = Z dz
    in the coordinates of the chart's EOM, the EOM the chart belongs to, notes) for a model with
    quaternion joints or Euler angles at gimbal lock; None for a regular point of ordinary
    coordinates."""
    blocks = quaternion_blocks(eom)
    locked = locked_joints(eom, q, t, pv) if not constrained(eom) else []
    if not blocks and not locked:
        return None
    notes = []
    base, qb = eom, np.asarray(q, float)
    if locked:
        base, to_new = quaternion_model(eom, locked)
        qb = to_new(qb)
        blocks = quaternion_blocks(base)
        notes.append(f"the Euler angles of {', '.join(locked)} are at gimbal lock here: analysed in a "
                     "quaternion chart instead (rotation vectors <joint>.rx, .ry, .rz in child axes)")
    else:
        notes.append("quaternion joint(s): analysed in the tangent space of the unit quaternion(s) "
                     "(rotation vectors <joint>.rx, .ry, .rz in child axes)")
    ch = chart(base, qb)
    st0 = structure(base, pv)
    keep = [i for i in range(base.n) if not any(i in idx for _, idx in blocks)]
    N = st0.symmetry
    cols = [c for c in N.T if np.max(np.abs(np.delete(c, keep)), initial=0.0) <= 1e-12]
    Z = zbasis(qb, blocks, base.n)
    Nc = np.array([Z.T @ c for c in cols]).T if cols else np.zeros((ch.n, 0))
    per = [False] * ch.n
    ang = [False] * ch.n
    j = 0
    for i in range(base.n):
        if i in keep:
            per[j], ang[j] = st0.periodic[i], st0.angle_unit[i]
            j += 1
        elif any(i == idx[0] for _, idx in blocks):
            j += 3
    import dataclasses

    st = dataclasses.replace(st0, n=ch.n, periodic=tuple(per), angle_unit=tuple(ang), symmetry=Nc)
    return ch, st, qb, Z, base, notes


def _lock_artefact(eom, q, t, pv, tol) -> bool:
    """q is at gimbal lock and only a critical point of the Euler angles: the same configuration
    in quaternions has a force at rest (dV/d(angles) = J' grad V vanishes where J loses rank)."""
    locked = charts.locked_joints(eom, q, t, pv)
    if not locked:
        return False
    base, to_new = charts.quaternion_model(eom, locked)
    _, bias = parts(base).M_bias(to_new(q), np.zeros(base.n), t, pv)
    return not np.max(np.abs(bias), initial=0.0) <= tol


def _classify_in_chart(eom, st, pv, qs, alpha, t, resid, notes, blocks, locked) -> Equilibrium:
    """Classification in the chart of :func:`chart_of`; continuous families of equilibria
    through the point (a top's rotation about the vertical) are neutral directions, like
    symmetry directions."""
    ch, stc, qb, Z, base, more = chart_of(eom, qs, t, pv)
    nz = ch.n
    k = stc.symmetry.shape[1]
    if locked and not k:
        # at gimbal lock dV/d(angles) = J' grad V vanishes where J loses rank: a point that is
        # no equilibrium in a regular chart is an artefact of the Euler angles
        _, bias = parts(ch).M_bias(np.zeros(nz), np.zeros(nz), t, pv)
        if np.max(np.abs(bias), initial=0.0) > 1e-8 * max(st.force_scale, 1e-300):
            return None
    a = np.zeros(k)
    if k and len(alpha) == st.symmetry.shape[1]:
        a = np.linalg.lstsq(stc.symmetry, Z.T @ (st.symmetry @ alpha) if base is eom else np.zeros(nz),
                            rcond=None)[0]
    stc, a, fam_notes = _with_families(ch, stc, pv, np.zeros(nz), t, a)
    e = _classify(ch, stc, pv, np.zeros(nz), a, t, resid, notes + more + fam_notes)
    e.coords, e.q, e.chart_coords = tuple(eom.coords), np.asarray(qs, float), tuple(ch.coords)
    e.tangent_basis = Z if base is eom else None
    e.acceleration = np.zeros(eom.n) if not k else (st.symmetry @ alpha)
    return e


def _with_families(eom, st, pv, q, t, alpha):
    """(structure, alpha, notes) with the directions along a continuous family of equilibria
    through q added to the symmetry directions (neutral)."""
    import dataclasses

    fam = _family_directions(eom, st, pv, t, alpha, q)
    if not fam.shape[1]:
        return st, alpha, []
    Nold = st.symmetry
    k = Nold.shape[1]
    Nall = np.linalg.qr(np.hstack([Nold, fam]))[0] if k else fam
    a = np.linalg.lstsq(Nall, Nold @ alpha, rcond=None)[0] if k else np.zeros(Nall.shape[1])
    return (dataclasses.replace(st, symmetry=Nall), a,
            [f"{fam.shape[1]} direction(s) along a continuous family of equilibria through this point: neutral"])


def _family_directions(ch, st, pv, t, alpha, q=None) -> np.ndarray:
    """Orthonormal directions v of zero stiffness (transverse to the symmetry directions) along
    which the point q (default 0: a chart's centre) continues as a curve of equilibria: from
    q + s v (s = 0.2) Levenberg-Marquardt with the gauge v'(z - q) = s converges to an
    equilibrium.  Not for accelerated references."""
    import casadi as ca

    n = ch.n
    q = np.zeros(n) if q is None else np.asarray(q, float)
    N = st.symmetry
    M, C, K, _, _ = second_order(ch, q, np.zeros(n), t, pv, acc=np.zeros(n))
    # an accelerated reference motion (round-off in alpha is not one: as _classify decides)
    if N.size and np.linalg.norm(M @ (N @ np.asarray(alpha, float))) > 1e-8 * max(st.force_scale, 1e-300):
        return np.zeros((n, 0))
    P = complement(N)
    Kr = sym(P.T @ K @ P)
    if not Kr.size:
        return np.zeros((n, 0))
    w, V = np.linalg.eigh(Kr)
    kscale = max(np.max(np.abs(K), initial=0.0), st.stiffness_scale, 1e-300)
    null = [P @ V[:, i] for i in range(len(w)) if abs(w[i]) <= 1e-9 * kscale]
    if not null:
        return np.zeros((n, 0))
    scale = max(st.force_scale, 1e-300)
    z = ca.SX.sym("z", n)
    rest = ca.substitute(ca.substitute(ch.bias, ch.qd, ca.SX.zeros(n)), ch.t, ca.SX(float(t)))
    f = ca.Function("fam", [z, ch.p], [ca.substitute(rest, ch.q, z)])
    keep = []
    for v in null:
        s = 0.2
        vv = ca.DM(v)
        r = ca.vertcat(ca.substitute(rest, ch.q, z) / scale, ca.mtimes(vv.T, z - ca.DM(q)) - s)
        F = ca.Function("famr", [z, ch.p], [r])
        JF = ca.Function("famj", [z, ch.p], [ca.jacobian(r, z)])
        try:
            x = levenberg_marquardt(lambda x: dense(F(x, pv)).ravel(), lambda x: dense(JF(x, pv)), q + s * v)
        except (ValueError, np.linalg.LinAlgError, FloatingPointError):
            x = None
        if x is None:
            continue
        res = dense(f(x, pv)).ravel()
        if np.all(np.isfinite(res)) and np.max(np.abs(res), initial=0.0) <= 1e-8 * scale \
                and abs(float(v @ (x - q)) - s) <= 1e-6:
            keep.append(v)
    if not keep:
        return np.zeros((n, 0))
    Q = np.linalg.qr(np.array(keep).T)[0]
    return Q


def _result(eqs, search: Search, notes=()) -> Equilibria:
    out = Equilibria(eqs)
    out.search = search
    out.notes = list(notes)
    return out


RUNAWAY = 10.0           # a failed run that ends this many times farther out than its start ran away


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


def _same(a: np.ndarray, b: np.ndarray, periodic, blocks=()) -> bool:
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


def _euler_same(eom, a, b, st) -> bool:
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


def _rotation_joined(eom, a, b, t, pv, tol) -> bool:
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


def _joined(F, q0, pv, a, b, alpha_a, alpha_b, tol, periodic, blocks=(), families=False) -> bool:
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


def _classify(eom, st, pv, q, alpha, t, resid, notes, con=None, lam=None) -> Equilibrium:
    """Kind and stability.  Constrained models: K is the Hessian of V + lambda'g (the geometric
    stiffness of the constraint forces added) and everything is decided on the tangent space
    of the constraints (coordinates dq = Z dz, Z an orthonormal basis of null(G))."""
    n = eom.n
    N = st.symmetry
    k = N.shape[1]
    acc = N @ alpha if k else np.zeros(n)
    M, C, K, _, _ = second_order(eom, q, np.zeros(n), t, pv, acc=acc)
    if k and np.linalg.norm(M @ acc) <= 1e-8 * max(st.force_scale, 1e-300) and np.any(acc):
        # no force along N: alpha is arbitrary where N carries no inertia; the reference is at rest
        acc = np.zeros(n)
        M, C, K, _, _ = second_order(eom, q, np.zeros(n), t, pv, acc=acc)
    Z = None
    Kabs = np.abs(K)             # the sizes of the terms K adds up: what an eigenvalue is resolved against
    if con is not None:
        Kg = con.geometric_stiffness(q, lam)
        Kabs = Kabs + np.abs(Kg)
        K = K + Kg
        Z = tangent_basis(con.G_active(q))
        Mt, Ct, Kt, Nt = Z.T @ M @ Z, Z.T @ C @ Z, Z.T @ K @ Z, Z.T @ N
    else:
        Mt, Ct, Kt, Nt = M, C, K, N
    R = active_basis(Mt, Ct, Kt)
    Mt, Ct, Kt, Nt, inert = drop_inert(Mt, Ct, Kt, Nt)
    if inert:
        notes = notes + [f"{inert} direction(s) carry neither inertia nor force here (the spin of a point "
                         "mass about its own axis): left out"]
    P = complement(Nt)
    Kr = P.T @ Kt @ P
    accel = bool(k) and np.linalg.norm(M @ acc) > 1e-8 * max(st.force_scale, 1e-300)
    if accel:
        kind = "accelerated-reference"
    elif st.scleronomic:
        kind = "static"
    else:
        kind = "relative"
    Ksym = sym(Kr)
    heig, vecs = np.linalg.eigh(Ksym) if Kr.size else (np.zeros(0), np.zeros((0, 0)))
    kscale = max(np.max(np.abs(K), initial=0.0), st.stiffness_scale, 1e-300)
    if con is not None:      # the geometric stiffness is of the order force scale x curvature
        kscale = max(kscale, st.force_scale * con.curvature_scale(q))
    circulatory = np.max(np.abs(Kt - Kt.T), initial=0.0) > 1e-7 * kscale
    massless = singular_mass(Mt)
    A = reduced_first_order(Mt, Ct, Kt, Nt) if not massless else np.zeros((0, 0))
    ev = np.linalg.eigvals(A) if A.size else np.zeros(0, complex)
    ev = ev[np.lexsort((ev.imag, ev.real))]
    lscale = max(1.0, np.max(np.abs(ev), initial=0.0))
    growth = float(np.max(ev.real, initial=-np.inf)) if ev.size else -np.inf
    # each eigenvalue against the terms along its own direction u (full coordinates): |u|'|K||u|,
    # so that 5.96 beside a spring of 1e12 N/m is resolved (issue 23: a global 1e-9 x max|K| called
    # it zero); a floor at round-off of the largest terms anywhere
    B = (Z if Z is not None else np.eye(n)) @ (R if R is not None else np.eye(Kt.shape[0] + inert)) @ P
    U = np.abs(B @ vecs) if vecs.size else np.zeros((n, 0))
    etol = 1e-9 * np.einsum("ij,ik,kj->j", U, Kabs, U) + 1e-13 * kscale if heig.size else np.zeros(0)
    Csym = sym(Ct)
    gyro = np.max(np.abs(Ct - Ct.T), initial=0.0) > 1e-9 * max(np.max(np.abs(Ct), initial=0.0), 1e-300)
    damping_ok = np.min(np.linalg.eigvalsh(Csym), initial=0.0) >= -1e-9 * max(np.max(np.abs(Ct), initial=0.0), 1e-300)
    # the Hessian's eigenvalues have K's unit when every coordinate has the same unit
    hu = _unit_suffix(matrix_units(coordinate_units(eom)).get("K", ""))
    potential = "V - T0" if st.has_T0 else "V"
    if con is not None:
        potential += " + lambda'g on the constraint manifold"
    singular = con is not None and Z.shape[1] != n - con.ma
    if singular:
        notes = notes + ["singular configuration: the active constraints lose rank here, so the "
                         "multipliers are not unique"]

    if not st.autonomous:
        stable, reason = None, "explicitly time-dependent equations: stability is not decided here"
    elif massless:
        stable, reason = None, (f"the mass matrix is singular here ({massless}) while forces act in that "
                                "direction: the equations of motion do not determine the motion, stability "
                                "is not decided")
    elif singular:
        stable, reason = None, "singular configuration of the constraints: stability is not decided here"
    elif growth > 1e-6 * lscale:
        i = int(np.argmax(ev.real))
        neg = heig[heig < -etol]
        why = (f"Hessian of {potential} has negative eigenvalue(s) {_fmt_list(neg)}{hu}; " if neg.size else "")
        stable, reason = False, (why + f"linearization has eigenvalue {_fmt_c(ev[i])} 1/s with positive "
                                       "real part (Lyapunov's indirect method)")
    elif circulatory:
        stable, reason = None, ("non-conservative positional (circulatory) forces: the stiffness is not "
                                "symmetric, Lagrange-Dirichlet does not apply; linear model has no growing mode")
    elif heig.size and np.all(heig > etol) and damping_ok:
        stable, reason = True, (f"Lagrange-Dirichlet: Hessian of {potential} positive definite "
                                f"(eigenvalues {_fmt_list(heig)}{hu})")
        if k:
            reason += "; neutral along the symmetry directions"
    elif heig.size and np.any(heig < -etol):
        stable, reason = None, (f"Hessian of {potential} has negative eigenvalue(s) "
                                f"{_fmt_list(heig[heig < -etol])}{hu} but gyroscopic terms keep the linear "
                                "model bounded (gyroscopic stabilization): nonlinear stability undetermined")
    elif heig.size == 0 and con is not None and Z.shape[1] == 0:
        stable, reason = None, "no degree of freedom: the constraints fix the configuration"
    elif heig.size == 0:
        stable, reason = None, "no coordinate transverse to the symmetry directions: nothing to decide"
    elif np.any(np.abs(heig) <= etol):
        stable, reason = None, (f"zero eigenvalue(s) of the Hessian of {potential} "
                                f"({_fmt_list(heig[np.abs(heig) <= etol])}{hu}): higher-order terms decide")
    else:
        stable, reason = None, (f"Hessian of {potential} positive definite (eigenvalues {_fmt_list(heig)}) but "
                                "the damping matrix is not positive semidefinite (a force that feeds energy in "
                                "at some speeds): Lagrange-Dirichlet does not apply, and the linear model has no "
                                "growing mode; stability is not decided")
    if gyro and stable is not None:
        notes = notes + ["gyroscopic terms present (T1 != 0)"]
    if accel:
        notes = notes + ["uniformly accelerated reference motion q(t) = q* + a t^2/2 with acceleration a = "
                         + ", ".join(f"{c}: {v:.6g}" + _unit_suffix(u and u + "/s2")
                                     for c, v, u in zip(eom.coords, acc, coordinate_units(eom)) if abs(v) > 0)]
    extra = {}
    if con is not None:
        extra = dict(multipliers=con.full_multipliers(lam), constraint_names=tuple(eom.constraint_names),
                     multiplier_units=multiplier_units(eom),
                     active_constraints=tuple(eom.constraint_names[i] for i in con.active), tangent_basis=Z)
    return Equilibrium(coords=tuple(eom.coords), q=np.asarray(q, float), stable=stable,
                       hessian_eigenvalues=heig, kind=kind, residual=resid, reason=reason, hessian=K,
                       acceleration=acc if k else np.zeros(n), linear_eigenvalues=ev,
                       symmetry_directions=N if k else None, t=float(t), notes=list(notes), **extra)


def drop_inert(M, C, K, N):
    """Leave out the directions that carry neither inertia nor force (M v = 0, K v = K'v = 0,
    C v = C'v = 0: a point mass spinning about its own axis); (M, C, K, N, count) in an
    orthonormal basis of the rest."""
    R = active_basis(M, C, K)
    if R is None:
        return M, C, K, N, 0
    Nr = R.T @ N
    if Nr.size:
        U, sv, _ = np.linalg.svd(Nr, full_matrices=False)
        Nr = U[:, sv > 1e-8]
    return R.T @ M @ R, R.T @ C @ R, R.T @ K @ R, Nr, M.shape[0] - R.shape[1]


def active_basis(M, C, K):
    """Orthonormal basis of the complement of the directions without inertia or force (None
    when there are none); columns that are coordinate axes are kept exactly."""
    n = M.shape[0]
    if n == 0:
        return None

    scale = max(np.max(np.abs(M), initial=0.0), 1e-300)
    ks = max(np.max(np.abs(K), initial=0.0), np.max(np.abs(C), initial=0.0), 1e-300)
    J = np.vstack([M / scale, K / ks, K.T / ks, C / ks, C.T / ks])
    inert = null_space(J, rel=1e-10)
    if inert.shape[1] == 0:
        return None
    R = complement(inert)
    R[np.abs(R) <= 1e-12] = 0.0
    return R


def singular_mass(M) -> str:
    """'' when M is invertible, else a description of its null direction."""
    if M.size == 0:
        return ""
    w, V = np.linalg.eigh(sym(M))
    if w[0] > 1e-12 * max(abs(w[-1]), 1e-300):
        return ""
    return f"smallest eigenvalue {w[0]:.3g} of {w[-1]:.3g}"


def _unit_suffix(unit: str) -> str:
    return f" {unit}" if unit else ""


def _fmt_list(v) -> str:
    return "[" + ", ".join(f"{x:.6g}" for x in v) + "]"


def _fmt_c(z: complex) -> str:
    return f"{z.real:.6g}" if abs(z.imag) < 1e-12 * max(1.0, abs(z)) else f"{z.real:.6g}{z.imag:+.6g}i"


def levenberg_marquardt(f, jac, x0, max_iter: int = 200, tol: float = 1e-15):
    """Minimize |f(x)|^2 (Levenberg-Marquardt with Nielsen's damping update); None if f is not finite."""
    x = np.asarray(x0, float).copy()
    with np.errstate(all="ignore"):
        r = f(x)
        if not np.all(np.isfinite(r)):
            return None
        J = jac(x)
        A, g = J.T @ J, J.T @ r
        mu = 1e-3 * max(np.max(np.diag(A), initial=0.0), 1e-12)
        nu = 2.0
        cost = r @ r
        for _ in range(max_iter):
            if cost <= 1e-32 or np.max(np.abs(g), initial=0.0) <= 1e-30:
                break
            step = np.linalg.solve(A + mu * np.eye(len(x)), -g)
            if not np.all(np.isfinite(step)):
                return None
            xn = x + step
            rn = f(xn)
            cn = rn @ rn if np.all(np.isfinite(rn)) else np.inf
            pred = -(step @ g) * 0.5 + 0.5 * mu * (step @ step)     # predicted decrease / 1
            rho = (cost - cn) / max(pred * 2.0, 1e-300) if np.isfinite(cn) else -1.0
            if rho > 0:
                x, r, cost = xn, rn, cn
                J = jac(x)
                A, g = J.T @ J, J.T @ r
                mu *= max(1.0 / 3.0, 1.0 - (2.0 * rho - 1.0) ** 3)
                nu = 2.0
                if np.max(np.abs(step), initial=0.0) <= tol * (1.0 + np.max(np.abs(x), initial=0.0)):
                    break
            else:
                mu *= nu
                nu *= 2.0
                if mu > 1e30:
                    break
    return x


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
    eq = min(eqs, key=lambda e: _distance(e.q, target, periodic))
    if len(eqs) > 1:
        notes.append(f"{len(eqs)} equilibria found; linearized about the one nearest to {what}: "
                     + ", ".join(f"{c} = {v:.6g}" for c, v in eq.values.items()))
    return eq


def _distance(a, b, periodic) -> float:
    d = 0.0
    for x, y, per in zip(a, b, periodic):
        z = wrap_angle(x - y) if per else x - y
        d += z * z
    return d
