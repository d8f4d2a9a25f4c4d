"""``Model.fit``: parameters and start values from measured motion, by least squares.

    r = m.fit("tracked.csv", params=["l1", "l2", "m1", "m2"])
    r.estimates["l1"], r.standard_errors["l1"]      in the declared units
    print(r.table()); r.identifiability             what the data cannot determine
    r.plot("fit.png")                               the data and the fitted model

The residual of experiment e, column c, sample k is w_c (y_c(t_k; theta) - d_c,k), the model's
recorded signal at the sample times from one run of the experiment's prepared problem
(``Prepared.trajectory(times=data times)``).  The minimizer (``levenberg_marquardt``) takes
Gauss-Newton steps damped by Levenberg-Marquardt, clipped to the bounds, its Jacobian the
forward sensitivities of the run (one integration with k directions per iteration, CasADi's),
in log-parameter space; each step is the minimum-norm one over the directions the data
resolve, so a combination the data cannot determine keeps its start value instead of
wandering; a trial step whose run fails counts as a rejected step.  At the estimate: the noise variance s^2 = |r|^2 / (N - rank), the covariance
s^2 (J' J)^+ (the Fisher information's inverse on the directions the data determine), standard
errors and correlations from it, and the directions J cannot see (identify.py) named as
products of powers of the parameters.
"""
from __future__ import annotations

import time

import numpy as np

from ..diagnostics import UsageError, did_you_mean
from ..eom import parameter_vector
from ..model.records import record
from ..simulation.prepared import prepare
from . import data as D
from .identify import RANK_TOL, determined, identifiability, log_scale
from .sensitivity import check_kind, signal_units
from .unknowns import unknowns

SOLVERS = ("lm",)            # Levenberg-Marquardt with exact sensitivities


@record(frozen=False)
class _Run:
    """One experiment: its data, trajectory, unknowns and where they sit in theta."""
    exp: object
    tr: object
    unk: object
    where: np.ndarray          # global index of each local unknown
    rows: list                 # rows of tr.names measured (data column order)
    cols: np.ndarray           # columns of tr.times at the data times
    pv: np.ndarray             # the parameter vector of the settings
    x0: object                 # the settings' start overrides
    w: np.ndarray              # (n_columns, N) weights


class FitResult:
    """What a fit found (see the module docstring); values in the declared units."""

    def __init__(self, **kw):
        self.__dict__.update(kw)

    def table(self) -> str:
        """The estimates: name, estimate, standard error, unit; what cannot be determined; the
        residual norm."""
        from ..analysis.tables import num, table

        rows = []
        for n in self.names:
            se = self.standard_errors[n]
            rel = se / abs(self.estimates[n]) if np.isfinite(se) and self.estimates[n] != 0 else None
            rows.append([n, num(self.estimates[n]), num(se) if np.isfinite(se) else "not determined",
                         self.units[n] or "-", f"{100 * rel:.2g}%" if rel is not None else "",
                         num(self.initial[n])])
        lines = [f"{self.model_name}: least-squares fit to {self.n_observations} values "
                 f"({len(self.experiments)} experiment{'s' if len(self.experiments) > 1 else ''}), "
                 f"{self.iterations} iterations, {self.message if self.success else 'NOT converged: ' + self.message}",
                 table(["name", "estimate", "std error", "unit", "rel.", "start"], rows, "  ")]
        if self.unidentifiable:
            lines.append("  cannot be determined from these data:")
            for c in self.unidentifiable:
                lines.append(f"    {c.text}" + (f"  (only {c.determinable} can: {num(c.value)} +- "
                                                  f"{num(c.standard_error)}{' ' + c.unit if c.unit else ''})"
                                                  if c.determinable else ""))
        lines.append(f"  residual norm {num(self.residual_norm)} (weighted), noise estimate s = {num(self.sigma)} "
                     f"from {self.degrees_of_freedom} degrees of freedom")
        for name, (rms, unit) in self.rms.items():
            lines.append(f"    rms residual {name}: {num(rms)}" + (f" {unit}" if unit else ""))
        return "\n".join(lines)

    def to_dict(self) -> dict:
        return {"model": self.model_name, "names": list(self.names),
                "estimates": {n: _f(v) for n, v in self.estimates.items()},
                "standard_errors": {n: _f(v) for n, v in self.standard_errors.items()},
                "units": dict(self.units), "initial": {n: _f(v) for n, v in self.initial.items()},
                "correlation": [[_f(v) for v in row] for row in self.correlation],
                "unidentifiable": [c.to_dict() for c in self.unidentifiable],
                "relative_singular_values": [_f(v) for v in self.singular_values],
                "residual_norm": _f(self.residual_norm), "sigma": _f(self.sigma),
                "degrees_of_freedom": int(self.degrees_of_freedom), "n_observations": int(self.n_observations),
                "rms": {k: {"value": _f(v), "unit": u} for k, (v, u) in self.rms.items()},
                "success": bool(self.success), "message": self.message, "iterations": int(self.iterations),
                "cpu_time": float(self.cpu_time), "experiments": [e.label for e in self.experiments],
                "integration": self.integration}

    def plot(self, path=None, overwrite: bool = False, title: str | None = None):
        """The measured samples and the fitted model's signals over time, one panel per measured
        column (every experiment in it); written atomically when ``path`` is given, else the
        matplotlib Figure."""
        from ..output.plot import save_figure
        from .plot import fit_figure

        fig = fit_figure(self, title)
        return fig if path is None else save_figure(fig, path, overwrite=overwrite)

    def __repr__(self) -> str:
        est = ", ".join(f"{n} = {self.estimates[n]:.6g}" for n in self.names)
        return f"<FitResult {self.model_name}: {est}>"


