"""Consistent initialization of a constrained model.

The start values (q0, q0') come from the model; those marked fixed (``EOM.fixed_q`` /
``EOM.fixed_qd``) are held, the others are changed as little as possible so that

    g(q, t0) = 0          (Gauss-Newton with minimum-norm steps on the free coordinates)
    G q' + g_t = 0        (one minimum-norm linear least-squares solve on the free speeds)

"As little as possible" is measured in the mass metric (coordinate i weighted by
sqrt(M_ii)), so the result does not depend on units.  Every changed value is reported
(:class:`InitReport`); a start the constraints cannot meet raises a MechError that names
the violated constraints (E821 positions, E822 velocities).

Feasibility is judged per constraint by its distance to the surface in coordinate space,
|g_i| / ||dg_i/dq||, against ``tol * (1 + ||q||_inf)`` (default tol = 1e-10).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..diagnostics import Diagnostic, MechError, Span
from ..eom import EOM
from .dof import dof_report


CODE_POSITION = "E821"
CODE_VELOCITY = "E822"
CODE_UNDEFINED = "E826"       # a constraint or its Jacobian is inf/nan at the start values


@dataclass
class InitChange:
    name: str
    kind: str          # 'start' (position) | 'speed' (velocity)
    before: float
    after: float

    @property
    def change(self) -> float:
        return self.after - self.before

    def __str__(self) -> str:
        what = self.name if self.kind == "start" else f"der({self.name})"
        return f"{what}: {self.before:.12g} -> {self.after:.12g} (changed by {self.change:+.3g})"


@dataclass
class InitReport:
    q: np.ndarray
    qd: np.ndarray
    changes: list[InitChange] = field(default_factory=list)
    position_residual: float = 0.0     # max |g| after initialization
    velocity_residual: float = 0.0     # max |G q' + g_t| after initialization
    iterations: int = 0
    free_positions: tuple[str, ...] = ()
    free_speeds: tuple[str, ...] = ()

    def lines(self) -> list[str]:
        if not self.changes:
            return ["initial values are consistent with the constraints (nothing changed)"]
        return ["consistent initialization changed:"] + [f"  {c}" for c in self.changes]

    def as_dict(self) -> dict:
        return {"changes": [{"name": c.name, "kind": c.kind, "before": c.before, "after": c.after,
                             "change": c.change} for c in self.changes],
                "position_residual": self.position_residual, "velocity_residual": self.velocity_residual,
                "iterations": self.iterations, "free_positions": list(self.free_positions),
                "free_speeds": list(self.free_speeds)}


def _functions(eom: EOM):
    return eom.workspace.memo("init_functions", lambda: _build_functions(eom))


def _build_functions(eom: EOM):
    import casadi as ca

    G = ca.jacobian(eom.g, eom.q)
    return (ca.Function("g", [eom.q, eom.t, eom.p], [eom.g]),
            ca.Function("G", [eom.q, eom.t, eom.p], [G]),
            ca.Function("gt", [eom.q, eom.t, eom.p], [ca.jacobian(eom.g, eom.t)]),
            ca.Function("M", [eom.q, eom.t, eom.p], [eom.M]))


def _flags(flags, n, default=True):
    flags = tuple(flags)
    return flags if len(flags) == n else (default,) * n


def constraint_labels(eom: EOM) -> list[str]:
    """'name' or 'name' (doc) for each constraint: explicit constraint equations of a .mech
    model are named after their description (else c1, c2, ...) and carry their text or
    documentation string, shown when it says more than the name."""
    docs = {}
    if eom.model is not None:
        docs = {c.name: c.doc for c in eom.model.constraints if c.doc and c.doc.replace(" ", "_") != c.name}
    return [f"'{n}' ({docs[n]})" if n in docs else f"'{n}'" for n in eom.constraint_names]


def _span(eom: EOM, index: int):
    """Source span of constraint `index` (an explicit equation) or of its loop's joint."""
    if eom.model is None:
        return Span()
    name = eom.constraint_names[index]
    for c in eom.model.constraints:
        if c.name == name:
            return c.span
    joint = name.split(".")[0]
    for j in eom.model.joints:
        if j.name == joint:
            return j.span
    return eom.model.span


