"""Numeric machinery shared by the analyses (CasADi SX in, numpy out).

Everything here works on an :class:`mechdsl.eom.EOM` (q, qd, t, p as CasADi SX) and never
needs the model text.  The pieces:

- ``param_vector``: the parameter vector p from the model's values plus overrides;
- ``Parts``: the speed decomposition T = T2 + T1 + T0 (T2 = 1/2 qd'M qd, T1 = b'qd, T0),
  the Lagrangian, the total non-conservative force, and cached CasADi Functions;
- ``Probe``: deterministic random states and "identically zero" tests (a structural check on
  the SX first, then a numeric check at random states);
- ``structure``: what kind of system this is (scleronomic, autonomous, angle coordinates,
  translational symmetry directions of the equations).
"""
from __future__ import annotations

import math
from contextlib import contextmanager
from dataclasses import field

import numpy as np

from ..diagnostics import Diagnostic, MechError, UsageError, did_you_mean
from ..eom import fold_inputs
from ..eom import parameter_vector as param_vector  # noqa: F401  (re-exported)
from ..model.records import record


SEED = 20240605          # fixed: the analyses are deterministic
N_PROBE = 8              # random states used by the numeric identity checks
REL_TOL = 1e-9           # "identically zero" relative to the size of the quantity




def require_ode(eom, what: str) -> None:
    """The analyses work in minimal coordinates; constrained models (DAE) are refused."""
    if eom.g is not None and eom.g.numel() > 0:
        raise MechError(Diagnostic(
            "E901", f"{what} needs a model in independent coordinates; '{eom.name}' has "
                    f"{eom.g.numel()} holonomic constraint(s) ({', '.join(eom.constraint_names)})",
            help="describe the mechanism with independent coordinates (a tree of joints), "
                 "or analyse the constrained model numerically by simulation"))


def dense(x) -> np.ndarray:
    return np.array(x.full() if hasattr(x, "full") else x, float)


class Parts:
    """SX pieces of the Lagrangian and cached CasADi Functions of one EOM."""

    def __init__(self, eom):
        import casadi as ca

        self.eom = eom
        n = eom.n
        self.n = n
        q, qd, t, p = eom.q, eom.qd, eom.t, eom.p
        z = ca.SX.zeros(n)
        self.args = [q, qd, t, p]
        self.T0 = ca.substitute(eom.T, qd, z)
        self.b = ca.substitute(ca.gradient(eom.T, qd), qd, z)            # T1 = b'qd
        self.M = eom.M
        self.L = eom.T - eom.V
        self.Qtot = eom.Q - ca.gradient(eom.D, qd) if n else ca.SX.zeros(0)
        self.Veff = eom.V - self.T0
        self._fn: dict[str, object] = {}

    # -- cached functions -------------------------------------------------------------
    def fn(self, name: str):
        f = self._fn.get(name)
        if f is None:
            f = self._build(name)
            self._fn[name] = f
        return f

    def _build(self, name: str):
        import casadi as ca

        e = self.eom
        q, qd, t, p = self.args
        a = ca.SX.sym("a", self.n)
        if name == "M_bias":
            return ca.Function(name, self.args, [e.M, e.bias])
        if name == "lin":   # M, bias, dbias/dq, dbias/dqd, d(M a)/dq with a an extra input
            return ca.Function(name, self.args + [a], [e.M, e.bias, ca.jacobian(e.bias, q),
                                                       ca.jacobian(e.bias, qd),
                                                       ca.jacobian(ca.mtimes(e.M, a), q)])
        if name == "dbias_dp":
            return ca.Function(name, self.args, [ca.jacobian(e.bias, p)])
        if name == "probe":  # quantities used by structure(): all functions of (q, qd, t, p)
            Mv = ca.reshape(e.M, self.n * self.n, 1)
            return ca.Function(name, self.args, [
                ca.jacobian(self.L, t), ca.jacobian(e.bias, t), ca.jacobian(Mv, t),
                self.b, self.T0, e.T, self.Qtot, e.bias, Mv,
                ca.jacobian(e.bias, q), ca.jacobian(Mv, q), ca.gradient(self.L, q)])
        if name == "g":      # constraint residuals (constrained models)
            return ca.Function(name, [q, t, p], [e.g])
        if name == "energies":
            return ca.Function(name, self.args, [e.T, e.V, self.T0, self.b, e.M])
        raise KeyError(name)

    def M_bias(self, q, qd, t, p):
        M, b = self.fn("M_bias")(q, qd, t, p)
        return dense(M), dense(b).ravel()


