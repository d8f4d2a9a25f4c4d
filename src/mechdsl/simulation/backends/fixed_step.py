"""The fixed-step back end: integration in canonical variables (q, p), symplectic methods and RATTLE.

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
  (``schemes.rattle_step``), symplectic on the constraint manifold, order 2; ``stormer-verlet`` means
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
from dataclasses import dataclass

import numpy as np

from ...analysis.hamilton import hamiltonian
from ...analysis.integrals import integral_signals
from ...dae.constrained_system import ConstrainedSystem
from ...dae.dof import dof_report
from ...dae.init import initialize
from ...diagnostics import UsageError, did_you_mean
from ...eom import parameter_vector
from ...eom.start import fixed_start, start_vector
from ...interrupts import noted, was_interrupt
from ...output.result import INTERRUPTED, Failure, Result
from .. import record as R
from ..monitors import compute_signals, energy_drift_stats
from ..record_dae import constrained_signals as record_signals
from ..record_dae import multipliers, select_signals
from ..registry import spec
from . import Backend
from .schemes import rattle_step, step_function


CHUNK = 2000                  # steps a mapaccum call (at most)
FIRST_CHUNK = 16              # the first call's steps, doubled call by call up to CHUNK: a short run
                              # builds small maps, and Ctrl-C is seen between calls
MAX_POINTS = 20001            # recorded points unless ``points`` asks otherwise


class FixedStepBackend(Backend):
    name = "fixed-step"
    noun = "a fixed-step"
    groups = ("fixed_step",)
    ignores = ("rtol", "atol", "max_steps", "integrator_options", "compiled")
    fixed_step = True

    def run(self, problem, progress, setup=None):
        return fixed_step_run(problem.eom, problem.settings, progress, step_eom=problem.step_eom)

    def describe(self, r):
        m = r.metadata.get("method")
        return {"formulation": "canonical", "integrator": f"mechdsl:{m}", "method": m}


def fixed_step_run(eom, s, progress=None, step_eom=None) -> Result:
    """Integrate ``eom`` from t_start to t_end with a fixed step (at most ``dt``).

    Reads the validated settings: the common fields and the ``fixed_step`` group (dt: default
    (t_end - t_start) / 1000; newton_tol, max_newton of the implicit stages).  points: number
    of recorded points (default: every step, at most 20001).  step_eom: the equations to step
    when zero-order-hold inputs drive the model (``Drive.close_eom(eom, hold_time=True)``: the
    holds read at a trailing parameter, which every step sets to its midpoint t_n + h/2, so that
    all its stages see the value held on [t_n, t_n + h); ``eom`` records).  Returns a Result
    whose signals hold the energy T + V, the Hamiltonian H, the canonical momenta
    p_<coordinate>, the first integrals and the model outputs at every recorded point.
    """
    fs = s.fixed_step
    method, dt = s.method, fs.dt
    constrained = eom.g is not None and eom.m > 0
    if constrained and not spec(method).constrained:
        raise UsageError(f"the method '{method}' ignores the constraints of {eom.name}; for a constrained "
                         "model use method = \"rattle\" (constrained Stormer-Verlet, symplectic) or an "
                         "adaptive DAE formulation (method = \"auto\", docs/constraints.md)")
    if method == "rattle" and not constrained:
        method = "stormer-verlet"          # RATTLE without constraints is Stormer-Verlet
    t0, t_end = s.t_start, s.t_end
    notes = []
    if dt is None:
        dt = fs.step(t_end - t0)
        notes.append(f"no step size given: dt = (stop time - start time)/{fs.STEPS_DEFAULT}")
    wall0 = _time.perf_counter()

    pv = parameter_vector(eom, s.p)
    ham = hamiltonian(eom, pv)
    n = eom.n
    out_names = _output_names(eom, s.outputs) if not constrained else s.outputs
    qs, qds, active, extra_meta = _start(eom, s.x0, t0, pv, constrained)
    pm0 = np.array(ham.function("momenta")(qs, qds, t0, pv), float).ravel()
    nsteps = max(1, int(math.ceil((t_end - t0) / dt - 1e-9)))
    h = (t_end - t0) / nsteps
    st = _stepper(eom, ham, method, constrained, active, fs, qs, pm0, t0, pv, step_eom)
    run = _steps(st, n, nsteps, h, t0, t_end, _stride(nsteps, s.points), fs.max_newton, progress)
    S = np.array(run.states).T                     # (2n + extra, npts)
    t = t0 + np.array(run.idx, float) * h
    t[-1] = t_end if (run.failure is None and run.idx[-1] == nsteps) else t[-1]
    q = S[:n].T
    pm = S[n:2 * n].T
    qd = _map(ham.function("qd"), [q.T, pm.T, t[None, :], pv]).T
    signals = _signals(eom, ham, q, qd, pm, t, pv, out_names, active if constrained else None)
    stats = _stats(st, run, h, len(t), _time.perf_counter() - wall0, fs, signals, constrained)
    meta = {"model": eom.name, "route": getattr(eom, "route", ""), "coordinates": list(eom.coords),
            "method": st.method, "method_reason": "requested", "why": _why(st.method, st.explicit_sv, ham),
            "dt": h, "symplectic": spec(st.method).symplectic, "separable": ham.separable,
            "canonical_variables": True, "notes": notes + list(ham.notes), "warnings": [],
            "options": {"t_start": t0, "t_end": t_end, "dt": h, "method": st.method, "points": int(len(t)),
                        "outputs": list(out_names or ()), "newton_tolerance": fs.newton_tol,
                        "parameters": dict(zip(eom.params, map(float, pv))),
                        "start": {**dict(zip(eom.coords, map(float, qs))),
                                  **{f"der({c})": float(v) for c, v in zip(eom.coords, qds)}}}, **extra_meta}
    if run.interrupted:
        meta["interrupted"] = True
    return Result(t=t, q=q, qd=qd, coordinates=tuple(eom.coords), signals=signals, stats=stats,
                  metadata=meta, failure=run.failure)


def _start(eom, x0, t0, pv, constrained: bool):
    """(q, qd, the active constraints, metadata of a constrained start): the consistent start of
    a constrained model, else the given or the model's start values."""
    if constrained:
        qs, qds, init, active, dof = consistent_start(eom, x0, t0, pv)
        return qs, qds, active, {"initialization": init.as_dict(), "dof": dof.as_dict(),
                                 "constraints": list(eom.constraint_names),
                                 "active_constraints": [eom.constraint_names[i] for i in active]}
    if x0 is not None:
        xs = start_vector(eom, x0, pv)
        return xs[:eom.n], xs[eom.n:], None, {}
    qs, qds = eom.start(pv)
    return qs, qds, None, {}