def check_defined(eom: EOM, g: np.ndarray, G: np.ndarray, where: str = "at the start values") -> None:
    """A MechError (E826) naming the first constraint whose residual or gradient is inf/nan."""
    bad = [i for i in range(len(g)) if not (np.isfinite(g[i]) and np.all(np.isfinite(G[i])))]
    if bad:
        labels = constraint_labels(eom)
        i = bad[0]
        what = "residual" if not np.isfinite(g[i]) else "gradient"
        raise MechError(Diagnostic(
            CODE_UNDEFINED,
            f"the constraint {labels[i]} is not defined {where}: its {what} is "
            f"{'nan' if np.any(np.isnan(np.r_[g[i], G[i]])) else 'infinite'}"
            + (f" (also {', '.join(labels[j] for j in bad[1:4])})" if len(bad) > 1 else ""),
            span=_span(eom, i),
            help="check the start values and parameters against the constraint's domain (square roots, "
                 "divisions, logarithms); a constraint must be differentiable where the mechanism is"))


def _lstsq(eom: EOM, A, b, labels) -> np.ndarray:
    """Minimum-norm least squares; values that are not finite (or a solver that fails on
    them) are a located error naming the constraints (E826), never a numpy exception."""
    bad = [i for i in range(A.shape[0]) if not (np.isfinite(b[i]) and np.all(np.isfinite(A[i])))]
    if not bad and np.all(np.isfinite(A)):
        try:
            return np.linalg.lstsq(A, b, rcond=1e-12)[0]
        except np.linalg.LinAlgError:
            pass
    bad = bad or list(range(A.shape[0]))
    raise MechError(Diagnostic(
        CODE_UNDEFINED, "the constraint" + ("s " if len(bad) > 1 else " ") + ", ".join(labels[i] for i in bad)
        + " cannot be solved for during consistent initialization: the values are not finite "
        "(the constraints' gradients or the mass matrix)", span=_span(eom, bad[0]),
        help="check the lengths, masses and start values of the bodies in the loop for zero, huge or "
             "undefined values"))


def _distances(g, G):
    norms = np.linalg.norm(G, axis=1)
    return np.abs(g) / np.where(norms > 0, norms, 1.0)


def initialize(eom: EOM, q0=None, qd0=None, t: float = 0.0, p=None, tol: float = 1e-10,
               max_iter: int = 50, fixed_q=None, fixed_qd=None) -> InitReport:
    """Make (q0, q0') consistent with g = 0 and G q' + g_t = 0, holding the fixed values
    (``EOM.fixed_q`` / ``EOM.fixed_qd``, or the flags given here)."""
    with np.errstate(all="ignore"):      # values that are not finite are reported (E826), not warned
        return _initialize(eom, q0, qd0, t, p, tol, max_iter, fixed_q, fixed_qd)


def _initialize(eom, q0, qd0, t, p, tol, max_iter, fixed_q, fixed_qd) -> InitReport:
    pv = eom.param_values if p is None else np.asarray(p, float)
    if q0 is None or qd0 is None:
        a, b = eom.start(pv)
        q0 = a if q0 is None else q0
        qd0 = b if qd0 is None else qd0
    q = np.array(q0, float).copy()
    qd = np.array(qd0, float).copy()
    n, m = eom.n, eom.m
    if m == 0:
        return InitReport(q=q, qd=qd)
    fg, fG, fgt, fM = _functions(eom)
    labels = constraint_labels(eom)
    fixed_q = _flags(eom.fixed_q if fixed_q is None else fixed_q, n)
    fixed_qd = _flags(eom.fixed_qd if fixed_qd is None else fixed_qd, n)
    free = [i for i in range(n) if not fixed_q[i]]
    freev = [i for i in range(n) if not fixed_qd[i]]

    q, g, G, it = _positions(eom, fg, fG, fM, q, t, pv, free, tol, max_iter, labels)
    qd, r = _velocities(eom, fG, fgt, fM, q, qd, G, t, pv, freev, tol, labels)
    return InitReport(q=q, qd=qd, changes=_changes(eom, q0, qd0, q, qd), position_residual=float(np.max(np.abs(g))),
                      velocity_residual=float(np.max(np.abs(r))), iterations=it,
                      free_positions=tuple(eom.coords[i] for i in free),
                      free_speeds=tuple(eom.coords[i] for i in freev))


def _ev(f, *args, shape=None):
    a = np.array(f(*args), float)
    return a.reshape(shape) if shape else a.ravel()