def _f(v) -> float | None:
    v = float(v)
    return v if np.isfinite(v) else None


def fit(model, data, params=(), starts=(), weights=None, bounds=None, experiments=None, *, method: str = "lm",
        max_iterations: int = 100, rank_tol: float = RANK_TOL, t_end=None, settings=None) -> FitResult:
    """See ``Model.fit`` (``settings``: the runs', ``method`` there the integrator's)."""
    settings = dict(settings or {})
    cpu0 = time.process_time()
    if method not in SOLVERS:
        hint = did_you_mean(str(method), SOLVERS)
        raise UsageError(f"method must be one of {', '.join(SOLVERS)} (got {method!r})" + (f"; {hint}" if hint else ""))
    if isinstance(max_iterations, bool) or not isinstance(max_iterations, (int, np.integer)) or max_iterations < 1:
        raise UsageError(f"max_iterations must be a whole number >= 1 (got {max_iterations!r})")
    if settings.get("compiled"):
        raise UsageError("compiled = true: a fit differentiates the run's Functions in CasADi's virtual machine")
    settings["compiled"] = False
    exps = D.experiments(data, experiments)
    runs, names, kinds, theta0, lower, upper, factors, units = _setup(model, exps, params, starts, settings, t_end)
    _check_weights(weights, runs)
    for r in runs:
        r.w = _weights(weights, r)
    lo, hi = _bounds(bounds, names, factors, lower, upper, theta0)
    cache: dict = {}

    def evaluate(theta, jac: bool):
        key = theta.tobytes()
        hit = cache.get(key)
        if hit is not None and (hit[1] is not None or not jac):
            return hit
        res, J = [], []
        for r in runs:
            local = theta[r.where]
            pv = r.unk.parameter_values(r.tr.eom, r.pv, local)
            x0 = r.unk.start_overrides(r.tr.eom, r.x0, local)
            x, dx_dp, dx_dx = r.tr.start(pv, x0)
            if jac:
                DX, DP = r.unk.seeds(r.tr.eom, pv, dx_dp, dx_dx)
                Y, _, dY, _ = r.tr.forward(x, pv, DX, DP)
                Jr = np.zeros((r.w.size, theta.size))
                Jr[:, r.where] = (dY[:, r.rows][:, :, r.cols] * r.w[None]).reshape(len(r.where), -1).T
                J.append(Jr)
            else:
                Y, _ = r.tr.evaluate(x, pv)
            res.append(((Y[r.rows][:, r.cols] - r.exp.Y) * r.w).ravel())
        out = (np.concatenate(res), np.vstack(J) if jac else None)
        if len(cache) > 8:
            cache.clear()
        cache[key] = out
        return out

    try:
        r0 = evaluate(theta0, True)[0]
    except RuntimeError as e:
        raise UsageError(f"the run at the fit's start values fails: {str(e).strip().splitlines()[-1]}") from None
    if not np.isfinite(r0).all():
        raise UsageError("the run at the fit's start values is not finite: start from other values (--start)")
    sol = levenberg_marquardt(evaluate, theta0, lo, hi, log_scale(theta0, kinds), rank_tol, int(max_iterations))
    r, J = evaluate(sol.theta, True)
    return _result(model, exps, runs, names, kinds, sol.theta, theta0, factors, units, r, J, sol, rank_tol, cpu0)