@dataclass
class _Stepper:
    """One step as a CasADi Function (x, h, p) -> (x1, residual), its start state and parameters."""

    method: str
    step: object
    state0: np.ndarray
    pstep: np.ndarray
    evals_per_step: int | None          # None: implicit (Newton iterations, not counted)
    evals_init: int
    explicit_sv: bool


def _stepper(eom, ham, method, constrained, active, fs, qs, pm0, t0, pv, step_eom) -> _Stepper:
    """The step of ``method``: RATTLE for constraints, the zero-order holds read at the step's
    midpoint (a trailing parameter) when ``step_eom`` is given."""
    explicit_sv = method == "stormer-verlet" and ham.separable and not constrained
    if constrained:
        step = rattle_step(ham, eom, active, fs.newton_tol, fs.max_newton)
        return _Stepper("rattle", step, np.concatenate([qs, pm0, [t0], np.zeros(len(active))]), pv, None, 0,
                        explicit_sv)
    if step_eom is not None:        # zero-order holds read at the step's midpoint (a trailing parameter)
        hs = hamiltonian(step_eom, np.r_[pv, t0])
        explicit_sv = method == "stormer-verlet" and hs.separable
        step, state0, per_step, init = step_function(hs, method, explicit_sv, eom.n, fs.newton_tol, fs.max_newton,
                                                     qs, pm0, t0, np.r_[pv, t0], hold=True)
        return _Stepper(method, step, state0, np.r_[pv, t0], per_step, init, explicit_sv)
    step, state0, per_step, init = step_function(ham, method, explicit_sv, eom.n, fs.newton_tol, fs.max_newton,
                                                 qs, pm0, t0, pv)
    return _Stepper(method, step, state0, pv, per_step, init, explicit_sv)


