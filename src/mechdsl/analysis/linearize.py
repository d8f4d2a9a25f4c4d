"""The linear model about an equilibrium or a reference state.

``linearize(eom, at=...)`` returns M, C, K (second order), A, B (first order, x = (dq, dq'))
computed numerically by CasADi AD of the equations of motion (see :mod:`.matrices`), and
``.symbolic()`` the same M, C, K derived exactly by sympy from T, V, D, Q (see :mod:`.symbolic`).
"""
from __future__ import annotations

import json
import math
import re
from dataclasses import dataclass, field

import numpy as np

from ..output import display as _display
from ..diagnostics import Diagnostic, MechError, UsageError, did_you_mean
from .constraints import constrained, setup
from .core import dense, param_vector, parts, structure, wrap_angle
from .charts import chart_speeds, normalize_blocks, quaternion_blocks
from .matrices import first_order, second_order, singular_mass_error, skew, sym
from .modes import Modes, modes_of


@dataclass
class Linearization:
    coords: tuple[str, ...]
    M: np.ndarray
    C: np.ndarray
    K: np.ndarray
    A: np.ndarray
    B: np.ndarray                    # (2n, m) first-order input matrix
    Bq: np.ndarray                   # (n, m): M dq'' + C dq' + K dq = Bq du
    inputs: tuple[str, ...]
    q: np.ndarray                    # reference state
    qd: np.ndarray
    t: float
    acceleration: np.ndarray         # reference acceleration (0 at an equilibrium)
    kind: str                        # 'equilibrium' | 'accelerated-reference' | 'state'
    p: np.ndarray
    equilibrium: object | None = None
    notes: list[str] = field(default_factory=list)
    eom: object | None = field(default=None, repr=False)
    _modes: Modes | None = field(default=None, repr=False)
    # constrained models (see analysis.reduced): M, C, K, A, B are those of the reduced model in
    # the coordinates ``reduced_coords`` (dq = basis dz); multipliers at the reference state for
    # every constraint (0 for dropped redundant ones); stiffness: the full n x n K including the
    # geometric stiffness sum lambda_l d2g_l/dq2, before the reduction
    basis: np.ndarray | None = None
    reduced_coords: tuple[str, ...] = ()
    multipliers: np.ndarray | None = None
    constraint_names: tuple[str, ...] = ()
    active_constraints: tuple[str, ...] = ()
    # |dg_i/dq| of explicit constraint equations (1 for cut-joint rows): `lambdas` reports
    # scale * multiplier, the reaction along -grad g (eom.multiplier_scales)
    multiplier_scales: np.ndarray | None = None
    stiffness: np.ndarray | None = None

    _repr_html_ = _display.linearization_html        # notebook displays (mechdsl.output.display)
    _repr_markdown_ = _display.linearization_markdown

    def __repr__(self) -> str:
        """One line: about what, how many coordinates, the modes' frequencies (the HTML display
        and ``to_dict()`` hold the matrices)."""
        where = {"equilibrium": "about the equilibrium", "accelerated-reference": "about the accelerated reference",
                 "state": f"about the state at t = {self.t:g}"}.get(self.kind, self.kind)
        n = len(self.matrix_coords)
        md = self.modes()
        w = ", ".join(f"{v:.6g}" for v in md.frequencies[:4]) + (", ..." if len(md.frequencies) > 4 else "")
        return (f"<Linearization {where}: {n} coordinate{'' if n == 1 else 's'}, "
                f"{len(md)} mode{'' if len(md) == 1 else 's'}" + (f", w = {w} rad/s" if w else "") + ">")

    @property
    def constrained(self) -> bool:
        """True for a constrained model: M, C, K are then those of the reduced coordinates."""
        return self.basis is not None

    @property
    def matrix_coords(self) -> tuple[str, ...]:
        """Names of the rows and columns of M, C, K (the reduced coordinates when constrained)."""
        return self.reduced_coords if self.constrained else self.coords

    @property
    def lambdas(self) -> dict[str, float]:
        """The constraint multipliers at the reference state, by constraint name ({} if none)."""
        if self.multipliers is None:
            return {}
        scale = np.ones(len(self.multipliers)) if self.multiplier_scales is None else self.multiplier_scales
        return {c: float(s * v) for c, s, v in zip(self.constraint_names, scale, self.multipliers)}

    @property
    def n(self) -> int:
        """The number of coordinates."""
        return len(self.coords)

    @property
    def D(self) -> np.ndarray:
        """Damping: the symmetric part of C."""
        return sym(self.C)

    @property
    def G(self) -> np.ndarray:
        """Gyroscopic matrix: the skew-symmetric part of C."""
        return skew(self.C)

    @property
    def values(self) -> dict[str, float]:
        """The coordinates' values at the reference state, by name."""
        return {c: float(v) for c, v in zip(self.coords, self.q)}

    def modes(self) -> Modes:
        """The modes (mechdsl.analysis.modes.Modes): frequencies [rad/s], ``hz``, damping
        ratios, shapes (in the original coordinates) and kinds, slowest first."""
        if self._modes is None:
            md = modes_of(self.M, self.C, self.K, self.A, self.matrix_coords)
            self._modes = md.in_coordinates(self.basis, self.coords) if self.constrained else md
        return self._modes

    @property
    def eigenvalues(self) -> np.ndarray:
        """The eigenvalues of the first-order system matrix A [1/s]."""
        return self.modes().eigenvalues

    def lqr(self, Q, R):
        """The LQR state feedback du = -K dx for this linear model (analysis.lqr)."""
        from .lqr import lqr

        return lqr(self, Q, R)

    def symbolic(self, exact: bool = True):
        """M, C, K derived by sympy from T, V, D, Q at this state (see analysis.symbolic)."""
        from .symbolic import symbolic_linearization

        if self.constrained:
            raise MechError(Diagnostic("E901", "the symbolic linearization is available for models in "
                                               "independent coordinates only; the numeric M, C, K of the "
                                               "reduced model are exact to rounding"))

        return symbolic_linearization(self.eom, self.q, self.qd, self.t, self.acceleration,
                                      inputs=self.inputs, exact=exact)

    def to_dict(self) -> dict:
        """Plain JSON types: coordinates, state, M, C, K, A, B, modes, eigenvalues, notes, ..."""
        md = self.modes().to_dict()
        return {"coordinates": list(self.coords), "kind": self.kind, "t": self.t,
                "state": {"q": self.values, "qd": {c: float(v) for c, v in zip(self.coords, self.qd)}},
                "acceleration": {c: float(v) for c, v in zip(self.coords, self.acceleration)},
                "inputs": list(self.inputs), "M": self.M.tolist(), "C": self.C.tolist(), "K": self.K.tolist(),
                "A": self.A.tolist(), "B": self.B.tolist(), "modes": md["modes"],
                "eigenvalues": md["eigenvalues"], "notes": list(self.notes),
                "equilibrium": None if self.equilibrium is None else self.equilibrium.to_dict(),
                **self._constrained_dict()}

    def _constrained_dict(self) -> dict:
        if not self.constrained:
            return {}
        return {"reduced_coordinates": list(self.reduced_coords),
                "basis": [{c: float(v) for c, v in zip(self.coords, col)} for col in self.basis.T],
                "multipliers": self.lambdas, "active_constraints": list(self.active_constraints),
                "stiffness_full": self.stiffness.tolist()}

    def to_json(self) -> str:
        """``to_dict()`` as JSON text (what ``mech linearize -o OUT.json`` writes)."""
        return json.dumps({"generator": "mechdsl", **self.to_dict()}, indent=2) + "\n"


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
    from ..eom import fold_inputs

    eom = fold_inputs(eom)          # inputs held at their defaults: trailing parameters
    from .equilibrium import Equilibrium, active_basis, chart_of, singular_mass

    pv = param_vector(eom, p)
    if constrained(eom):
        from .reduced import linearize_constrained

        return linearize_constrained(eom, setup(eom, pv, t, "linearization"), at, inputs, pv, t, guesses)
    n = eom.n
    q0, qd0 = eom.start(pv)
    eq = None
    notes: list[str] = []
    acc = None
    if isinstance(at, Equilibrium):
        eq = at
    elif isinstance(at, str) and at.strip() == "equilibrium":
        eq = nearest_equilibrium(eom, guesses, t, pv, q0, notes, "linearize about a state (--at t=0)")
    if eq is not None:
        q, qd, t, acc = np.asarray(eq.q, float), np.zeros(n), eq.t, eq.acceleration
        kind = "accelerated-reference" if eq.kind == "accelerated-reference" else "equilibrium"
    else:
        q, qd, t = _state(eom, at, q0, qd0, pv, t)
        kind = "state"

    # quaternion joints and Euler angles at gimbal lock: the linear model lives in a chart
    # (analysis.charts); base is the EOM whose coordinates the result reports
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
    names, Bq = _inputs(base, inputs, q, qd, t, pv)
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


