"""Fixed-step integration in canonical variables (q, p): symplectic methods.

    q' = dH/dp = qd(q, p, t) = M^-1 (p - b),   p' = -dH/dq + Q_nc = dL/dq|_(q, qd(q, p)) + Q - dD/dqd

(see mechdsl.analysis.hamilton).  Methods (fixed step h <= dt, the same for every step):

- ``stormer-verlet``: for separable H = 1/2 p'M^-1 p + U(q, t) with constant M and
  speed-independent forces, the explicit kick-drift-kick leapfrog (one force evaluation a
  step, the force carried from one step to the next); otherwise the generalized (implicit)
  Stormer-Verlet scheme (Hairer, Lubich, Wanner, GNI, eq. VI.3.4), order 2, symplectic;
- ``implicit-midpoint``: y1 = y0 + h f((y0 + y1)/2), order 2, symplectic;
- ``gauss-legendre``: the 2-stage Gauss collocation method, order 4, symplectic;
- ``rk4``: the classical explicit Runge-Kutta method (4 evaluations a step), not symplectic,
  for comparisons;
- ``rattle``: for constrained models (g(q, t) = 0), the constrained Stormer-Verlet method
  (mechdsl.rattle), symplectic on the constraint manifold, order 2; ``stormer-verlet`` means
  RATTLE there.  The other methods ignore constraints and refuse constrained models.  Without
  constraints ``rattle`` is ``stormer-verlet``.

Implicit stages are solved by CasADi's Newton rootfinder (Jacobians by AD of the SX
residuals).  Steps run in chunks through ``Function.mapaccum``; every step reports its
residual, and a step that did not converge (or a non-finite state) ends the run with a
``Failure`` that keeps the results up to the last good step.
"""
from __future__ import annotations

import math
import time as _time

import numpy as np

from .diagnostics import UsageError
from .output.result import Failure, Result

from .simulation.registry import FIXED_METHODS

METHODS = tuple(FIXED_METHODS)     # the names live in the one method registry
SYMPLECTIC = ("stormer-verlet", "implicit-midpoint", "gauss-legendre", "rattle")
CONSTRAINED = ("stormer-verlet", "rattle")     # methods for models with constraints (RATTLE)
CHUNK = 2000                  # steps a mapaccum call
MAX_POINTS = 20001            # recorded points unless ``points`` asks otherwise
# options of the adaptive solvers that do not apply to a fixed step (noted in the metadata)
_IGNORED = ("rtol", "atol", "tolerance", "max_step", "first_step", "formulation", "compiled", "reactions")