def parts(eom) -> Parts:
    """The Parts of an EOM, built once and kept in the EOM's workspace."""
    # shared with the EOM.replace copies of the same equations
    return eom.workspace.by_content(eom, ("T", "V", "D", "Q", "M", "q", "qd", "t", "p"), "parts", lambda: Parts(eom))


# --------------------------------------------------------------------------- probing


@record(frozen=False)
class Probe:
    """Deterministic random states (q, qd, t) at which identities are checked numerically."""

    q: np.ndarray
    qd: np.ndarray
    t: np.ndarray

    @staticmethod
    def states(n: int, count: int = N_PROBE, q_center: np.ndarray | None = None) -> "Probe":
        rng = np.random.default_rng(SEED)
        c = np.zeros(n) if q_center is None else np.asarray(q_center, float)
        q = c + rng.uniform(-1.3, 1.3, (count, n)) + 0.17
        qd = rng.uniform(-1.1, 1.1, (count, n))
        t = rng.uniform(0.3, 2.7, count)
        return Probe(q, qd, t)

    def __len__(self) -> int:
        return len(self.t)


def at_states(f, pr: Probe, pv) -> list[list[np.ndarray]]:
    """``[[dense(o) for o in f(q, qd, t, pv)] for each state of pr]``, from one call of ``f``'s map
    (the same evaluation of each state as a call each, without the Python round trips per state
    and output: about 30 ms of the 12-link chain's first run, 70 states in the rotation search)."""
    count = len(pr)
    if count == 0:
        return []
    blocks = stacked_states(f, pr, pv)
    widths = [f.size2_out(j) for j in range(f.n_out())]
    return [[b[:, i * w:(i + 1) * w] for b, w in zip(blocks, widths)] for i in range(count)]


def stacked_states(f, pr: Probe, pv) -> list[np.ndarray]:
    """``f``'s outputs at every state of pr side by side, one dense block per output (rows x
    states * columns; state i's value in the columns i*columns ... (i+1)*columns - 1)."""
    count = len(pr)
    outs = f.map(count)(pr.q.T, pr.qd.T, pr.t.reshape(1, count), pv)
    if f.n_out() == 1:
        outs = [outs]
    return [dense(o) for o in outs]


def _is_structural_zero(x) -> bool:
    import casadi as ca

    x = ca.SX(x)
    return x.nnz() == 0 or all(x.nz[i].is_zero() for i in range(x.nnz()))


def vanishes(values: list[np.ndarray], scale: float, rel: float = REL_TOL) -> bool | None:
    """True when every finite sample is below rel*scale; None when no sample was finite."""
    finite = [np.asarray(v, float).ravel() for v in values if np.all(np.isfinite(v))]
    if not finite:
        return None
    return all(np.max(np.abs(v), initial=0.0) <= rel * max(scale, 1e-300) for v in finite)


@record(frozen=False)
class Structure:
    """What kind of mechanical system an EOM describes (for the given parameter values)."""

    n: int
    autonomous: bool                 # the equations of motion do not depend on t
    lagrangian_time_free: bool       # dL/dt == 0
    has_T1: bool                     # terms linear in the speeds (gyroscopic / moving frame)
    has_T0: bool                     # terms without speeds (moving frame: V_eff = V - T0)
    time_in_T: bool
    conservative: bool               # no dissipation and no non-conservative force
    periodic: tuple[bool, ...]       # equations 2 pi-periodic in the coordinate
    angle_unit: tuple[bool, ...]     # declared unit rad
    symmetry: np.ndarray             # (n, k) orthonormal directions the equations are invariant along
    force_scale: float               # typical size of the generalized forces
    stiffness_scale: float = 0.0     # typical size of d bias/dq
    quadratic_T: bool = True
    notes: list[str] = field(default_factory=list)
    # per coordinate: the typical size of its generalized force at rest (a coordinate without a
    # force of its own: the smallest of the others), so that a stiff spring on one coordinate does
    # not make a force of 10 N on another look like zero (issue 23)
    force_scales: np.ndarray | None = None

    def scales(self) -> np.ndarray:
        if self.force_scales is None:
            return np.full(self.n, max(self.force_scale, 1e-300))
        return self.force_scales

    @property
    def scleronomic(self) -> bool:
        return not (self.has_T1 or self.has_T0 or self.time_in_T)

    @property
    def angles(self) -> tuple[bool, ...]:
        return tuple(a or b for a, b in zip(self.periodic, self.angle_unit))


