"""The linear model about an equilibrium or a reference state.

``linearize(eom, at=...)`` returns M, C, K (second order), A, B (first order, x = (dq, dq'))
computed numerically by CasADi AD of the equations of motion (see :mod:`.matrices`), and
``.symbolic()`` the same M, C, K derived exactly by sympy from T, V, D, Q (see :mod:`.symbolic`).
"""
from __future__ import annotations

import math
import re

import numpy as np

from ..diagnostics import Diagnostic, MechError, UsageError, did_you_mean
from ..eom import fold_inputs
from .charts import chart_speeds, normalize_blocks, quaternion_blocks
from .constraints import constrained, setup
from .core import param_vector, parts, structure
from .equilibrium import nearest_equilibrium
from .equilibrium_classify import active_basis, chart_of, singular_mass
from .equilibrium_record import Equilibrium
from .linear_model import Linearization, declared_inputs, input_columns
from .matrices import first_order, second_order, singular_mass_error, sym
from .reduced import linearize_constrained
from ..model.names import split_state


def linearize(eom, at="equilibrium", inputs=None, *, p=None, t: float = 0.0, guesses=None) -> Linearization:
    """Linear model of ``eom`` about ``at``:

    - ``"equilibrium"``: the equilibrium nearest to the start values (``guesses`` steer the
      search; see :func:`equilibria`); an :class:`Equilibrium` object: that one;
    - ``"t=T"``: the state reached at time T from the start values (integrated with scipy's
      DOP853, rtol 1e-11), ``"start"``: the start state;
    - a dict ``{coordinate: value, "der(coordinate)": speed}``: missing coordinates take their
      start values, missing speeds zero.

    inputs: names of parameters or coordinates (a unit generalized force on that coordinate,
    also written ``force(name)``) treated as inputs u; B = [0; M^-1 Bq], Bq = d bias/du.
    None: the parameters the model declares ``input``; () for none.
    """
    eom = fold_inputs(eom)          # inputs held at their defaults: trailing parameters

    pv = param_vector(eom, p)
    if constrained(eom):
        return linearize_constrained(eom, setup(eom, pv, t, "linearization"), at, inputs, pv, t, guesses)
    q0, qd0 = eom.start(pv)
    notes: list[str] = []
    q, qd, t, acc, kind, eq = _point(eom, at, guesses, q0, qd0, pv, t, notes)
    base, work, q, qd, qw, qdw, accw, Zc = _chart(eom, q, qd, acc, q0, t, pv, notes)
    nw = work.n
    M, C, K, bias, accw = second_order(work, qw, qdw, t, pv, acc=accw)
    if kind == "state":
        st = structure(eom, pv)
        if np.max(np.abs(qdw), initial=0.0) == 0 and np.max(np.abs(bias), initial=0.0) <= 1e-8 * max(st.force_scale, 1e-300):
            kind = "equilibrium"
            accw = np.zeros(nw)
            M, C, K, bias, accw = second_order(work, qw, qdw, t, pv, acc=accw)
        else:
            notes.append("not an equilibrium: the linear model describes deviations from the motion "
                         "through this state at this instant (frozen time, reference acceleration "
                         "included in K)")
    if inputs is None:
        inputs = declared_inputs(eom)
    names, Bq = input_columns(base, inputs, q, qd, t, pv)
    stiffness = K
    R = active_basis(M, C, K) if singular_mass(M) else None
    if R is not None:
        notes.append(f"{nw - R.shape[1]} direction(s) carry neither inertia nor force (the spin of a point "
                     "mass about its own axis): left out of the linear model")
        M, C, K = R.T @ M @ R, R.T @ C @ R, R.T @ K @ R
    if singular_mass(M):
        w, V = np.linalg.eigh(sym(M))
        raise singular_mass_error(work, (V[:, 0] if R is None else R @ V[:, 0]), "at the linearization point")
    basis = Zc if R is None else (R if Zc is None else Zc @ R)
    if basis is not None:
        Bq = basis.T @ Bq
    m = M.shape[0]
    A = first_order(M, C, K)
    B = np.vstack([np.zeros((m, Bq.shape[1])), np.linalg.solve(M, Bq)]) if m else np.zeros((0, Bq.shape[1]))
    acc_out = np.asarray(accw, float) if Zc is None else Zc @ np.asarray(accw, float)
    extra = {}
    if basis is not None:
        rnames = tuple(work.coords) if R is None else _names(work.coords, R)
        extra = dict(basis=basis, reduced_coords=rnames, stiffness=stiffness)
    return Linearization(coords=tuple(base.coords), M=M, C=C, K=K, A=A, B=B, Bq=Bq, inputs=names,
                         q=np.asarray(q, float), qd=np.asarray(qd, float), t=float(t),
                         acceleration=acc_out, kind=kind, p=pv, equilibrium=eq,
                         notes=notes, eom=eom, **extra)