def simulate_symplectic(eom, t_end: float, method: str = "stormer-verlet", dt: float | None = None, *,
                        t0: float = 0.0, p=None, q0=None, qd0=None, points: int | None = None,
                        newton_tol: float = 1e-12, max_newton: int = 30, outputs=None, t_start=None,
                        x0=None, progress=None, step_eom=None, **opts) -> Result:
    """Integrate ``eom`` from t0 to t_end with a fixed step (at most ``dt``).

    p: parameter overrides (dict or vector); q0/qd0: start values (default: the model's), or
    x0: the full state [q; qd] or a dict {coordinate: value, "der(coordinate)": value}
    (as mechdsl.simulate); progress: a callable(t, t_end) called after every chunk of steps;
    points: number of recorded points (default: every step, at most 20001); outputs: names of
    the model outputs to record (default: all); t_start: alias of t0; step_eom: the equations
    to step when zero-order-hold inputs drive the model (``Drive.close_eom(eom, hold_time=True)``:
    the holds read at a trailing parameter, which every step sets to its midpoint t_n + h/2, so
    that all its stages see the value held on [t_n, t_n + h); ``eom`` records).  Tolerance
    options of the adaptive solvers (rtol, atol) do not apply and are noted in the metadata.
    Returns a Result whose signals hold the energy T + V, the Hamiltonian H, the canonical
    momenta p_<coordinate>, the first integrals and the model outputs at every recorded point.
    """
    import casadi as ca

    from .eom import parameter_vector
    from .analysis.hamilton import hamiltonian

    method = str(method).lower().replace("_", "-")
    if method not in METHODS:
        raise UsageError(f"unknown symplectic method {method!r}; choose one of {', '.join(METHODS)}")
    constrained = eom.g is not None and eom.m > 0
    if constrained and method not in CONSTRAINED:
        raise UsageError(f"the method '{method}' ignores the constraints of {eom.name}; for a constrained "
                         "model use method = \"rattle\" (constrained Stormer-Verlet, symplectic) or an "
                         "adaptive DAE formulation (method = \"auto\", docs/constraints.md)")
    if method == "rattle" and not constrained:
        method = "stormer-verlet"          # RATTLE without constraints is Stormer-Verlet
    unknown = sorted(k for k in opts if k not in _IGNORED)
    if unknown:
        raise UsageError(f"unknown option(s) for the fixed-step integrators: {', '.join(unknown)}")
    t0 = float(t_start) if t_start is not None else float(t0)
    t_end = float(t_end)
    if not (math.isfinite(t_end) and t_end > t0):
        raise UsageError(f"stop time {t_end} must be after the start time {t0}")
    notes = []
    if dt is None:
        dt = (t_end - t0) / 1000.0
        notes.append("no step size given: dt = (stop time - start time)/1000")
    dt = float(dt)
    if not (math.isfinite(dt) and dt > 0):
        raise UsageError(f"step size dt = {dt} must be positive")
    if opts:
        notes.append("fixed-step method: ignored " + ", ".join(sorted(opts)))
    wall0 = _time.perf_counter()

    pv = parameter_vector(eom, p)
    ham = hamiltonian(eom, pv)
    n = eom.n
    out_names = _output_names(eom, outputs) if not constrained else outputs
    extra_meta = {}
    if constrained:
        from .rattle import consistent_start

        qs, qds, init, active, dof = consistent_start(eom, x0, q0, qd0, t0, pv)
        extra_meta = {"initialization": init.as_dict(), "dof": dof.as_dict(),
                      "constraints": list(eom.constraint_names),
                      "active_constraints": [eom.constraint_names[i] for i in active]}
    elif x0 is not None:
        from .simulation.inputs import start_vector

        xs = start_vector(eom, x0, pv)
        qs, qds = xs[:n], xs[n:]
    else:
        qs, qds = eom.start(pv)
    if not constrained:
        qs = qs if q0 is None else np.asarray(q0, float).ravel()
        qds = qds if qd0 is None else np.asarray(qd0, float).ravel()
    if qs.size != n or qds.size != n:
        raise UsageError(f"start values need {n} entries each")
    pm0 = np.array(ham.function("momenta")(qs, qds, t0, pv), float).ravel()

    nsteps = max(1, int(math.ceil((t_end - t0) / dt - 1e-9)))
    h = (t_end - t0) / nsteps
    explicit_sv = method == "stormer-verlet" and ham.separable and not constrained
    if constrained:
        from .rattle import rattle_step

        method = "rattle"
        step = rattle_step(ham, eom, active, newton_tol, max_newton)
        state0, evals_per_step, evals_init = np.concatenate([qs, pm0, [t0], np.zeros(len(active))]), None, 0
    elif step_eom is not None:        # zero-order holds read at the step's midpoint (a trailing parameter)
        hs = hamiltonian(step_eom, np.r_[pv, t0])
        explicit_sv = method == "stormer-verlet" and hs.separable
        step, state0, evals_per_step, evals_init = _step_function(hs, method, explicit_sv, n, newton_tol,
                                                                  max_newton, qs, pm0, t0, np.r_[pv, t0],
                                                                  hold=True)
    else:
        step, state0, evals_per_step, evals_init = _step_function(ham, method, explicit_sv, n, newton_tol,
                                                                  max_newton, qs, pm0, t0, pv)
    pstep = pv if step_eom is None or constrained else np.r_[pv, t0]
    stride = _stride(nsteps, points)
    rec_idx = [0]
    rec_states = [state0.copy()]
    failure = None
    done = 0
    x = state0.copy()
    cache = {}
    res_tol = 1e-8
    while done < nsteps:
        k = min(CHUNK, nsteps - done)
        F = cache.get(k)
        if F is None:
            F = step.mapaccum("steps", k)
            cache[k] = F
        try:
            X, R = F(x, h, pstep)
        except RuntimeError as e:  # pragma: no cover - CasADi evaluation error
            failure = Failure(t0 + done * h, "evaluation error in the step", str(e).splitlines()[0])
            break
        X = np.array(X, float)
        R = np.array(R, float).ravel()
        scale = 1.0 + np.max(np.abs(X[: 2 * n]), axis=0)
        bad = np.flatnonzero(~np.isfinite(R) | (R > res_tol * scale) | ~np.all(np.isfinite(X), axis=0))
        good = k if bad.size == 0 else int(bad[0])
        for j in range(good):
            idx = done + j + 1
            if idx % stride == 0 or idx == nsteps:
                rec_idx.append(idx)
                rec_states.append(X[:, j].copy())
        if bad.size:
            j = int(bad[0])
            tf = t0 + (done + j + 1) * h
            if not np.all(np.isfinite(X[:, j])):
                failure = Failure(tf, "the state became non-finite",
                                  f"{method} step of size {h:.6g} from t = {tf - h:.6g}")
            else:
                failure = Failure(tf, "Newton iteration of the implicit step did not converge",
                                  f"residual {R[j]:.3g} after {max_newton} iterations; try a smaller dt")
            if good and (done + good) not in rec_idx:
                rec_idx.append(done + good)
                rec_states.append(X[:, good - 1].copy())
            done += good
            break
        x = X[:, -1]
        done += k
        if callable(progress):
            progress(t0 + done * h, t_end)

    S = np.array(rec_states).T                     # (2n + extra, npts)
    t = t0 + np.array(rec_idx, float) * h
    t[-1] = t_end if (failure is None and rec_idx[-1] == nsteps) else t[-1]
    q = S[:n].T
    pm = S[n:2 * n].T
    qd = _map(ham.function("qd"), [q.T, pm.T, t[None, :], pv]).T
    signals = _signals(eom, ham, q, qd, pm, t, pv, out_names, active if constrained else None)
    wall = _time.perf_counter() - wall0
    stats = {"steps": int(done), "dt": h, "points": int(len(t)), "wall_time": wall,
             "implicit": evals_per_step is None}
    if evals_per_step is not None:    # explicit: exact count of right-hand-side (force) evaluations
        stats["rhs_evaluations"] = int(evals_init + evals_per_step * done)
    else:
        stats["newton_max_iterations"] = int(max_newton)
        stats["newton_tolerance"] = float(newton_tol)
    why = {"stormer-verlet": ("explicit Stormer-Verlet (leapfrog): H is separable" if explicit_sv else
                              "generalized (implicit) Stormer-Verlet: H is not separable ("
                              + "; ".join(ham.notes) + ")"),
           "implicit-midpoint": "implicit midpoint rule (symplectic, order 2)",
           "gauss-legendre": "2-stage Gauss-Legendre collocation (symplectic, order 4)",
           "rk4": "classical Runge-Kutta (explicit, order 4, not symplectic)",
           "rattle": "RATTLE (constrained Stormer-Verlet: symplectic on the constraint manifold, order 2)"}[method]
    stats.update(_energy_drift(signals))
    if constrained:
        stats.update({"max_constraint_drift": float(np.max(signals["constraint_drift"], initial=0.0)),
                      "max_velocity_drift": float(np.max(signals["velocity_drift"], initial=0.0))})
    meta = {"model": eom.name, "route": getattr(eom, "route", ""), "coordinates": list(eom.coords),
            "method": method, "method_reason": "requested", "why": why, "dt": h,
            "symplectic": method in SYMPLECTIC, "separable": ham.separable, "canonical_variables": True,
            "notes": notes + list(ham.notes), "warnings": [],
            "options": {"t_start": t0, "t_end": t_end, "dt": h, "method": method, "points": int(len(t)),
                        "outputs": list(out_names or ()), "newton_tolerance": newton_tol,
                        "parameters": dict(zip(eom.params, map(float, pv))),
                        "start": {**dict(zip(eom.coords, map(float, qs))),
                                  **{f"der({c})": float(v) for c, v in zip(eom.coords, qds)}}}, **extra_meta}
    return Result(t=t, q=q, qd=qd, coordinates=tuple(eom.coords), signals=signals, stats=stats,
                  metadata=meta, failure=failure)