def structure(eom, p=None) -> Structure:
    """Classify the system numerically at deterministic random states (see module doc).

    Cached on the EOM per parameter vector."""
    eom = fold_inputs(eom)          # inputs held at their defaults: trailing parameters
    pv = param_vector(eom, p)
    def build():
        with np.errstate(all="ignore"):     # probes with huge values overflow: judged by finiteness, not printed
            return _structure(eom, pv)

    return eom.workspace.shared(("structure", pv.tobytes(), id(parts(eom))), build)


def _structure(eom, pv) -> Structure:
    pt = parts(eom)
    n = eom.n
    pr = Probe.states(n)
    f = pt.fn("probe")
    rows = []
    for i, out in enumerate(at_states(f, pr, pv)):
        if all(np.all(np.isfinite(o)) for o in out):
            rows.append((i, out))
    if not rows:
        raise MechError(Diagnostic("E902", f"the equations of '{eom.name}' could not be evaluated "
                                           "at any probe state (NaN/inf everywhere)"))

    def col(k):
        return [o[k] for _, o in rows]

    def scale_of(k):
        return max((float(np.max(np.abs(v), initial=0.0)) for v in col(k)), default=0.0)

    L_scale = max(scale_of(5), 1e-300)
    bias_scale = max(scale_of(7), 1e-300)
    M_scale = max(scale_of(8), 1e-300)
    lag_tf = _zero_or_sym(pt.L, eom.t) or bool(vanishes(col(0), L_scale))
    auto = (_zero_or_sym(eom.bias, eom.t) or bool(vanishes(col(1), bias_scale))) and \
        (_zero_or_sym(eom.M, eom.t) or bool(vanishes(col(2), M_scale)))
    has_T1 = not (_is_structural_zero(pt.b) or bool(vanishes(col(3), L_scale)))
    has_T0 = not (_is_structural_zero(pt.T0) or bool(vanishes(col(4), L_scale)))
    t_in_T = not _zero_or_sym(eom.T, eom.t)
    if t_in_T:
        import casadi as ca

        fT = ca.Function("dTdt", pt.args, [ca.jacobian(eom.T, eom.t)])
        t_in_T = not vanishes([dense(fT(pr.q[i], pr.qd[i], pr.t[i], pv)) for i, _ in rows], L_scale)
    cons = _is_structural_zero(pt.Qtot) or bool(vanishes(col(6), bias_scale))

    # translational symmetry: directions N with d(bias)/dq N == 0 and dM/dq N == 0 everywhere
    J = np.vstack([np.vstack([o[9] / bias_scale, o[10] / M_scale]) for _, o in rows])
    if eom.m:   # constrained: the constraints must not change along N either (dg/dq N = 0)
        J = np.vstack([J, _constraint_rows(eom, pv, pr)])
    N = null_space(J, rel=1e-8) if n else np.zeros((0, 0))

    # rest forces (for tolerances): |bias(q, 0)|
    fM = pt.fn("M_bias")
    rest_b = [np.abs(fM(pr.q[i], np.zeros(n), pr.t[i], pv)[1].full()).ravel() for i, _ in rows]
    rest_b = [b for b in rest_b if np.all(np.isfinite(b))]
    rest = [float(np.max(b, initial=0.0)) for b in rest_b]
    force_scale = median(rest) if rest else 0.0
    per = np.array([median([b[j] for b in rest_b]) for j in range(n)]) if rest_b and n else np.zeros(n)
    own = per[per > 1e-12 * max(force_scale, 1e-300)]
    floor = float(np.min(own)) if own.size else max(force_scale, 1e-300)
    force_scales = np.maximum(per, floor)

    stiff = [float(np.max(np.abs(o[9]), initial=0.0)) for _, o in rows]
    periodic = _periodic_all(pt, pv, pr, bias_scale, M_scale)
    angle_unit = _declared_angles(eom)
    quad = _quadratic_T(pt, pv, pr, L_scale)
    st = Structure(n=n, autonomous=auto, lagrangian_time_free=lag_tf, has_T1=has_T1, has_T0=has_T0,
                   time_in_T=t_in_T, conservative=cons, periodic=periodic, angle_unit=angle_unit,
                   symmetry=N, force_scale=force_scale, stiffness_scale=median(stiff),
                   quadratic_T=quad, force_scales=force_scales)
    return st