@dataclass
class _Steps:
    """What the step loop did: recorded step indices and states, steps done, failure, Ctrl-C."""

    idx: list
    states: list
    done: int = 0
    failure: Failure | None = None
    interrupted: bool = False


def _steps(st: _Stepper, n: int, nsteps: int, h: float, t0: float, t_end: float, stride: int, max_newton: int,
           progress) -> _Steps:
    """The steps in chunks through ``mapaccum`` (the first small, doubled call by call); a step
    whose residual or state is bad ends the run there, Ctrl-C keeps the steps recorded so far."""
    run = _Steps([0], [st.state0.copy()])
    x = st.state0.copy()
    cache = {}
    res_tol = 1e-8
    chunk = FIRST_CHUNK
    try:                       # Ctrl-C anywhere in the loop: the steps recorded so far are kept
        while run.done < nsteps:
            done = run.done
            k = min(chunk, nsteps - done)
            chunk = min(CHUNK, 2 * chunk)
            F = cache.get(k)
            if F is None:
                F = st.step.mapaccum("steps", k)
                cache[k] = F
            try:
                X, R = F(x, h, st.pstep)
                X = np.array(X, float)
                R = np.array(R, float).ravel()
            except (RuntimeError, SystemError) as e:  # CasADi evaluation error, or Ctrl-C in disguise
                run.interrupted = was_interrupt(e)
                if not run.interrupted:
                    run.failure = Failure(t0 + done * h, "evaluation error in the step", str(e).splitlines()[0])
                    break
            if run.interrupted or noted():
                run.interrupted = True
                run.failure = Failure(t0 + run.idx[-1] * h, "interrupted", INTERRUPTED)
                break
            scale = 1.0 + np.max(np.abs(X[: 2 * n]), axis=0)
            bad = np.flatnonzero(~np.isfinite(R) | (R > res_tol * scale) | ~np.all(np.isfinite(X), axis=0))
            good = k if bad.size == 0 else int(bad[0])
            for j in range(good):
                idx = done + j + 1
                if idx % stride == 0 or idx == nsteps:
                    run.idx.append(idx)
                    run.states.append(X[:, j].copy())
            if bad.size:
                j = int(bad[0])
                tf = t0 + (done + j + 1) * h
                if not np.all(np.isfinite(X[:, j])):
                    run.failure = Failure(tf, "the state became non-finite",
                                          f"{st.method} step of size {h:.6g} from t = {tf - h:.6g}")
                else:
                    run.failure = Failure(tf, "Newton iteration of the implicit step did not converge",
                                          f"residual {R[j]:.3g} after {max_newton} iterations; try a smaller dt")
                if good and (done + good) not in run.idx:
                    run.idx.append(done + good)
                    run.states.append(X[:, good - 1].copy())
                run.done += good
                break
            x = X[:, -1]
            run.done += k
            if callable(progress):
                progress(t0 + run.done * h, t_end)
    except KeyboardInterrupt:
        run.interrupted = True
        del run.idx[len(run.states):], run.states[len(run.idx):]     # (an append cut short in between)
        run.failure = Failure(t0 + run.idx[-1] * h, "interrupted", INTERRUPTED)
    return run