@record(frozen=False)
class Solution:
    theta: np.ndarray
    success: bool
    message: str
    iterations: int            # accepted steps
    evaluations: int           # runs (each step tried is one; each Jacobian one with sensitivities)
    jacobians: int


def levenberg_marquardt(evaluate, theta0, lo, hi, scale, rank_tol, max_iterations, ftol=1e-10, xtol=1e-10,
                        gtol=1e-12) -> Solution:
    """Gauss-Newton steps damped by Levenberg-Marquardt (Nielsen's update of the damping), in the
    variables theta / scale (log-parameter space), each step the minimum-norm solution over the
    directions the Jacobian resolves (singular values above ``rank_tol`` of the largest): a
    direction the data cannot see keeps its start value.  Steps are clipped to the bounds; a
    step whose run fails is rejected.  ``evaluate(theta, jac) -> (r, J or None)``."""
    theta = theta0.copy()
    r, J = evaluate(theta, True)
    cost = 0.5 * float(r @ r)
    lam, nu = None, 2.0
    n_eval, n_jac, it = 1, 1, 0
    message, success = f"stopped after {max_iterations} iterations (max_iterations)", False
    while it < max_iterations:
        Js = J * scale[None, :]
        U, s, Vt = np.linalg.svd(Js, full_matrices=False)
        smax = float(s.max()) if s.size else 0.0
        keep = s > rank_tol * smax
        Ur = U[:, keep].T @ r
        grad = Js.T @ r
        if smax == 0.0 or np.max(np.abs(grad), initial=0.0) <= gtol * max(1.0, 2 * cost):
            message, success = "converged: the gradient vanishes", True
            break
        if lam is None:
            lam = 1e-3 * smax ** 2
        while True:
            d = s[keep] / (s[keep] ** 2 + lam)
            du = -Vt[keep].T @ (d * Ur)
            new = np.clip(theta + scale * du, lo, hi)
            du = (new - theta) / scale
            pred = -(grad @ du) - 0.5 * float(np.sum((Js @ du) ** 2))
            if 0 <= pred <= ftol * cost and lam <= 1e-3 * smax ** 2:    # Gauss-Newton itself gains nothing
                rho = None
                break
            try:
                r_new = evaluate(new, False)[0]
                n_eval += 1
                cost_new = 0.5 * float(r_new @ r_new) if np.isfinite(r_new).all() else np.inf
            except RuntimeError:
                n_eval += 1
                cost_new = np.inf
            rho = (cost - cost_new) / pred if pred > 0 else -1.0
            if rho > 0:
                lam *= max(1.0 / 3.0, 1.0 - (2.0 * rho - 1.0) ** 3)
                nu = 2.0
                break
            lam *= nu
            nu *= 2.0
            if lam > 1e16 * max(smax ** 2, 1e-300):
                break
        if rho is None:
            message, success = "converged: a Gauss-Newton step would lower the residual by less than 1e-10", True
            break
        if not rho > 0:
            message, success = "converged: no step lowers the residual (a minimum, to the runs' accuracy)", True
            break
        it += 1
        small_step = np.linalg.norm(du) <= xtol * (np.linalg.norm(theta / scale) + xtol)
        small_gain = cost - cost_new <= ftol * cost
        theta, cost = new, cost_new
        r, J = evaluate(theta, True)
        n_jac += 1
        if small_step or small_gain:
            message = ("converged: the step is below the tolerance" if small_step else
                       "converged: the residual no longer decreases (relative change below 1e-10)")
            success = True
            break
    return Solution(theta, success, message, it, n_eval, n_jac)