def _constraint_rows(eom, pv, pr: Probe) -> np.ndarray:
    """dg/dq at the probe states, scaled by its largest entry (symmetry test of constrained models)."""
    import casadi as ca

    f = ca.Function("G", [eom.q, eom.t, eom.p], [ca.jacobian(eom.g, eom.q)])
    Gs = [dense(f(pr.q[i], pr.t[i], pv)) for i in range(len(pr))]
    Gs = [G for G in Gs if np.all(np.isfinite(G))]
    if not Gs:
        return np.zeros((0, eom.n))
    scale = max(max(float(np.max(np.abs(G), initial=0.0)) for G in Gs), 1e-300)
    return np.vstack(Gs) / scale


def _zero_or_sym(expr, var) -> bool:
    import casadi as ca

    return not ca.depends_on(ca.SX(expr), var)


def _periodic_all(pt: Parts, pv, pr: Probe, bias_scale: float, M_scale: float) -> tuple[bool, ...]:
    """``_periodic`` of every coordinate, M and bias evaluated in two mapped calls (the states and
    the states shifted by 2 pi in each coordinate in turn: the same evaluations as one call each)."""
    n, count = pt.n, min(4, len(pr))
    if count == 0:
        return tuple(_periodic(pt, pv, pr, k, bias_scale, M_scale, [], []) for k in range(n))
    f = pt.fn("M_bias")

    def at(q, qd, t):
        M, b = stacked_states(f, Probe(q, qd, t), pv)[:2]
        return [(M[:, i * n:(i + 1) * n], b[:, i].ravel()) for i in range(len(t))]
    base = at(pr.q[:count], pr.qd[:count], pr.t[:count])
    shifts = np.zeros((n, count, n))
    for k in range(n):
        shifts[k, :, k] = 2 * math.pi
    moved = at((pr.q[:count][None, :, :] + shifts).reshape(n * count, n), np.tile(pr.qd[:count], (n, 1)),
               np.tile(pr.t[:count], n))
    return tuple(_periodic(pt, pv, pr, k, bias_scale, M_scale, base, moved[k * count:(k + 1) * count])
                 for k in range(n))


def _periodic(pt: Parts, pv, pr: Probe, k: int, bias_scale: float, M_scale: float, base, moved) -> bool:
    shift = np.zeros(pt.n)
    shift[k] = 2 * math.pi
    diffs = []
    for (M1, b1), (M2, b2) in zip(base, moved):
        diffs.append(np.concatenate([(b1 - b2) / bias_scale, ((M1 - M2) / M_scale).ravel()]))
    if pt.eom.m:    # constrained: g must be periodic in the coordinate too
        fg = pt.fn("g")
        for i in range(min(4, len(pr))):
            g1 = dense(fg(pr.q[i], pr.t[i], pv)).ravel()
            g2 = dense(fg(pr.q[i] + shift, pr.t[i], pv)).ravel()
            diffs.append((g1 - g2) / max(float(np.max(np.abs(g1), initial=0.0)), 1.0))
    return bool(vanishes(diffs, 1.0, rel=1e-8))


def _declared_angles(eom) -> tuple[bool, ...]:
    model = getattr(eom, "model", None)
    out = []
    for c in eom.coords:
        unit = None
        if model is not None:
            try:
                unit = model.coordinate(c).unit
            except KeyError:
                unit = None
        out.append(bool(unit) and unit.strip().lower() in ("rad", "radian", "radians"))
    return tuple(out)


def _quadratic_T(pt: Parts, pv, pr: Probe, L_scale: float) -> bool:
    """T == 1/2 qd'M qd + b'qd + T0 at the probe states (mechanical systems always are)."""
    f = pt.fn("energies")
    diffs = []
    for i, (T, _, T0, b, M) in enumerate(at_states(f, pr, pv)):
        qd = pr.qd[i]
        diffs.append(np.array([T.item() - (0.5 * qd @ M @ qd + b.ravel() @ qd + T0.item())]))
    return vanishes(diffs, L_scale, rel=1e-8) is not False


_BLAS: list = []     # [(set_num_threads, get_num_threads) of numpy's OpenBLAS, or None]


def _openblas():
    """numpy's OpenBLAS thread setters (found among the libraries loaded, /proc/self/maps), or None."""
    if not _BLAS:
        found = None
        try:
            import ctypes

            with open("/proc/self/maps") as f:
                paths = sorted({line.split()[-1] for line in f if "openblas" in line.lower() and "/" in line})
            for path in paths:
                lib = ctypes.CDLL(path)             # (loaded already: the same handle)
                for name in ("scipy_openblas_{}_num_threads64_", "scipy_openblas_{}_num_threads",
                             "openblas_{}_num_threads64_", "openblas_{}_num_threads"):
                    set_, get = (getattr(lib, name.format(k), None) for k in ("set", "get"))
                    if set_ is not None and get is not None:
                        found = (set_, get)
                        break
                if found:
                    break
        except (OSError, ValueError, IndexError):
            found = None
        _BLAS.append(found)
    return _BLAS[0]