def _stats(st: _Stepper, run: _Steps, h: float, points: int, wall: float, fs, signals, constrained: bool) -> dict:
    """The run's statistics: steps, step size, evaluations (explicit) or Newton settings
    (implicit), the energy drift and, with constraints, the constraint drifts."""
    stats = {"steps": int(run.done), "dt": h, "points": int(points), "wall_time": wall,
             "implicit": st.evals_per_step is None}
    if st.evals_per_step is not None:    # explicit: exact count of right-hand-side (force) evaluations
        stats["rhs_evaluations"] = int(st.evals_init + st.evals_per_step * run.done)
    else:
        stats["newton_max_iterations"] = int(fs.max_newton)
        stats["newton_tolerance"] = float(fs.newton_tol)
    stats.update(_energy_drift(signals))
    if constrained:
        stats.update({"max_constraint_drift": float(np.max(signals["constraint_drift"], initial=0.0)),
                      "max_velocity_drift": float(np.max(signals["velocity_drift"], initial=0.0))})
    return stats


def _why(method: str, explicit_sv: bool, ham) -> str:
    """What the method is, in words (metadata["why"])."""
    return {"stormer-verlet": ("explicit Stormer-Verlet (leapfrog): H is separable" if explicit_sv else
                               "generalized (implicit) Stormer-Verlet: H is not separable ("
                               + "; ".join(ham.notes) + ")"),
            "implicit-midpoint": "implicit midpoint rule (symplectic, order 2)",
            "gauss-legendre": "2-stage Gauss-Legendre collocation (symplectic, order 4)",
            "rk4": "classical Runge-Kutta (explicit, order 4, not symplectic)",
            "rattle": "RATTLE (constrained Stormer-Verlet: symplectic on the constraint manifold, order 2)"}[method]


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
            hint = did_you_mean(o, list(eom.outputs or ()) + sorted(known))
            raise UsageError(f"'{o}' is not an output of {eom.name}" + (f"; {hint}" if hint else ""))
    return tuple(names)


def _signals(eom, ham, q, qd, pm, t, pv, out_names, active=None) -> dict[str, np.ndarray]:
    """The simulator's signals (simulate.compute_signals: outputs, energies, monitors, ...; a
    constrained model as the DAE simulator records them, with the drift), then this back
    end's own columns: H, the canonical momenta p_<coordinate> and the first integrals of
    ``integral_signals`` not recorded yet (one recorder call, simulation/record.py)."""
    if len(t) == 0:
        return {}
    if active is not None:
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
    out = energy_drift_stats(signals)
    if "H" in signals and np.isfinite(signals["H"]).all():
        out["hamiltonian_drift"] = float(np.abs(signals["H"] - signals["H"][0]).max())
    return out


def consistent_start(eom, x0, t0, pv):
    """(q, qd, InitReport, active constraint indices, DofReport) at the start: the DAE's
    consistent initialization (overridden values count as fixed) and its choice of
    independent constraints."""
    qs, qds, fq, fqd = fixed_start(eom, x0, pv)
    init = initialize(eom, qs, qds, t0, pv, fixed_q=fq, fixed_qd=fqd)
    dof = dof_report(eom, init.q, t0, pv)
    return init.q, init.qd, init, tuple(dof.independent), dof


def constrained_signals(eom, active, t, q, qd, pv, outputs) -> tuple[dict, dict]:
    """Signals of a constrained run as the DAE simulator records them (outputs, energies,
    residuals, drift, multipliers from the consistent state when an output needs them);
    returns (signals, drift statistics)."""
    chosen, need_lam = select_signals(eom, outputs, False)
    LAM = multipliers(ConstrainedSystem.build(eom, pv, active), t, q, qd) if need_lam else None
    sig = record_signals(eom, chosen, t, q, qd, LAM, pv)
    stats = {"max_constraint_drift": float(np.max(sig.get("constraint_drift", [0.0]), initial=0.0)),
             "max_velocity_drift": float(np.max(sig.get("velocity_drift", [0.0]), initial=0.0))}
    return sig, stats
