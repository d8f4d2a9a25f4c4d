"""A prepared run as one differentiable CasADi Function: ``Prepared.trajectory() -> Trajectory``.

    tr = prepare(problem).trajectory(times=None, integrals=())
    tr.function      (x0, p) -> (Y, Q): the recorded signals on the times (rows: tr.names,
                     columns: tr.times) and the running integrals of the signals named in
                     ``integrals`` (quadratures of the integrator, one row each)
    tr.start(p, x0)  the run's start at the parameters p (x0: the settings' start overrides)
                     and its derivatives with respect to p and to the start values given
    tr.forward(x0, p, DX, DP)   Y and its directional derivatives along the columns of DX, DP
    tr.reverse(x0, p, seeds)    the adjoint: seeds on (Y, Q) -> (d/dx0, d/dp)

It integrates what a run integrates: the Functions (``OdeSetup.funcs``; a constrained
model's index-1 ODE with the multipliers solved, ``functions.problem_functions``), the method
(``auto`` resolved as the run resolved it), the integrator's options (tolerances, step
budget, fixed steps, the user's integrator_options) and the pieces between the input tables'
samples; and records what a run records (``record.function``: coordinates, speeds, outputs,
energies, with the multipliers a constrained model's outputs read; the inputs' values).  Its derivatives are
CasADi's: ``Function.forward(k)`` / ``.reverse(m)`` of the integrator (forward sensitivities
and adjoints of CVODES / IDAS, the exact derivatives of the discrete solution for erk, rk and
collocation), never a second integrator written here.  Used by ``Model.sensitivities`` and
``Model.fit`` (mechdsl.estimation).
"""
from __future__ import annotations

import casadi as ca
import numpy as np

from .. import integrators as I
from ..diagnostics import UsageError
from ..eom import parameter_vector
from ..eom.codegen import TXUP, casadi_functions
from ..eom.start import start_vector, state_key
from . import record as R
from .backends import backend
from .backends.ode import MAX_STEPS_TOTAL
from .choose import fixed_step_count, min_step
from .registry import METHODS, spec
from .settings import DEFAULT_POINTS


_START_JACOBIANS: dict = {}       # id(start Function) -> (it, the Function of its Jacobian): holding it keeps the id
_TRAJECTORIES: dict = {}          # (id(eom), kind, settings, times, integrals) -> (eom, Trajectory)
_TRAJECTORY_CACHE_SIZE = 8


def cached_trajectory(problem, setup, times, integrals) -> "Trajectory":
    """The Trajectory of ``problem`` on ``times`` with ``integrals``, reused while the model's
    equations, the settings and the times are the same: building the Function and, above
    all, its derivative Functions (``function.forward(k)``: 0.1 s for the double pendulum on
    1,000 points) costs more than a run, and a sensitivity study or a fit calls again and
    again.  Settings that cannot be hashed (input functions) build afresh."""
    grid = None if times is None else np.atleast_1d(np.asarray(times, float)).tobytes()
    key = (id(problem.eom), problem.kind, problem.backend, problem.settings, grid, tuple(integrals))
    try:
        hit = _TRAJECTORIES.get(key)
    except TypeError:                 # an unhashable setting
        return Trajectory(problem, setup, times=times, integrals=tuple(integrals))
    if hit is not None and hit[0] is problem.eom:
        return hit[1]
    tr = Trajectory(problem, setup, times=times, integrals=tuple(integrals))
    if len(_TRAJECTORIES) >= _TRAJECTORY_CACHE_SIZE:
        _TRAJECTORIES.pop(next(iter(_TRAJECTORIES)))
    _TRAJECTORIES[key] = (problem.eom, tr)
    return tr


def casadi_methods() -> list[str]:
    return [k for k, v in METHODS.items() if v.family == "casadi"]