def _positions(eom, fg, fG, fM, q, t, pv, free, tol, max_iter, labels):
    """Gauss-Newton with minimum-norm steps in the mass metric on the free coordinates,
    backtracking on ||g||: (q, g, G, iterations); E821 when the constraints stay violated."""
    n, m = eom.n, eom.m
    it = 0
    g = _ev(fg, q, t, pv)
    G = _ev(fG, q, t, pv, shape=(m, n))
    check_defined(eom, g, G)
    scale = 1.0 + np.max(np.abs(q))
    if free:
        d = 1.0 / np.sqrt(np.maximum(np.abs(np.diag(_ev(fM, q, t, pv, shape=(n, n)))), 1e-300))
        for it in range(1, max_iter + 1):
            if np.max(_distances(g, G)) <= 1e-3 * tol * scale:
                break
            A = G[:, free] * d[free][None, :]
            y = _lstsq(eom, A, -g, labels)
            step = d[free] * y
            # backtracking on ||g|| keeps Gauss-Newton from overshooting far from the surface
            lam, g_norm = 1.0, np.linalg.norm(g)
            while True:
                trial = q.copy()
                trial[free] += lam * step
                g_trial = _ev(fg, trial, t, pv)
                G_trial = _ev(fG, trial, t, pv, shape=(m, n))
                ok = np.all(np.isfinite(g_trial)) and np.all(np.isfinite(G_trial))
                if (ok and np.linalg.norm(g_trial) < g_norm) or lam < 1e-4:
                    break
                lam *= 0.5
            if not ok:          # the step leaves the constraints' domain: keep the last point
                break
            q = trial
            g, G = g_trial, G_trial
            if np.max(np.abs(lam * step)) <= 1e-15 * scale:
                break
    dist = _distances(g, G)
    bad = [i for i in range(m) if dist[i] > tol * scale]
    if bad:
        raise MechError(Diagnostic(
            CODE_POSITION,
            "the start values cannot satisfy the constraint" + ("s " if len(bad) > 1 else " ")
            + ", ".join(f"{labels[i]} with residual {g[i]:.3g}" for i in bad),
            span=_span(eom, bad[0]),
            help=("every coordinate in them has a fixed start value; correct the start values or let "
                  "some of them be computed (fixed = false)" if not free else
                  "the coordinates left free (" + ", ".join(eom.coords[i] for i in free) + ") cannot close "
                  "these constraints; check the start values, the dimensions, or free other coordinates")))
    return q, g, G, it


def _velocities(eom, fG, fgt, fM, q, qd, G, t, pv, freev, tol, labels):
    """One linear least-squares solve for the free speeds (the problem is linear in q'):
    (q', G q' + g_t); E822 when the velocity constraints stay violated."""
    n, m = eom.n, eom.m
    gt = _ev(fgt, q, t, pv)
    r = G @ qd + gt
    if freev:
        d = 1.0 / np.sqrt(np.maximum(np.abs(np.diag(_ev(fM, q, t, pv, shape=(n, n)))), 1e-300))
        A = G[:, freev] * d[freev][None, :]
        y = _lstsq(eom, A, -r, labels)
        qd[freev] += d[freev] * y
        r = G @ qd + gt
    vscale = 1.0 + np.max(np.abs(qd))
    vdist = _distances(r, G)
    badv = [i for i in range(m) if vdist[i] > tol * vscale * 1e2]
    if badv:
        raise MechError(Diagnostic(
            CODE_VELOCITY,
            "the start speeds violate the velocity form of the constraint" + ("s " if len(badv) > 1 else " ")
            + ", ".join(f"{labels[i]} with G q' + g_t = {r[i]:.3g}" for i in badv),
            span=_span(eom, badv[0]),
            help=("every speed in them has a fixed start value; correct the speeds or let some be computed "
                  "(speed fixed = false)" if not freev else
                  "the speeds left free (" + ", ".join(eom.coords[i] for i in freev) + ") cannot satisfy them")))
    return qd, r


def _changes(eom, q0, qd0, q, qd) -> list:
    """What initialization changed, starts before speeds, in the coordinates' order."""
    changes = []
    q_in, qd_in = np.asarray(q0, float), np.asarray(qd0, float)
    for i in range(eom.n):
        for kind, a, b in (("start", q_in[i], q[i]), ("speed", qd_in[i], qd[i])):
            if abs(b - a) > 4 * np.finfo(float).eps * (1 + abs(a)):
                changes.append(InitChange(eom.coords[i], kind, float(a), float(b)))
    changes.sort(key=lambda c: (c.kind != "start", eom.coords.index(c.name)))
    return changes