def _setup(model, exps, params, starts, settings, t_end):
    """The experiments' prepared trajectories and the unknowns: parameters shared, start values
    one set per experiment (named ``c@k`` for experiment k when there are several)."""
    runs, names, kinds, theta0, lower, upper, factors, units = [], [], [], [], [], [], [], []
    many = len(exps) > 1
    for k, exp in enumerate(exps):
        s_kw = {**settings, **exp.settings}
        t_start = model.settings(**{key: v for key, v in s_kw.items() if key != "t_end"}).t_start
        t1 = float(t_end) if t_end is not None else float(exp.t[-1])
        D.check_times(exp, t_start, t1)
        problem = model.problem(t_end=t1, **s_kw)
        check_kind(model, problem)
        tr = prepare(problem).trajectory(times=exp.t)
        D.check_columns(exp, tr.names, model.name)
        unk = unknowns(model, problem.eom, params, starts)
        pv = parameter_vector(problem.eom, problem.settings.p)
        x = tr.start(pv)[0]
        vals = unk.values(pv, x)
        where = []
        for u, v in zip(unk.items, vals):
            label = u.name if (u.kind == "parameter" or not many) else f"{u.name}@{k + 1}"
            if label not in names:
                names.append(label)
                kinds.append(u.kind)
                theta0.append(v)
                lower.append(-np.inf if u.lower is None else u.lower)
                upper.append(np.inf if u.upper is None else u.upper)
                factors.append(u.factor)
                units.append(u.unit)
            where.append(names.index(label))
        rows = [tr.names.index(c) for c in exp.columns]
        cols = np.searchsorted(tr.times, exp.t)
        cols = np.clip(cols, 0, tr.times.size - 1)
        runs.append(_Run(exp, tr, unk, np.array(where, int), rows, cols, pv, problem.settings.x0, None))
    return (runs, names, kinds, np.array(theta0, float), np.array(lower, float), np.array(upper, float),
            np.array(factors, float), units)


def _check_weights(weights, runs) -> None:
    if weights is None:
        return
    if not isinstance(weights, dict):
        raise UsageError(f"weights: a dict {{column: weight}} (got {type(weights).__name__})")
    measured = sorted({c for r in runs for c in r.exp.columns})
    for k in weights:
        if k not in measured:
            hint = did_you_mean(str(k), measured)
            raise UsageError(f"weights: '{k}' is not a measured column" + (f"; {hint}" if hint else
                             f" (columns: {', '.join(measured)})"))


def _weights(weights, r) -> np.ndarray:
    """(n_columns, N): 1, or the weight given for a column (a number, or one per sample)."""
    n, N = len(r.exp.columns), r.exp.t.size
    W = np.ones((n, N))
    for i, c in enumerate(r.exp.columns):
        if weights is None or c not in weights:
            continue
        try:
            w = np.asarray(weights[c], float)
        except (TypeError, ValueError):
            raise UsageError(f"weights: the weight of '{c}' must be a number (or one per sample)") from None
        if w.ndim > 1 or (w.ndim == 1 and w.size != N):
            raise UsageError(f"weights: '{c}' needs one weight, or one per sample ({N}; got {w.size})")
        if not (np.isfinite(w).all() and (w > 0).all()):
            raise UsageError(f"weights: the weights of '{c}' must be finite and positive")
        W[i] = w
    return W


def _bounds(bounds, names, factors, lower, upper, theta0):
    """Lower and upper bounds (SI): the parameters' declared min / max, or ``bounds`` {name:
    (lo, hi)} in declared units (None: unbounded); the start must lie inside."""
    lo, hi = lower.copy(), upper.copy()
    if bounds is not None:
        if not isinstance(bounds, dict):
            raise UsageError(f"bounds: a dict {{name: (lower, upper)}} (got {type(bounds).__name__})")
        for k, v in bounds.items():
            if k not in names:
                hint = did_you_mean(str(k), names)
                raise UsageError(f"bounds: '{k}' is not fitted" + (f"; {hint}" if hint else f" (fitted: {', '.join(names)})"))
            try:
                a, b = v
                a = -np.inf if a is None else float(a)
                b = np.inf if b is None else float(b)
            except (TypeError, ValueError):
                raise UsageError(f"bounds: '{k}' needs (lower, upper), numbers or None (got {v!r})") from None
            if np.isnan(a) or np.isnan(b) or not a < b:
                raise UsageError(f"bounds: '{k}' needs lower < upper (got {v!r})")
            j = names.index(k)
            lo[j], hi[j] = a * factors[j], b * factors[j]
    for j, n in enumerate(names):
        if not lo[j] <= theta0[j] <= hi[j]:
            raise UsageError(f"the fit starts {n} at {theta0[j] / factors[j]:g}, outside its bounds "
                             f"[{lo[j] / factors[j]:g}, {hi[j] / factors[j]:g}]: start it inside (--start {n}=...)")
    return lo, hi