class Trajectory:
    """See the module docstring.  Built by ``Prepared.trajectory``; holds no values, only the
    Functions (evaluate it at any parameters and start values)."""

    def __init__(self, problem, setup, times=None, integrals=()):
        self.problem = problem
        s, eom = problem.settings, problem.eom
        self.eom, self.settings = eom, s
        self.constrained = problem.kind == "dae"
        self.drive = problem.drive if problem.kind == "ode" else None
        self.backend = backend(problem.backend)
        pv = parameter_vector(eom, s.p)
        xs = self.start(pv)[0]
        self.method, self.funcs, why = self._method(setup, pv, xs)
        self.method_reason = why
        grid = setup.grid if setup is not None and times is None else None
        if grid is None:
            grid = (np.linspace(s.t_start, s.t_end, s.points or DEFAULT_POINTS) if times is None
                    else _times(times, s.t_start, s.t_end))
        self.times = np.asarray(grid, float)
        self.names, self.signal = self._signals()
        unknown = [k for k in integrals if k not in self.names]
        if unknown:
            raise UsageError(f"integral of {', '.join(map(repr, unknown))}: not a recorded signal of {eom.name} "
                             f"(signals: {', '.join(self.names)})")
        self.integrals = tuple(integrals)
        self.max_steps = int(s.max_steps or max(20_000, MAX_STEPS_TOTAL // max(1, len(self.times) - 1)))
        self.extra = dict(s.integrator_options or {}) if not self.constrained else {}
        self.fixed_dt = self._fixed_dt(pv, xs)
        self.function = self._build()
        self._fwd: dict[int, ca.Function] = {}
        self._rev: dict[int, ca.Function] = {}

    # ------------------------------------------------------------------ what runs
    def _method(self, setup, pv, xs):
        m, funcs, why = self.backend.integration(self.problem, setup, pv, xs)
        if spec(m).family != "casadi":
            raise UsageError(f"method '{m}' has no CasADi integrator, and sensitivities are CasADi's forward "
                             f"and adjoint sensitivities of the run's integrator: choose one of "
                             f"{', '.join(casadi_methods())} (or auto)")
        return m, funcs, why

    def _fixed_dt(self, pv, xs):
        """The fixed step of rk / collocation, as a run takes it (from rtol at the start, or dt)."""
        if not spec(self.method).fixed_step:
            return None
        s = self.settings
        steps, _ = fixed_step_count(self.method, casadi_functions(self.eom, names=("ode", "ode_jacobian")),
                                    xs, pv, s.t_start, s.t_end, s.rtol, s.fixed_step.dt, 10 * s.budget,
                                    u=self._u(s.t_start))
        return (s.t_end - s.t_start) / steps

    def _u(self, t):
        if self.drive is None:
            return np.zeros(self.eom.u_sym.numel()) if self.eom.inputs else np.zeros(0)
        return self.drive.vector(t)

    def _options(self, a, b):
        m = spec(self.method)
        steps = None if self.fixed_dt is None else max(1, int(np.ceil((b - a) / self.fixed_dt - 1e-9)))
        return I.casadi_options(m.plugin, m.options, self.settings.rtol, self.settings.atol, self.max_steps, steps,
                                self.extra, hmin=min_step(a, b))

    # ------------------------------------------------------------------ what is recorded
    def _signals(self):
        """(names, Function (t, x, u, p) -> the recorded signals at one time): the state, the
        outputs and the energies, as the run's recorder computes them (u: the values the
        integrator's parameter carries, i.e. the zero-order holds; other signals closed in)."""
        eom = self.eom
        n = eom.n
        outs = [o for o in (self.settings.outputs if self.settings.outputs is not None else eom.outputs)
                if o in eom.outputs]
        cols = R.merged(R.outputs(eom, outs), R.energies(eom))
        col_names, rec = R.function(eom, cols)
        t, x = ca.MX.sym("t"), ca.MX.sym("x", 2 * n)
        u, p = ca.MX.sym("u", self._u(self.settings.t_start).size), ca.MX.sym("p", eom.p.numel())
        if self.drive is not None and self.drive.signals:
            U = self.drive.expression(t, x, held=u)
        else:
            U = ca.MX(eom.input_defaults) if eom.inputs else ca.MX(0, 1)
        if self.constrained:
            lam = self.funcs["multipliers"](t, x, ca.MX(0, 1), p)
        else:
            lam = ca.MX.zeros(R.lam_symbol(eom).numel())
        y = ca.vertcat(x, rec(t, x[:n], x[n:], U, p, lam))
        names = list(eom.coords) + [f"der({c})" for c in eom.coords] + list(col_names)
        if self.drive is not None and self.drive.signals:     # the inputs' values, as the run records them
            fresh = [j for j, k in enumerate(self.drive.names) if k not in names]
            y = ca.vertcat(y, U[fresh])
            names += [self.drive.names[j] for j in fresh]
        return tuple(names), ca.Function("signals", [t, x, u, p], [y], TXUP, ["y"])

    # ------------------------------------------------------------------ the Function
    def _pieces(self):
        s = self.settings
        t0, t1 = s.t_start, float(self.times[-1])
        breaks = self.drive.breakpoints(t0, t1) if self.drive is not None else np.zeros(0)
        return np.r_[t0, breaks, t1]

    def _build(self) -> ca.Function:
        eom, m = self.eom, spec(self.method)
        ode = self.funcs["ode"]
        nx, np_ = 2 * eom.n, eom.p.numel()
        x0, p = ca.MX.sym("x0", nx), ca.MX.sym("p", np_)
        edges = self._pieces()
        full = np.union1d(self.times, edges)
        on = np.isin(full, self.times)
        quad = self._quadrature() if self.integrals else None
        dae = I.dae_function(ode) if quad is None else quad
        cols_x, cols_q, x, q_end = [], [], x0, ca.MX.zeros(len(self.integrals))
        for a, b in zip(edges[:-1], edges[1:]):
            idx = np.flatnonzero((full >= a) & (full <= b))
            if cols_x:
                idx = idx[1:]          # the piece's start is the last piece's end
                grid = np.r_[a, full[idx]]
            else:
                grid = full[idx]
            if grid.size < 2:
                grid = np.r_[a, b]
                keep = slice(1, 1) if cols_x else slice(0, 1)
            else:
                keep = slice(1, None) if cols_x else slice(None)
            integ = I.make_integrator("trajectory", m.plugin, dae, float(grid[0]), grid, self._options(a, b))
            res = integ(x0=x, p=ca.vertcat(self._u(a), p))
            X = res["xf"]
            cols_x.append(X[:, keep])
            if quad is not None:
                Q = res["qf"] + ca.repmat(q_end, 1, grid.size)
                cols_q.append(Q[:, keep])
                q_end = Q[:, -1]
            x = X[:, -1]
        X = ca.horzcat(*cols_x)
        if X.size2() != full.size:
            raise AssertionError(f"trajectory: {X.size2()} columns for {full.size} times")   # pragma: no cover
        sel = [int(i) for i in np.flatnonzero(on)]
        X = X[:, sel]
        N = len(self.times)
        U = np.array([self._u(float(t) + 1e-12 * max(1.0, abs(float(t)))) for t in self.times]).reshape(N, -1).T
        Y = self.signal.map(N)(ca.DM(self.times).T, X, ca.DM(U), ca.repmat(p, 1, N))
        outs, names = [Y], ["y"]
        if quad is not None:
            outs.append(ca.horzcat(*cols_q)[:, sel])
            names.append("q")
        return ca.Function("trajectory", [x0, p], outs, ["x0", "p"], names)

    def _quadrature(self):
        """The DAE scheme of the run's ode with the integrals' integrands as quadratures."""
        ode = self.funcs["ode"]
        nu = ode.size1_in(2)
        t, x = ca.MX.sym("t"), ca.MX.sym("x", ode.size1_in(1))
        pp = ca.MX.sym("p", nu + ode.size1_in(3))
        u, p = pp[:nu], pp[nu:]
        y = self.signal(t, x, u, p)
        rows = [self.names.index(k) for k in self.integrals]
        e = ca.MX(0, 1)
        return ca.Function("dae", [t, x, e, pp, e], [ca.densify(ode(t, x, u, p)), e, ca.densify(y[rows]), e],
                           ca.dyn_in(), ca.dyn_out())          # dense: CasADi's integrators refuse sparse outputs

    # ------------------------------------------------------------------ the start
    def start(self, pv, x0=None):
        """(x, dx/dp, dx/dx_given): the run's start at the parameters ``pv`` with the start
        overrides ``x0`` (default: the settings'), and its derivatives: with respect to the
        parameters (start values written as expressions of them, and a constrained model's
        consistent initialization), and to the start values given (consistent initialization
        keeps some of them and changes others: its linearization; identity without constraints)."""
        eom = self.eom
        x0 = self.settings.x0 if x0 is None else x0
        pv = np.asarray(pv, float)
        xs = start_vector(eom, x0, pv)
        dstart = self._start_jacobian(pv)
        dstart[_overridden(eom, x0), :] = 0.0
        x, Jx, Jp = self.backend.start(self.problem, xs, pv, x0)
        if not self.constrained:        # the start as given (Jx = I, Jp = 0): no product of n x n matrices
            return x, dstart + Jp, Jx
        return x, Jx @ dstart + Jp, Jx

    def _start_jacobian(self, pv):
        f = casadi_functions(self.eom, names=("start",))["start"]
        hit = _START_JACOBIANS.get(id(f))          # per model's start Function: a trajectory is built per call
        if hit is None or hit[0] is not f:
            p = ca.SX.sym("p", f.size1_in(0))
            q0, qd0 = f(p)
            if len(_START_JACOBIANS) > 32:
                _START_JACOBIANS.clear()
            hit = _START_JACOBIANS[id(f)] = (f, ca.Function("dstart", [p], [ca.jacobian(ca.vertcat(q0, qd0), p)]))
        return np.array(hit[1](pv), float).reshape(2 * self.eom.n, -1)

    # ------------------------------------------------------------------ derivatives
    def evaluate(self, x0, p):
        """(Y, Q) at the start x0 and parameters p (Q None without integrals)."""
        out = self.function(x0, p)
        out = out if isinstance(out, (list, tuple)) else [out]
        Y = np.array(out[0], float)
        return Y, (np.array(out[1], float) if len(out) > 1 else None)

    def forward(self, x0, p, DX, DP):
        """(Y, Q, dY, dQ): values and the derivatives along the k directions (columns of DX
        (nx, k) and DP (np, k)); dY has shape (k, n_signals, n_times)."""
        DX, DP = np.atleast_2d(DX), np.atleast_2d(DP)
        k = DX.shape[1]
        Y, Q = self.evaluate(x0, p)
        if k == 0:
            return Y, Q, np.zeros((0,) + Y.shape), None if Q is None else np.zeros((0,) + Q.shape)
        f = self._fwd.get(k)
        if f is None:
            f = self._fwd[k] = self.function.forward(k)
        nominal = [Y] + ([Q] if Q is not None else [])
        res = f(x0, p, *nominal, DX, DP)
        res = res if isinstance(res, (list, tuple)) else [res]
        dY = _split(np.array(res[0], float), k)
        dQ = _split(np.array(res[1], float), k) if Q is not None else None
        return Y, Q, dY, dQ

    def reverse(self, x0, p, seed_y, seed_q=None, nominal=None):
        """Adjoint: seeds (m, n_signals, n_times) on Y and (m, n_integrals, n_times) on Q ->
        (d/dx0 (m, nx), d/dp (m, np)), one row per seed, and the nominal (Y, Q) (``nominal``:
        already evaluated at x0, p; else one run more)."""
        Y, Q = self.evaluate(x0, p) if nominal is None else nominal
        seed_y = np.asarray(seed_y, float)
        m = seed_y.shape[0]
        f = self._rev.get(m)
        if f is None:
            f = self._rev[m] = self.function.reverse(m)
        nominal = [Y] + ([Q] if Q is not None else [])
        seeds = [np.hstack(list(seed_y))]
        if Q is not None:
            sq = np.zeros((m,) + Q.shape) if seed_q is None else np.asarray(seed_q, float)
            seeds.append(np.hstack(list(sq)))
        ax, ap = f(x0, p, *nominal, *seeds)
        return (np.array(ax, float).reshape(-1, m, order="F").T, np.array(ap, float).reshape(-1, m, order="F").T,
                Y, Q)

    def describe(self) -> dict:
        m = spec(self.method)
        return {"method": self.method, "integrator": f"{m.family}:{m.plugin}", "why": self.method_reason,
                "rtol": self.settings.rtol, "atol": self.settings.atol,
                **({"fixed_step": self.fixed_dt} if self.fixed_dt is not None else {}),
                **({"pieces": int(self._pieces().size - 1)} if self._pieces().size > 2 else {})}


def _split(A: np.ndarray, k: int) -> np.ndarray:
    """(rows, k * cols) horizontally concatenated directions -> (k, rows, cols)."""
    cols = A.shape[1] // k
    return np.stack([A[:, j * cols:(j + 1) * cols] for j in range(k)])


def _overridden(eom, x0) -> list[int]:
    if x0 is None:
        return []
    if isinstance(x0, dict):
        return [state_key(eom, str(k)) for k in x0]
    return list(range(2 * eom.n))


def _times(times, t0, t1) -> np.ndarray:
    t = np.atleast_1d(np.asarray(times, float)).ravel()
    if t.size == 0:
        raise UsageError("times: give at least one time")
    if not np.isfinite(t).all():
        raise UsageError("times: every time must be a finite number")
    tol = 1e-12 * max(1.0, abs(t0), abs(t1))
    bad = t[(t < t0 - tol) | (t > t1 + tol)]
    if bad.size:
        raise UsageError(f"times: {bad[0]:g} s is outside the run [{t0:g}, {t1:g}] s")
    return np.unique(np.r_[t0, np.clip(t, t0, t1)])