def check_report(eom: EOM, p=None, t: float = 0.0) -> list[str]:
    """Lines for ``mech check``: degrees of freedom and what initialization would change.

    Never raises for a model problem: an inconsistent start becomes an ``error:`` line.
    """
    try:
        init = initialize(eom, t=t, p=p)
        lines = dof_report(eom, init.q, t, p).lines()
        lines += init.lines()
    except MechError as e:
        try:
            lines = dof_report(eom, None, t, p).lines()
        except (MechError, np.linalg.LinAlgError):
            lines = []
        lines += [f"error[{d.code}]: {d.message}" + (f" (help: {d.help})" if d.help else "") for d in e.diagnostics]
    return lines


def start_jacobian(eom: EOM, q, qd, qd_given, t: float, p, fixed_q, fixed_qd) -> tuple[np.ndarray, np.ndarray]:
    """The linearization of ``initialize`` at its result (q, qd): (Jx, Jp), the change of the
    consistent start [q; qd] per change of the start values given [q_in; qd_in] (2n x 2n) and of
    the parameters (2n x n_p).  Used by sensitivities with respect to start values and
    parameters of a constrained model (mechdsl.simulation.trajectory).

    Positions: the free coordinates move along the minimum-norm direction in the mass metric,
    dq_F = dq_in_F - D A^+ (G dq_in + g_p dp), A = G_F D, over the independent constraints
    (exact when the start given was consistent or its free coordinates are determined by the
    fixed ones; otherwise to first order of the correction).  Speeds: the one least-squares
    solve qd_F = qd_in_F - D A^+ (G qd_in + g_t), differentiated exactly (CasADi, at q, qd_in)."""
    n = eom.n
    pv = np.asarray(p, float)
    fixed_q, fixed_qd = _flags(fixed_q, n), _flags(fixed_qd, n)
    free = [i for i in range(n) if not fixed_q[i]]
    freev = [i for i in range(n) if not fixed_qd[i]]
    keep = tuple(dof_report(eom, q, t, pv).independent)
    f = eom.workspace.memo(("start_jacobian", tuple(free), tuple(freev), keep),
                           lambda: _start_jacobian_functions(eom, free, freev, keep))
    Jq, Jqp, Vq, Vqd, Vp = (np.array(v, float) for v in f(q, qd_given, t, pv))
    Jq, Jqp = Jq.reshape(n, n), Jqp.reshape(n, -1)
    Vq, Vqd, Vp = Vq.reshape(n, n), Vqd.reshape(n, n), Vp.reshape(n, -1)
    Jx = np.block([[Jq, np.zeros((n, n))], [Vq @ Jq, Vqd]])
    Jp = np.vstack([Jqp, Vq @ Jqp + Vp])
    return Jx, Jp


def _start_jacobian_functions(eom: EOM, free, freev, keep):
    """Function (q, qd_in, t, p) -> (dq/dq_in, dq/dp, dqd/dq, dqd/dqd_in, dqd/dp) of the
    consistent initialization (``start_jacobian``)."""
    import casadi as ca

    n = eom.n
    q, t, p = eom.q, eom.t, eom.p
    qd_in = ca.SX.sym("qd_in", n)
    g = ca.SX(eom.g)[list(keep)] if keep else ca.SX(0, 1)
    G = ca.jacobian(g, q)
    d = 1.0 / ca.sqrt(ca.fmax(ca.fabs(ca.diag(ca.SX(eom.M))), 1e-300))

    def embed(rows, v):
        out = ca.SX.zeros(n, v.size2())
        for k, i in enumerate(rows):
            out[i, :] = v[k, :]
        return out

    def correction(rows, rhs):
        """-D A^+ rhs on the rows, A = G_rows D_rows (A^+ = A' (A A')^-1: full row rank)."""
        if not rows or g.numel() == 0:
            return ca.SX.zeros(n, rhs.size2())
        D = ca.diag(d[rows])
        A = ca.mtimes(G[:, rows], D)
        return embed(rows, -ca.mtimes(D, ca.mtimes(A.T, ca.solve(ca.mtimes(A, A.T), rhs))))

    Jq = ca.SX.eye(n) + correction(free, G)
    Jqp = correction(free, ca.jacobian(g, p))
    qd = qd_in + correction(freev, ca.mtimes(G, qd_in) + ca.jacobian(g, t))
    return ca.Function("start_jacobian", [q, qd_in, t, p],
                       [Jq, Jqp, ca.jacobian(qd, q), ca.jacobian(qd, qd_in), ca.jacobian(qd, p)])