def nearest_equilibrium(eom, guesses, t, pv, q0, notes: list, other: str):
    """The equilibrium nearest to the first guess (without guesses: to q0; angles compared
    modulo 2 pi), noted when there are several; E903 saying why and with the hint `other` when
    there is none."""
    from .equilibrium import equilibria, parse_guesses

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


def _state(eom, at, q0, qd0, pv, t):
    n = eom.n
    if isinstance(at, dict):
        q, qd = q0.copy(), np.zeros(n)
        for name, v in at.items():
            m = re.fullmatch(r"\s*der\((.+)\)\s*", name)
            key = m.group(1) if m else name
            if key not in eom.coords:
                hint = did_you_mean(key, eom.coords)
                raise UsageError(f"unknown coordinate {key!r}" + (f"; {hint}" if hint else ""))
            (qd if m else q)[eom.coords.index(key)] = float(v)
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


def declared_inputs(eom) -> list[str]:
    """The parameters declared `input` in the model (empty without a model)."""
    model = getattr(eom, "model", None)
    if model is None:
        return []
    return [p.name for p in model.inputs if p.name in eom.params]


def _inputs(eom, inputs, q, qd, t, pv):
    n = eom.n
    if not inputs:
        return (), np.zeros((n, 0))
    if isinstance(inputs, str):
        inputs = [s for s in re.split(r"[,\s]+", inputs) if s]
    cols, names = [], []
    dbp = None
    for name in inputs:
        m = re.fullmatch(r"\s*(?:force|Q)\((.+)\)\s*", name)
        key = m.group(1) if m else name.strip()
        if key in eom.coords and (m or key not in eom.params):
            e = np.zeros(n)
            e[eom.coords.index(key)] = 1.0
            cols.append(e)
            names.append(f"force({key})")
        elif key in eom.params and not m:
            if dbp is None:
                dbp = dense(parts(eom).fn("dbias_dp")(q, qd, t, pv))
            cols.append(dbp[:, eom.params.index(key)])
            names.append(key)
        else:
            hint = did_you_mean(key, list(eom.params) + list(eom.coords))
            raise UsageError(f"unknown input {name!r}: inputs are parameters or coordinates "
                             "(a generalized force on them)" + (f"; {hint}" if hint else ""))
    return tuple(names), np.array(cols).T