def _result(model, exps, runs, names, kinds, theta, theta0, factors, units, r, J, sol, rank_tol, cpu0) -> FitResult:
    n_obs, k = r.size, theta.size
    combos, rel = identifiability(J, names, theta, kinds, rank_tol)
    scale = log_scale(theta, kinds)
    Js = J * scale[None, :]
    _, s, Vt = np.linalg.svd(Js, full_matrices=False)
    keep = s > rank_tol * (s.max() if s.size else 0.0)
    rank = int(keep.sum())
    dof = max(n_obs - rank, 0)
    s2 = float(r @ r) / dof if dof > 0 else np.nan
    Cs = (Vt[keep].T / s[keep] ** 2) @ Vt[keep] * s2       # of theta / scale: the logarithms' covariance
    cov = Cs * scale[:, None] * scale[None, :]
    combos = [determined(c, names, theta, Cs, units) for c in combos]
    se = np.sqrt(np.maximum(np.diag(cov), 0.0))
    blind = np.zeros(k, bool)                   # unknowns in a direction the data cannot see
    for i in np.flatnonzero(~keep):
        blind |= np.abs(Vt[i]) > 1e-3
    if Vt.shape[0] < k:                         # fewer observations than unknowns
        blind[:] = True
    for c in combos:
        for n in c.names:
            blind[names.index(n)] = True
    se[blind] = np.inf
    with np.errstate(invalid="ignore", divide="ignore"):
        corr = cov / np.sqrt(np.outer(np.diag(cov), np.diag(cov)))
    corr[blind, :] = np.nan
    corr[:, blind] = np.nan
    np.fill_diagonal(corr, 1.0)
    residuals, fitted, rms = [], [], {}
    pos = 0
    sig_units = signal_units(model, [c for run in runs for c in run.exp.columns])
    for run in runs:
        size = run.w.size
        res = (r[pos:pos + size].reshape(run.w.shape) / run.w)
        pos += size
        residuals.append({c: res[i] for i, c in enumerate(run.exp.columns)})
        fitted.append({c: run.exp.Y[i] + res[i] for i, c in enumerate(run.exp.columns)})
        for i, c in enumerate(run.exp.columns):
            key = c if len(runs) == 1 else f"{c} ({run.exp.label})"
            rms[key] = (float(np.sqrt(np.mean(res[i] ** 2))), sig_units.get(c, ""))
    decl = {n: float(theta[j] / factors[j]) for j, n in enumerate(names)}
    fitted_model = model._with_real({n: float(theta[j]) for j, n in enumerate(names) if kinds[j] == "parameter"}) \
        if any(kd == "parameter" for kd in kinds) else model
    starts = [{u.name: float(theta[run.where[i]]) for i, u in enumerate(run.unk.items) if u.kind == "start"}
              for run in runs]
    return FitResult(
        model_name=model.name, names=tuple(names), kinds=tuple(kinds), units=dict(zip(names, units)),
        estimates=decl, standard_errors={n: float(se[j] / factors[j]) for j, n in enumerate(names)},
        initial={n: float(theta0[j] / factors[j]) for j, n in enumerate(names)},
        covariance=cov / np.outer(factors, factors), correlation=corr, unidentifiable=combos, singular_values=rel,
        residual_norm=float(np.linalg.norm(r)), sigma=float(np.sqrt(s2)) if np.isfinite(s2) else np.nan,
        degrees_of_freedom=dof, n_observations=n_obs, rank=rank, rms=rms, residuals=residuals, fitted=fitted,
        experiments=exps, starts=starts, success=bool(sol.success), message=str(sol.message),
        iterations=int(sol.iterations), evaluations=int(sol.evaluations), jacobians=int(sol.jacobians),
        cpu_time=time.process_time() - cpu0,
        model=fitted_model, source_model=model, integration=runs[0].tr.describe(), theta=theta, jacobian=J)
