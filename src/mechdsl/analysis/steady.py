"""Steady motions: relative equilibria of the Routh-reduced system (issue 17).

Coordinates split into ignorable ones s (cyclic: dL/ds = 0, no force on s; found by
``first_integrals`` or named by the caller) and the others r.  A steady motion keeps r at rest
and the ignorable speeds constant: r' = 0, s' = w, so q'' = 0 and Lagrange's equations reduce
to ``bias(r, s, r' = 0, s' = w) = 0`` (the s rows vanish by themselves at r' = 0, since
p_s = dT/ds' then does not change; they stay in the residual as a check).  There are n_r + n_s
unknowns (r, w) and n_r equations: the caller pins n_s more, each one of

    a coordinate r_j = value        (the heavy top's nutation angle)
    a speed der(s_k) = value        (its spin rate psi')
    a momentum p_<s_k> = value      (the ignorable coordinate's conserved momentum)

and the square system is solved by Levenberg-Marquardt from many deterministic guesses (the
heavy top at a given nutation angle and spin has two roots: the slow and the fast precession).

**Stability** at the momenta beta = p_s of the solution (Routh): the reduced (amended)
potential

    V_R(r; beta) = V - T0 + 1/2 (beta - b_s)' M_ss^-1 (beta - b_s)      (b = dT/dq' at q' = 0)

has a critical point at r*; its Hessian positive definite means stable (Routh's theorem, the
Lagrange-Dirichlet theorem of the reduced system).  The witness of instability is the
linearization of the reduced system: state (r, r') with s' = M_ss^-1 (beta - p_s(r, r', s' = 0))
(the momenta held), r'' from M q'' = bias; an eigenvalue with positive real part is unstable.
A Hessian that is not positive definite with a purely imaginary spectrum is gyroscopic
stabilization: linearly stable, left undetermined (as for equilibria).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..diagnostics import Diagnostic, MechError, UsageError, did_you_mean
from .core import dense, param_vector, parts, require_ode, structure, wrap_angle
from .lm import levenberg_marquardt
from .integrals import first_integrals
from ..model.names import split_state


MAX_GUESSES = 400
LM_ITERATIONS = 60        # runs that run away (an orbit's radius to infinity) stop early
SPEED_GRID = (0.1, 0.3, 1.0, 3.0, 10.0, 30.0, 100.0)     # times the speed scale, both signs


@dataclass
class SteadyMotion:
    """One steady motion: the non-ignorable coordinates at rest, the ignorable ones turning at
    constant speeds.  ``q`` holds every coordinate (ignorable ones at their start values: they
    do not matter), ``qd`` the speeds (0 except the ignorable ones)."""

    coords: tuple[str, ...]
    q: np.ndarray
    qd: np.ndarray
    ignorable: tuple[str, ...]
    momenta: dict[str, float]
    stable: bool | None
    reason: str
    reduced_coords: tuple[str, ...] = ()
    reduced_hessian: np.ndarray | None = None      # Hessian of V_R in the reduced coordinates
    hessian_eigenvalues: np.ndarray | None = None
    linear_eigenvalues: np.ndarray | None = None   # of the reduced linear system (r, r') at fixed momenta
    residual: float = 0.0
    notes: list[str] = field(default_factory=list)

    @property
    def values(self) -> dict[str, float]:
        return {c: float(v) for c, v in zip(self.coords, self.q) if c not in self.ignorable}

    @property
    def speeds(self) -> dict[str, float]:
        """The constant speeds of the ignorable coordinates, as "der(s)"."""
        return {f"der({c})": float(v) for c, v in zip(self.coords, self.qd) if c in self.ignorable}

    def to_dict(self) -> dict:
        return {"values": self.values, "speeds": self.speeds, "momenta": dict(self.momenta),
                "stable": self.stable, "reason": self.reason, "reduced_coords": list(self.reduced_coords),
                "hessian_eigenvalues": [float(x) for x in (self.hessian_eigenvalues if self.hessian_eigenvalues
                                                           is not None else [])],
                "linear_eigenvalues": [[float(z.real), float(z.imag)] for z in
                                       (self.linear_eigenvalues if self.linear_eigenvalues is not None else [])],
                "residual": self.residual, "notes": list(self.notes)}


def steady_motions(eom, pins: dict, *, ignorable=None, guesses=None, p=None, t: float = 0.0,
                   max_guesses: int = MAX_GUESSES) -> list[SteadyMotion]:
    """Steady motions with the ignorable coordinates turning at constant speeds (see the module
    docstring).  pins: {name: value}, as many as there are ignorable coordinates, names being
    non-ignorable coordinates, "der(<ignorable>)" or "p_<ignorable>".  ignorable: coordinate
    names (default: the cyclic coordinates).  guesses: {name: value} or a list of them (the
    same names as pins, and the other unknowns)."""
    require_ode(eom, "steady motions")
    pv = param_vector(eom, p)
    n = eom.n
    ign = _ignorable(eom, pv, ignorable)
    s_idx = [eom.coords.index(c) for c in ign]
    r_idx = [i for i in range(n) if i not in s_idx]
    kinds = _pins(eom, pins, ign, r_idx)
    pt = parts(eom)
    q0, qd0 = eom.start(pv)
    st = structure(eom, pv)
    F = _residual_function(eom, pins, kinds, r_idx, s_idx, q0, t, max(st.force_scale, 1e-12))

    last: list = [None, None, None]          # x, residual, Jacobian: one call gives both

    def ev(x):
        if last[0] is None or not np.array_equal(last[0], x):
            r, J = F(x, pv)
            last[:] = [np.array(x, float), r.full().ravel(), J.full()]
        return last

    def f(x):
        return ev(x)[1]

    def jac(x):
        return ev(x)[2]

    periodic = [st.angles[i] if i < len(st.angles) else False for i in r_idx]
    out: list[SteadyMotion] = []
    tries = _guesses(eom, guesses, kinds, pins, r_idx, s_idx, q0, qd0, periodic, max_guesses)
    n_own = (1 if isinstance(guesses, dict) else len(guesses or [])) + 1      # the user's and the start
    for i, g in enumerate(tries):
        x = levenberg_marquardt(f, jac, g, max_iter=200 if i < n_own else LM_ITERATIONS)
        if x is None:
            continue
        x = _polish(f, jac, x)
        r = f(x)
        if not np.all(np.isfinite(r)) or np.max(np.abs(r)) > 1e-8:
            continue
        newton = _newton_step(jac(x), r)
        if not np.max(np.abs(newton), initial=0.0) <= 1e-6 * (1.0 + np.max(np.abs(x), initial=0.0)):
            continue        # small only because the forces decayed (an orbit running away): no root near
        x = x.copy()
        for j, per in enumerate(periodic):
            if per:
                x[j] = wrap_angle(x[j])
        if any(_same(x, o, periodic) for o in (_z(m, r_idx, s_idx) for m in out)):
            continue
        out.append(_classify(eom, pt, pv, t, x, r_idx, s_idx, ign, q0, float(np.max(np.abs(r)))))
    out.sort(key=lambda m: tuple(np.round(_z(m, r_idx, s_idx), 9)))
    return out


def _residual_function(eom, pins: dict, kinds: dict, r_idx, s_idx, q0, t: float, fscale: float):
    """The Function z, p -> (residual, its Jacobian) of the steady-motion equations in the
    unknowns z = (the other coordinates r, the ignorables' speeds w): the bias forces at constant
    speeds (n rows, over the force scale) and the pins (one row each)."""
    import casadi as ca

    n = eom.n
    z = ca.SX.sym("z", len(r_idx) + len(s_idx))
    q_e = ca.SX(eom.q)
    q_expr = ca.vertcat(*[z[r_idx.index(i)] if i in r_idx else ca.SX(q0[i]) for i in range(n)])
    qd_expr = ca.vertcat(*[z[len(r_idx) + s_idx.index(i)] if i in s_idx else ca.SX(0) for i in range(n)])
    mom = ca.gradient(eom.T, eom.qd)
    sub = lambda e: ca.substitute(ca.substitute(e, q_e, q_expr), eom.qd, qd_expr)  # noqa: E731
    bias = sub(ca.substitute(eom.bias, eom.t, ca.SX(t)))
    mom_z = sub(ca.substitute(mom, eom.t, ca.SX(t)))
    rows = [bias / fscale]
    for name, (kind, k) in kinds.items():
        val = float(pins[name])
        if kind == "coord":
            rows.append(z[r_idx.index(k)] - val)
        elif kind == "speed":
            rows.append(z[len(r_idx) + s_idx.index(k)] - val)
        else:
            rows.append((mom_z[k] - val) / max(1.0, abs(val)))
    res = ca.vertcat(*rows)
    return ca.Function("steady_res", [z, eom.p], [res, ca.jacobian(res, z)])


def _polish(f, jac, x, steps: int = 12):
    """Gauss-Newton steps from Levenberg-Marquardt's result, kept when they end with a smaller
    residual: its isotropic damping stalls along weakly scaled directions (a force row of 1e-4
    next to a momentum row of 1), where undamped steps converge quadratically."""
    x0, r0 = x, f(x)
    r = r0
    for _ in range(steps):
        if not np.all(np.isfinite(r)) or np.max(np.abs(r), initial=0.0) == 0.0:
            break
        x = x - _newton_step(jac(x), r)
        r = f(x)
    ok = np.all(np.isfinite(x)) and np.all(np.isfinite(r)) and r @ r < r0 @ r0
    return x if ok else x0


def _newton_step(J, r) -> np.ndarray:
    """The least-squares Newton step with the rows equilibrated first, so that a weak row (a force
    that decayed) is not cut off by lstsq's cutoff relative to a strong one (a momentum)."""
    with np.errstate(all="ignore"):
        w = np.max(np.abs(J), axis=1)
        w = np.where(w > 0, 1.0 / np.where(w > 0, w, 1.0), 0.0)
        step = np.linalg.lstsq(J * w[:, None], r * w, rcond=1e-14)[0]
    return step if np.all(np.isfinite(step)) else np.full(len(step), np.inf)


def _z(m: SteadyMotion, r_idx, s_idx) -> np.ndarray:
    return np.r_[m.q[r_idx], m.qd[s_idx]]


def _same(a, b, periodic) -> bool:
    d = a - b
    for j, per in enumerate(periodic):
        if per:
            d[j] = wrap_angle(d[j])
    return bool(np.max(np.abs(d)) <= 1e-6 * (1.0 + np.max(np.abs(a))))


def _ignorable(eom, pv, ignorable) -> tuple[str, ...]:
    if ignorable is not None:
        names = (ignorable,) if isinstance(ignorable, str) else tuple(ignorable)
        for c in names:
            if c not in eom.coords:
                hint = did_you_mean(c, eom.coords)
                raise UsageError(f"'{c}' is not a coordinate of {eom.name}" + (f"; {hint}" if hint else ""))
        return names

    names = tuple(fi.coordinate for fi in first_integrals(eom, pv) if fi.kind == "momentum" and fi.coordinate)
    if not names:
        raise MechError(Diagnostic(
            "E912", f"{eom.name} has no ignorable (cyclic) coordinate, so it has no steady motions to reduce",
            help="steady motions turn ignorable coordinates at constant speed; equilibria (mech equilibrium) "
                 "are the steady states of models without them; or name them with ignorable=[...]"))
    return names


def _pins(eom, pins, ign, r_idx) -> dict:
    """{pin name: (kind, index)}; kind coord | speed | momentum."""
    allowed = [eom.coords[i] for i in r_idx] + [f"der({c})" for c in ign] + [f"p_{c}" for c in ign]
    out = {}
    for name in pins or {}:
        if name in ign:
            raise UsageError(f"'{name}' is ignorable: its value does not matter; pin its speed der({name}) "
                             f"or its momentum p_{name}")
        if name not in allowed:
            hint = did_you_mean(name, allowed)
            raise UsageError(f"cannot pin '{name}': pins are {', '.join(allowed)}" + (f"; {hint}" if hint else ""))
        if split_state(name)[1]:
            out[name] = ("speed", eom.coords.index(split_state(name)[0]))
        elif name.startswith("p_") and name[2:] in ign:
            out[name] = ("momentum", eom.coords.index(name[2:]))
        else:
            out[name] = ("coord", eom.coords.index(name))
        try:
            v = float(pins[name])
        except (TypeError, ValueError):
            raise UsageError(f"pin {name} needs a number, got {pins[name]!r}") from None
        if not np.isfinite(v):
            raise UsageError(f"pin {name} must be finite, got {v}")
    if len(out) != len(ign):
        raise UsageError(f"steady motions of {eom.name} need {len(ign)} pin(s), one per ignorable coordinate "
                         f"({', '.join(ign)}), got {len(out)}: choose among {', '.join(allowed)}")
    return out


def _guesses(eom, guesses, kinds, pins, r_idx, s_idx, q0, qd0, periodic, max_guesses):
    """Deterministic starting points z = (r, w): the user's, the start values, then a grid."""
    nr = len(r_idx)
    base = np.r_[q0[r_idx], qd0[s_idx]]
    names = [eom.coords[i] for i in r_idx] + [f"der({eom.coords[i]})" for i in s_idx]

    def pinned(zv):
        zv = zv.copy()
        for name, (kind, k) in kinds.items():
            if kind == "coord":
                zv[r_idx.index(k)] = float(pins[name])
            elif kind == "speed":
                zv[nr + s_idx.index(k)] = float(pins[name])
        return zv

    out = []
    for g in ([guesses] if isinstance(guesses, dict) else list(guesses or [])):
        zv = base.copy()
        for k, v in g.items():
            if k not in names:
                raise UsageError(f"guess {k!r}: unknowns are {', '.join(names)}")
            zv[names.index(k)] = float(v)
        out.append(pinned(zv))
    out.append(pinned(base))
    fixed = {r_idx.index(k) for kind, k in kinds.values() if kind == "coord"} | \
            {nr + s_idx.index(k) for kind, k in kinds.values() if kind == "speed"}
    axes = []
    scale = max(1.0, float(np.max(np.abs(qd0), initial=0.0)))
    for j in range(len(base)):
        if j in fixed:
            axes.append([base[j]])
        elif j < nr:
            axes.append(list(np.linspace(-np.pi, np.pi, 8, endpoint=False) + 0.1) if periodic[j] else
                        [base[j] + d * max(1.0, abs(base[j])) for d in (0.0, 0.5, -0.5, 2.0, -2.0)])
        else:
            axes.append([sg * v * scale for v in SPEED_GRID for sg in (1.0, -1.0)])
    grid = np.array(np.meshgrid(*axes, indexing="ij")).reshape(len(base), -1).T if axes else np.zeros((1, 0))
    if len(grid) > max_guesses:
        grid = grid[np.random.default_rng(1234).permutation(len(grid))[:max_guesses]]
    out += [pinned(g) for g in grid]
    return out


def _classify(eom, pt, pv, t, x, r_idx, s_idx, ign, q0, resid) -> SteadyMotion:
    import casadi as ca

    n, nr = eom.n, len(r_idx)
    q = q0.copy()
    q[r_idx] = x[:nr]
    qd = np.zeros(n)
    qd[s_idx] = x[nr:]
    mom = ca.gradient(eom.T, eom.qd)
    beta_all = dense(ca.Function("mom", [eom.q, eom.qd, eom.t, eom.p], [mom])(q, qd, t, pv)).ravel()
    beta = beta_all[s_idx]
    VR, A = _reduced(eom, pt, r_idx, s_idx)
    H, grad = (dense(v) for v in VR(q, t, pv, beta))
    Ared = dense(A(q, t, pv, beta))
    Hr = 0.5 * (H + H.T)
    if not (np.all(np.isfinite(Hr)) and np.all(np.isfinite(grad)) and np.all(np.isfinite(Ared))):
        # Routh's reduction divides by the ignorables' block of M: singular at a chart's singularity
        return SteadyMotion(coords=tuple(eom.coords), q=q, qd=qd, ignorable=tuple(ign),
                            momenta={f"p_{c}": float(b) for c, b in zip(ign, beta)}, stable=None,
                            reason="not decided: the ignorable coordinates' block of the mass matrix is singular "
                                   "here (a coordinate singularity, e.g. Euler angles with theta = 0, where two "
                                   "angles turn about one axis), so Routh's reduced potential is not defined; "
                                   "simulate near it, or use coordinates without this singularity",
                            reduced_coords=tuple(eom.coords[i] for i in r_idx), reduced_hessian=np.full((nr, nr), np.nan),
                            hessian_eigenvalues=np.zeros(0), linear_eigenvalues=np.zeros(0, complex), residual=resid,
                            notes=["the reduced Hessian and linearization are not defined at this configuration"])
    heig = np.linalg.eigvalsh(Hr) if nr else np.zeros(0)
    lam = np.linalg.eigvals(Ared) if Ared.size else np.zeros(0, complex)
    hscale = max(float(np.max(np.abs(Hr), initial=0.0)), 1e-300)
    lscale = max(float(np.max(np.abs(lam), initial=0.0)), 1e-300)
    notes = []
    if np.max(np.abs(grad), initial=0.0) > 1e-6 * max(1.0, hscale):
        notes.append(f"grad V_R = {np.max(np.abs(grad)):.3g} at the solution (Routh's condition not met "
                     "to tolerance: forces other than the potential act?)")
    if lam.size and np.max(lam.real) > 1e-6 * lscale:
        stable, reason = False, (f"unstable: the reduced linear system at fixed momenta has an eigenvalue with "
                                 f"positive real part ({np.max(lam.real):.6g} 1/s)")
    elif nr == 0:
        stable, reason = None, "no non-ignorable coordinate: nothing to decide"
    elif np.all(heig > 1e-9 * hscale):
        stable, reason = True, (f"stable (Routh): the Hessian of the reduced potential V_R at fixed momenta is "
                                f"positive definite (eigenvalues {_fmt(heig)})")
    elif np.any(heig < -1e-9 * hscale):
        stable, reason = None, (f"V_R has negative curvature ({_fmt(heig)}) but the reduced linear system has no "
                                "growing mode: gyroscopic stabilization, linearly stable only")
    else:
        stable, reason = None, f"zero eigenvalue(s) of the Hessian of V_R ({_fmt(heig)}): higher-order terms decide"
    return SteadyMotion(coords=tuple(eom.coords), q=q, qd=qd, ignorable=tuple(ign),
                        momenta={f"p_{c}": float(b) for c, b in zip(ign, beta)}, stable=stable, reason=reason,
                        reduced_coords=tuple(eom.coords[i] for i in r_idx), reduced_hessian=Hr,
                        hessian_eigenvalues=heig, linear_eigenvalues=lam, residual=resid, notes=notes)


def _reduced(eom, pt, r_idx, s_idx):
    """CasADi Functions of (q, t, p, beta): [Hessian of V_R in r, its gradient] and the reduced
    linear system matrix A (state (r, r'), momenta of s held at beta)."""
    # shared with EOM.replace copies: keyed by the Parts (content-keyed themselves), held by the entry
    key = ("steady_reduced", id(pt), tuple(r_idx), tuple(s_idx))
    return eom.workspace.shared(key, lambda: (pt,) + _build_reduced(eom, pt, r_idx, s_idx))[1:]


def _build_reduced(eom, pt, r_idx, s_idx):
    import casadi as ca

    n, nr, ns = eom.n, len(r_idx), len(s_idx)
    beta = ca.SX.sym("beta", ns)
    q, qd, t, p = eom.q, eom.qd, eom.t, eom.p
    M = ca.SX(eom.M)
    Mss = M[s_idx, s_idx]
    b_s = ca.SX(pt.b)[s_idx]
    d = beta - b_s
    VR = pt.Veff + 0.5 * ca.dot(d, ca.solve(Mss, d))
    qr = ca.vertcat(*[q[i] for i in r_idx]) if nr else ca.SX(0, 1)
    H = ca.hessian(VR, qr)[0] if nr else ca.SX(0, 0)
    grad = ca.gradient(VR, qr) if nr else ca.SX(0, 1)
    fv = ca.Function("VR", [q, t, p, beta], [H, grad])
    # reduced dynamics: rd free, sd from the momenta
    rd = ca.SX.sym("rd", nr)
    qd_r = ca.vertcat(*[rd[r_idx.index(i)] if i in r_idx else ca.SX(0) for i in range(n)])
    mom = ca.substitute(ca.gradient(eom.T, qd), qd, qd_r)
    sd = ca.solve(Mss, beta - mom[s_idx])
    qd_full = ca.vertcat(*[rd[r_idx.index(i)] if i in r_idx else sd[s_idx.index(i)] for i in range(n)])
    acc = ca.solve(M, ca.substitute(eom.bias, qd, qd_full))
    acc = ca.substitute(acc, qd, qd_full)
    state = ca.vertcat(qr, rd)
    rhs = ca.vertcat(rd, ca.vertcat(*[acc[i] for i in r_idx])) if nr else ca.SX(0, 1)
    A = ca.jacobian(rhs, state) if nr else ca.SX(0, 0)
    fa = ca.Function("Ared", [q, t, p, beta, rd], [A])
    fa0 = lambda q_, t_, p_, b_: fa(q_, t_, p_, b_, np.zeros(nr))  # noqa: E731
    return fv, fa0


def _fmt(v) -> str:
    return "[" + ", ".join(f"{x:.6g}" for x in v) + "]"