@contextmanager
def one_blas_thread():
    """numpy's BLAS on one thread for the block (restored after it).  The probes' SVDs are a few
    hundred rows: OpenBLAS's threads cost more CPU than they save there (a 400 x 66 SVD: 55 ms of
    CPU on two threads of a loaded machine against 2 ms on one; the 12-link chain's first run ~0.1 s),
    and each thread computes whole entries, so the numbers are the same (tests/test_analysis_blas.py)."""
    blas = _openblas()
    before = blas[1]() if blas is not None else 1
    if before <= 1:
        yield
        return
    blas[0](1)
    try:
        yield
    finally:
        blas[0](before)


def null_space(J: np.ndarray, rel: float = 1e-8) -> np.ndarray:
    """Orthonormal basis (columns) of the null space of J, in a deterministic orientation.
    A J with inf or nan entries (values that overflowed) has no basis to claim: none is
    returned (LAPACK's SVD does not return on nan input; heavy_top with g = 1e308 hung
    `mech check` in the symmetry search)."""
    n = J.shape[1]
    if not np.all(np.isfinite(J)):
        return np.zeros((n, 0))
    if J.size == 0 or not np.any(J):
        return np.eye(n)
    # thin SVD when J is tall (probes stack many rows): the full U would cost O(rows^2)
    with one_blas_thread():
        _, s, vt = np.linalg.svd(J, full_matrices=J.shape[0] < n)
    rank = int(np.sum(s > rel * s[0]))
    N = vt[rank:].T.copy()
    return canonical_basis(N)


def canonical_basis(N: np.ndarray) -> np.ndarray:
    """A deterministic basis of span(N): coordinate axes where they lie in it, then the rest.

    Columns are orthonormal; each is signed so that its largest entry is positive.
    """
    n, k = N.shape
    if k == 0:
        return N
    P = N @ N.T
    cols = []
    for i in range(n):
        e = np.zeros(n)
        e[i] = 1.0
        if np.linalg.norm(P @ e - e) < 1e-8:
            cols.append(e)
    if len(cols) < k:
        # complement of the axis vectors inside span(N): reduced row echelon form, orthonormalized
        E = np.array(cols).T if cols else np.zeros((n, 0))
        R = N - E @ (E.T @ N)
        u, s, _ = np.linalg.svd(R, full_matrices=False)
        rest = u[:, : k - len(cols)]
        rest = _rref_cols(rest)
        for c in rest.T:
            for e in cols:
                c = c - (e @ c) * e
            c = c / np.linalg.norm(c)
            j = int(np.argmax(np.abs(c) > 1e-9 * np.max(np.abs(c))))
            cols.append(c if c[j] > 0 else -c)
    return np.array(cols).T


def _rref_cols(B: np.ndarray) -> np.ndarray:
    """Columns spanning the same space, in reduced echelon form (deterministic directions)."""
    A = B.T.copy()
    r = 0
    for c in range(A.shape[1]):
        if r >= A.shape[0]:
            break
        piv = r + int(np.argmax(np.abs(A[r:, c])))
        if abs(A[piv, c]) < 1e-10:
            continue
        A[[r, piv]] = A[[piv, r]]
        A[r] /= A[r, c]
        for i in range(A.shape[0]):
            if i != r:
                A[i] -= A[i, c] * A[r]
        r += 1
    return A.T


def wrap_angle(x: float) -> float:
    """Angle in (-pi, pi]."""
    return math.pi - ((math.pi - x) % (2 * math.pi))


def median(xs) -> float:
    """``float(np.median(xs))`` of a 1-D sequence, without np.median's import of numpy.ma
    (11 ms of every ``mech check``): the middle of the sorted values, or the mean of the two."""
    a = np.sort(np.asarray(xs, dtype=float).ravel())
    if a.size == 0 or np.isnan(a[-1]):       # np.sort puts NaN last; np.median gives NaN
        return float("nan")
    k = a.size // 2
    return float(a[k]) if a.size % 2 else float(np.mean(a[k - 1:k + 1]))


def named_multipliers(names, values) -> dict[str, float]:
    """Multipliers by constraint name, as they are (the lambda of M q'' = f - G' lambda, in the
    units of eom.multiplier_units); empty without multipliers."""
    if values is None:
        return {}
    return {c: float(v) for c, v in zip(names, values)}