def _stride(nsteps: int, points: int | None) -> int:
    if points is None:
        return max(1, int(math.ceil(nsteps / (MAX_POINTS - 1))))
    if points < 2:
        raise UsageError("points must be at least 2")
    return max(1, nsteps // (points - 1))


def _map(f, args):
    """Evaluate a CasADi Function column-wise over N points."""
    N = max(np.shape(a)[1] if np.ndim(a) == 2 else 1 for a in args)
    out = f.map(N)(*[a if np.ndim(a) == 2 else np.asarray(a, float).reshape(-1, 1) for a in args])
    return np.array(out, float).reshape(-1, N)


def _output_names(eom, outputs) -> tuple[str, ...]:
    """Model outputs to record (names of coordinates and energies are recorded anyway)."""
    if outputs is None:
        return tuple(eom.outputs or ())
    if isinstance(outputs, str):
        outputs = [outputs]
    known = set(eom.coords) | {f"der({c})" for c in eom.coords} | {"energy", "kinetic_energy", "potential_energy"}
    names = []
    for o in outputs:
        if o in (eom.outputs or {}):
            if o not in names:
                names.append(o)
        elif o not in known:
            from .diagnostics import did_you_mean

            hint = did_you_mean(o, list(eom.outputs or ()) + sorted(known))
            raise UsageError(f"'{o}' is not an output of {eom.name}" + (f"; {hint}" if hint else ""))
    return tuple(names)


def _signals(eom, ham, q, qd, pm, t, pv, out_names, active=None) -> dict[str, np.ndarray]:
    """The simulator's signals (simulate.compute_signals: outputs, energies, monitors, ...; a
    constrained model as the DAE simulator records them, with the drift), then this back
    end's own columns: H, the canonical momenta p_<coordinate> and the first integrals of
    ``integral_signals`` not recorded yet (one recorder call, simulation/record.py)."""
    from .analysis.integrals import integral_signals
    from .simulate import compute_signals
    from .simulation import record as R

    if len(t) == 0:
        return {}
    if active is not None:
        from .rattle import constrained_signals

        sig, _ = constrained_signals(eom, active, t, q, qd, pv, out_names)
    else:
        sig = compute_signals(eom, t, np.hstack([q, qd]), pv, out_names)
    sig["H"] = _map(ham.function("H"), [q.T, pm.T, t[None, :], pv])[0]
    for i, c in enumerate(eom.coords):
        sig[f"p_{c}"] = pm[:, i].copy()
    extra = {k: v for k, v in integral_signals(eom, pv).items() if k not in sig and k != "energy"}
    sig.update(R.record(eom, extra, t, q, qd, pv, keep=False))     # fresh expressions each call
    return sig


def _energy_drift(signals) -> dict:
    from .simulate import _energy_drift as energy_drift

    out = energy_drift(signals)
    if "H" in signals and np.isfinite(signals["H"]).all():
        out["hamiltonian_drift"] = float(np.abs(signals["H"] - signals["H"][0]).max())
    return out


# --------------------------------------------------------------------------- step functions


def _step_function(ham, method, explicit_sv, n, tol, max_newton, q0, pm0, t0, pv, hold=False):
    """(Function (state, h, p) -> (state_next, residual), initial state, evals a step, initial evals).

    hold: the last parameter is the zero-order holds' time, set to the step's midpoint t_n + h/2
    for every stage of the step (the value passed in is ignored)."""
    import casadi as ca

    q, pm, t, p = ham.q, ham.pm, ham.t, ham.p
    rhs0 = ca.Function("f", [q, pm, t, p], [ham.qd_of_p, ham.pdot])
    held = {}                           # id(parameter symbol) -> its value in the step

    def rhs(qq, pp, tt, pps):
        return rhs0(qq, pp, tt, held.get(id(pps), pps))

    def holding(pps, tt, hh):
        """The parameters of a step from tt of size hh: the hold time at its midpoint."""
        if hold:
            held[id(pps)] = ca.vertcat(pps[:-1], tt + 0.5 * hh)
        return pps

    h = ca.SX.sym("h") if method in ("rk4",) or explicit_sv else ca.MX.sym("h")

    if explicit_sv:
        force0 = ca.Function("force", [q, t, p], [ca.substitute(ham.pdot, pm, ca.SX.zeros(n))])
        vel = ca.Function("vel", [pm, p], [ca.substitute(ham.qd_of_p, q, ca.SX.zeros(n))])

        def force(qq, tt, pps):
            return force0(qq, tt, held.get(id(pps), pps))
        X = ca.SX.sym("X", 2 * n + 1 + n)
        qn, pn, tn, Fn = X[:n], X[n:2 * n], X[2 * n], X[2 * n + 1:]
        ps = holding(ca.SX.sym("p", p.numel()), tn, h)
        if hold:                        # the force carried from the last step read the last step's hold
            Fn = force(qn, tn, ps)
        ph = pn + 0.5 * h * Fn
        q1 = qn + h * vel(ph, ps)
        F1 = force(q1, tn + h, ps)
        p1 = ph + 0.5 * h * F1
        step = ca.Function("sv", [X, h, ps], [ca.vertcat(q1, p1, tn + h, F1), ca.SX(0)])
        F0 = np.array(force0(q0, t0, pv), float).ravel()
        return step, np.concatenate([q0, pm0, [t0], F0]), 2 if hold else 1, 1

    if method == "rk4":
        X = ca.SX.sym("X", 2 * n + 1)
        qn, pn, tn = X[:n], X[n:2 * n], X[2 * n]
        ps = holding(ca.SX.sym("p", p.numel()), tn, h)

        def f(qq, pp, tt):
            a, b = rhs(qq, pp, tt, ps)
            return a, b

        k1 = f(qn, pn, tn)
        k2 = f(qn + 0.5 * h * k1[0], pn + 0.5 * h * k1[1], tn + 0.5 * h)
        k3 = f(qn + 0.5 * h * k2[0], pn + 0.5 * h * k2[1], tn + 0.5 * h)
        k4 = f(qn + h * k3[0], pn + h * k3[1], tn + h)
        q1 = qn + h / 6 * (k1[0] + 2 * k2[0] + 2 * k3[0] + k4[0])
        p1 = pn + h / 6 * (k1[1] + 2 * k2[1] + 2 * k3[1] + k4[1])
        step = ca.Function("rk4", [X, h, ps], [ca.vertcat(q1, p1, tn + h), ca.SX(0)])
        return step, np.concatenate([q0, pm0, [t0]]), 4, 0

    opts = {"abstol": tol, "abstolStep": tol, "max_iter": max_newton, "error_on_fail": False}
    X = ca.MX.sym("X", 2 * n + 1)
    qn, pn, tn = X[:n], X[n:2 * n], X[2 * n]
    # residual functions in SX (Jacobians by AD), called from the MX step
    zq = ca.SX.sym("zq", n)
    zp = ca.SX.sym("zp", n)
    Sq, Sp, St, Sh = ca.SX.sym("Sq", n), ca.SX.sym("Sp", n), ca.SX.sym("St"), ca.SX.sym("Sh")
    ps = holding(ca.MX.sym("p", p.numel()), tn, h)
    Sps = holding(ca.SX.sym("Sps", p.numel()), St, Sh)

    def frhs(qq, pp, tt):
        return rhs(qq, pp, tt, Sps)

    if method == "stormer-verlet":           # generalized Stormer-Verlet (implicit)
        a = frhs(Sq, zp, St)                                      # at (q_n, p_half, t_n)
        G1 = ca.Function("G1", [zp, Sq, Sp, St, Sh, Sps], [zp - Sp - 0.5 * Sh * a[1]])
        G2 = ca.Function("G2", [zq, Sq, Sp, St, Sh, Sps],
                         [zq - Sq - 0.5 * Sh * (frhs(Sq, Sp, St)[0] + frhs(zq, Sp, St + Sh)[0])])
        rf1 = ca.rootfinder("rf1", "newton", G1, opts)
        rf2 = ca.rootfinder("rf2", "newton", G2, opts)
        f0 = rhs(qn, pn, tn, ps)
        ph = rf1(pn + 0.5 * h * f0[1], qn, pn, tn, h, ps)
        q1 = rf2(qn + h * rhs(qn, ph, tn, ps)[0], qn, ph, tn, h, ps)
        p1 = ph + 0.5 * h * rhs(q1, ph, tn + h, ps)[1]
        r = ca.vertcat(G1(ph, qn, pn, tn, h, ps), G2(q1, qn, ph, tn, h, ps))
        step = ca.Function("gsv", [X, h, ps], [ca.vertcat(q1, p1, tn + h), ca.norm_inf(r)])
        return step, np.concatenate([q0, pm0, [t0]]), None, 0

    if method == "implicit-midpoint":
        Y = ca.SX.sym("Y", 2 * n)
        fm = frhs(Y[:n], Y[n:], St + 0.5 * Sh)
        G = ca.Function("G", [Y, Sq, Sp, St, Sh, Sps],
                        [Y - ca.vertcat(Sq, Sp) - 0.5 * Sh * ca.vertcat(fm[0], fm[1])])
        rf = ca.rootfinder("rf", "newton", G, opts)
        f0 = rhs(qn, pn, tn, ps)
        y0 = ca.vertcat(qn, pn)
        Ym = rf(y0 + 0.5 * h * ca.vertcat(f0[0], f0[1]), qn, pn, tn, h, ps)
        y1 = 2 * Ym - y0
        step = ca.Function("imr", [X, h, ps], [ca.vertcat(y1, tn + h), ca.norm_inf(G(Ym, qn, pn, tn, h, ps))])
        return step, np.concatenate([q0, pm0, [t0]]), None, 0

    # gauss-legendre, s = 2
    s3 = math.sqrt(3.0)
    A = [[0.25, 0.25 - s3 / 6], [0.25 + s3 / 6, 0.25]]
    c = [0.5 - s3 / 6, 0.5 + s3 / 6]
    d = [-s3, s3]                        # b' A^-1: y1 = y0 + d1 Z1 + d2 Z2
    m2 = 2 * n
    Z = ca.SX.sym("Z", 2 * m2)
    y0s = ca.vertcat(Sq, Sp)
    fs = []
    for j in range(2):
        Yj = y0s + Z[j * m2:(j + 1) * m2]
        fj = frhs(Yj[:n], Yj[n:], St + c[j] * Sh)
        fs.append(ca.vertcat(fj[0], fj[1]))
    res = ca.vertcat(*[Z[i * m2:(i + 1) * m2] - Sh * (A[i][0] * fs[0] + A[i][1] * fs[1]) for i in range(2)])
    G = ca.Function("G", [Z, Sq, Sp, St, Sh, Sps], [res])
    rf = ca.rootfinder("rf", "newton", G, opts)
    f0 = rhs(qn, pn, tn, ps)
    f0v = ca.vertcat(f0[0], f0[1])
    Zs = rf(ca.vertcat(c[0] * h * f0v, c[1] * h * f0v), qn, pn, tn, h, ps)
    y1 = ca.vertcat(qn, pn) + d[0] * Zs[:m2] + d[1] * Zs[m2:]
    step = ca.Function("gl2", [X, h, ps], [ca.vertcat(y1, tn + h), ca.norm_inf(G(Zs, qn, pn, tn, h, ps))])
    return step, np.concatenate([q0, pm0, [t0]]), None, 0