def _point(eom, at, guesses, q0, qd0, pv, t, notes):
    """The point linearized about: (q, q', t, reference acceleration or None, kind, the
    equilibrium or None)."""
    eq = None
    if isinstance(at, Equilibrium):
        eq = at
    elif isinstance(at, str) and at.strip() == "equilibrium":
        eq = nearest_equilibrium(eom, guesses, t, pv, q0, notes, "linearize about a state (--at t=0)")
    if eq is not None:
        kind = "accelerated-reference" if eq.kind == "accelerated-reference" else "equilibrium"
        return np.asarray(eq.q, float), np.zeros(eom.n), eq.t, eq.acceleration, kind, eq
    q, qd, t = _state(eom, at, q0, qd0, pv, t)
    return q, qd, t, None, "state", None


def _chart(eom, q, qd, acc, q0, t, pv, notes):
    """Quaternion joints and Euler angles at gimbal lock: the linear model lives in a chart
    (analysis.charts).  (base: the EOM whose coordinates the result reports, work: the one
    differentiated, q and q' over base, qw, qdw, the acceleration over work, Zc: work -> base
    or None)."""
    base, work, qw, qdw, accw, Zc = eom, eom, q, qd, acc, None
    blocks = quaternion_blocks(eom)
    if blocks:
        q = qw = normalize_blocks(q, blocks, fallback=q0)
    ch = chart_of(eom, q, t, pv)
    if ch is not None:
        work, _, qb, Zc, base, more = ch
        notes.extend(more)
        if base is not eom and np.any(qd):
            raise MechError(Diagnostic("E911", f"the Euler angles of '{eom.name}' are at gimbal lock in this "
                                               "state and the angle rates do not carry over to another chart",
                                       help="linearize about a state at rest here, or use a quaternion joint"))
        qdb = np.zeros(base.n) if base is not eom else qd
        qw, qdw = np.zeros(work.n), chart_speeds(qb, qdb, quaternion_blocks(base), base.n)
        accw = None if acc is None else np.linalg.lstsq(Zc, _to_base(acc, base, eom), rcond=None)[0]
        q, qd = qb, qdb
    return base, work, q, qd, qw, qdw, accw, Zc


def _to_base(v, base, eom) -> np.ndarray:
    """A vector over eom's coordinates carried to base's (those of the same name; 0 elsewhere)."""
    if base is eom:
        return np.asarray(v, float)
    out = np.zeros(base.n)
    for i, c in enumerate(base.coords):
        if c in eom.coords:
            out[i] = v[eom.coords.index(c)]
    return out


def _names(coords, R) -> tuple[str, ...]:
    """Names of the columns of R: a coordinate's name when the column is its axis, else z<k>."""
    out = []
    for j in range(R.shape[1]):
        nz = np.flatnonzero(np.abs(R[:, j]) > 1e-12)
        out.append(coords[nz[0]] if len(nz) == 1 and abs(abs(R[nz[0], j]) - 1) < 1e-12 else f"z{j + 1}")
    return tuple(out)


def _state(eom, at, q0, qd0, pv, t):
    n = eom.n
    if isinstance(at, dict):
        q, qd = q0.copy(), np.zeros(n)
        for name, v in at.items():
            key, speed = split_state(name)
            if key not in eom.coords:
                hint = did_you_mean(key, eom.coords)
                raise UsageError(f"unknown coordinate {key!r}" + (f"; {hint}" if hint else ""))
            (qd if speed else q)[eom.coords.index(key)] = float(v)
        return q, qd, t
    if isinstance(at, str):
        s = at.strip()
        if s == "start":
            return q0, qd0, 0.0
        m = re.fullmatch(r"t\s*=\s*(.+)", s)
        if m:
            try:
                T = float(m.group(1))
            except ValueError:
                raise UsageError(f"--at t=T needs a number, got {m.group(1)!r}") from None
            return (*_integrate(eom, q0, qd0, pv, T), T)
    raise UsageError(f"cannot linearize at {at!r}: use 'equilibrium', 't=T', 'start', a dict of "
                     "coordinate values or an Equilibrium")


def _integrate(eom, q0, qd0, pv, T):
    """State at time T from the start values (independent of the simulator: scipy DOP853)."""
    if T == 0:
        return q0, qd0
    if T < 0 or not math.isfinite(T):
        raise UsageError(f"t = {T} must be a finite time >= 0")
    from scipy.integrate import solve_ivp

    pt = parts(eom)
    n = eom.n

    def f(tt, x):
        M, b = pt.M_bias(x[:n], x[n:], tt, pv)
        try:
            return np.concatenate([x[n:], np.linalg.solve(M, b)])
        except np.linalg.LinAlgError:
            raise MechError(Diagnostic("E904", f"could not reach t = {T} from the start values: the mass "
                                               f"matrix is singular at t = {tt:.6g}",
                                       help="linearize about an earlier time or about the start (--at start)")) from None

    sol = solve_ivp(f, (0.0, T), np.concatenate([q0, qd0]), method="DOP853", rtol=1e-11, atol=1e-12)
    if not sol.success:
        raise MechError(Diagnostic("E904", f"could not reach t = {T} from the start values: {sol.message}"))
    x = sol.y[:, -1]
    return x[:n], x[n:]
