"""Simulation of equations of motion: ``simulate(eom, t_end, ...) -> Result``.

Minimal-coordinate ODEs are integrated here (CasADi plugins or scipy, see
:mod:`mechdsl.integrators`); constrained models go to ``mechdsl.dae.simulate_dae`` and the
symplectic methods to ``mechdsl.symplectic.simulate_symplectic``.  A failed run never
raises: the Result keeps every output point reached and ``Result.failure`` says when and
why.  See docs/simulate.md (users) and docs/internals/numerics.md (design).
"""
from __future__ import annotations

import math
import time
from typing import Any

import numpy as np

from . import integrators as I
from .eom.codegen import FastFunction, casadi_functions
from .diagnostics import UsageError, did_you_mean
from .output.result import Failure, Result
from .eom import parameter_vector
from .simulation.inputs import start_vector  # noqa: F401  (re-exported: one builder)
from .simulation.record import ENERGY_NAMES

DEFAULT_POINTS = 501
MAX_STEPS_TOTAL = 2_000_000          # default max_steps = max(20000, this / output intervals)
SINGULARITY_THRESHOLD = 0.05         # warn when a monitor comes closer than this to zero
NO_U = np.zeros(0)                   # the input vector u of a model without inputs
KNOWN_OPTS = ("singularity_threshold", "functions")   # back-end options of the ODE runs (besides the settings)


def simulate(eom, t_end, *, progress=None, **kw) -> Result:
    """Integrate ``eom`` from t_start to t_end and sample it on ``points`` equidistant times.

    The keyword arguments are the fields of :class:`mechdsl.simulation.SimulationSettings`
    (t_start, rtol, atol, method, formulation, points, outputs, x0, p, dt, reactions,
    compiled, max_steps, integrator_options, rest_speed, impact_order, budget,
    estimate_error) and back-end options (functions, singularity_threshold, baumgarte,
    ...).  x0: full state [q; qd] (array) or a dict of overrides {coordinate: value,
    "der(c)": value}; p: parameter vector or dict of overrides {name: value} (dependent
    parameters are not re-evaluated: use Model.with_params for that).  progress: True shows
    a bar on stderr for runs longer than 0.5 s, or a callable(t, t_end).  Every run goes
    through the one simulation layer (mechdsl.simulation: formulate, then solve).
    """
    from .simulation import simulate as run
    from .simulation.settings import from_kwargs

    return run(eom, from_kwargs(t_end, **kw), progress=progress)


def simulate_ode(eom, s, progress=None, drive=None) -> Result:
    """The ODE back end: minimal coordinates, CasADi integrator plugins or scipy (settings
    ``s`` validated by mechdsl.simulation.settings; ``drive``: the inputs' signals,
    mechdsl.simulation.drive, built by formulate)."""
    wall0 = time.perf_counter()
    opts = dict(s.extra)
    unknown = sorted(set(opts) - set(KNOWN_OPTS))
    if unknown:
        hint = did_you_mean(unknown[0], KNOWN_OPTS)
        raise UsageError(f"unknown simulation option '{unknown[0]}'" + (f"; {hint}" if hint else ""))
    method = s.method
    if method != "auto" and method not in I.METHODS:
        raise UsageError(f"method '{method}' does not apply to an ODE model (methods: {', '.join(['auto', *I.METHODS])}"
                         ", or a fixed-step method)")
    t0, t1, rtol, atol, npts = s.t_start, s.t_end, s.rtol, s.atol, s.points or DEFAULT_POINTS
    pv = parameter_vector(eom, s.p)
    xs = start_vector(eom, s.x0, pv)
    out_names = _check_outputs(eom, s.outputs)
    compiled = s.compiled
    if drive is None:
        from .simulation.drive import build_drive

        drive = build_drive(eom, s.inputs, t0, t1, xs)
    uv = drive.vector(t0)
    vm = drive.closed(casadi_functions(eom, names=("ode", "ode_jacobian")))
    post = casadi_functions(eom, names=("mass_matrix",))     # the failure diagnosis reads M
    grid = np.linspace(t0, t1, npts)
    meta: dict[str, Any] = {"model": eom.name, "route": eom.route, "coordinates": list(eom.coords),
                            "warnings": [], "notes": []}
    if eom.inputs:
        meta["inputs"] = drive.describe()
    if eom.n == 0:   # nothing to integrate (everything prescribed): outputs on the grid
        return _no_state_result(eom, grid, pv, out_names, meta, wall0, drive)
    auto_compiled = None
    if method == "auto":
        method, reason, info = choose_method(eom, vm, xs, pv, t0, t1, rtol, u=uv)
        meta["auto"] = info
        if method == "erk" and compiled is None and opts.get("functions") is None:
            method, reason, auto_compiled = _auto_compile(eom, vm, xs, pv, t0, t1, rtol, uv, reason, meta)
    else:
        reason = "requested"
    if method in I.COMPILED_LOOP and compiled is False:     # compiled = false wins: never compile
        from .simulation.crk import scipy_name

        method, reason = scipy_name(method), (f"{method} requested with compiled = false: its loop would compile; "
                                              f"{scipy_name(method)} is the same method stepped in Python")
    if "compiled" not in meta:
        meta["compiled"] = "requested" if compiled else ("off (requested)" if compiled is False else "no")
    meta.update(method=method, method_reason=reason, integrator=I.METHODS[method][3])
    loop_compiled = None
    if opts.get("functions") is not None:
        funcs = opts["functions"]
    elif method in I.COMPILED_LOOP:     # the loop compiles the model's C together with its own
        funcs = vm
        loop_compiled = _compile_loop(eom, funcs, meta, fallback="erk" if auto_compiled else None)
        if auto_compiled and not loop_compiled:     # could not build it: the automatic choice falls back
            method, loop_compiled = "erk", None
            meta.update(method=method, integrator=I.METHODS[method][3],
                        method_reason=reason.split(";")[0] + "; the compiled stepping loop it would pick could "
                                                             "not be built (see the warning): erk in the virtual machine")
            meta["compiled"] = "no: auto (the compiled loop could not be built)"
    elif compiled:
        funcs = casadi_functions(eom, compiled=True,
                                 names=("ode",) if method in I.NO_JACOBIAN else ("ode", "ode_jacobian"),
                                 jacobian="forward" if method in I.FORWARD_ONLY else "full")
        funcs["ode"]  # compile now (notes below)
        funcs = drive.closed(funcs)
    else:
        funcs = vm
    unavailable = compiled and loop_compiled is None and not getattr(funcs, "compiled", False)
    if unavailable:     # said once, as a warning (not also as a note)
        meta["warnings"].append("compiled code unavailable: " + "; ".join(getattr(funcs, "notes", [])))
    else:
        meta["notes"] += list(getattr(funcs, "notes", []))
    if s.formulation not in ("auto", "ode"):
        meta["notes"].append(f"formulation = {s.formulation!r} applies to constrained models only; ignored for this ODE")
    if s.reactions:
        meta["notes"].append("reactions = true applies to constrained models only; ignored for this ODE")
    max_steps = int(s.max_steps or max(20_000, MAX_STEPS_TOTAL // (npts - 1)))
    extra = dict(s.integrator_options or {})
    bar = I.Progress(progress, t0, t1, label=f"{eom.name} ({method})")
    breaks = drive.breakpoints(t0, t1)
    try:
        if breaks.size:
            run, fixed = _run_pieces(method, funcs, grid, xs, pv, rtol, atol, max_steps, s.dt, extra, bar, eom,
                                     t0, t1, meta["notes"], 10 * s.budget, drive, breaks)
        else:
            run, fixed = _run(method, funcs, grid, xs, pv, rtol, atol, max_steps, s.dt, extra, bar, eom, t0, t1,
                              meta["notes"], 10 * s.budget, u=uv)
    finally:
        bar.close()
    if fixed is not None:
        meta["fixed_steps"] = fixed
    failure = None
    if run.error is not None or run.reached < len(grid):
        u_fail = drive.vector(float(grid[max(run.reached - 1, 0)]))
        failure = diagnose(eom, funcs, post, method, run, grid, xs, pv, rtol, atol, max_steps, extra, u=u_fail)
    n_ok = max(run.reached, 1)
    X = run.X[:n_ok].copy()
    X[0] = xs
    t = grid[:n_ok].copy()
    U = drive.values(t, X)
    signals = compute_signals(eom, t, X, pv, out_names, U=U)
    record_inputs(drive, U, signals, meta)
    _singularity_report(eom, signals, t, meta, float(opts.get("singularity_threshold") or SINGULARITY_THRESHOLD))
    stats = {**{k: v for k, v in _counts(method, run.stats).items() if v is not None},
             "points": int(n_ok), "wall_time": time.perf_counter() - wall0}
    stats.update(_energy_drift(signals))
    stats.update(_integral_drift(signals, eom))
    stats["raw"] = run.stats
    if run.messages.strip():
        meta["integrator_messages"] = _dedup(run.messages)
    meta["conservative"] = is_conservative(eom)
    meta["options"] = {"t_start": t0, "t_end": t1, "rtol": rtol, "atol": atol, "points": npts,
                       "method": method,
                       "compiled": bool(getattr(funcs, "compiled", False)) if loop_compiled is None else loop_compiled,
                       "max_steps": max_steps, "outputs": list(out_names),
                       "parameters": dict(zip(eom.params, map(float, pv))),
                       "start": {**dict(zip(eom.coords, map(float, xs[:eom.n]))),
                                 **{f"der({c})": float(v) for c, v in zip(eom.coords, xs[eom.n:])}},
                       **({"integrator_options": extra} if extra else {})}
    meta["versions"] = versions()
    n = eom.n
    return Result(t=t, q=X[:, :n], qd=X[:, n:], coordinates=tuple(eom.coords), signals=signals,
                  stats=stats, metadata=meta, failure=failure)


def _compile_loop(eom, funcs, meta, fallback=None) -> bool:
    """Build (or load from the cache) the compiled stepping loop of a dopri5/dop853 run; a
    fallback to scipy's stepping in Python (or to ``fallback``) is a warning of the run."""
    from .simulation.crk import library

    fn, note = library(funcs["ode"], tag=eom.name)
    if fn is None:
        instead = (f"{fallback} runs instead" if fallback else
                   f"{meta['method']} runs as scipy's same method stepped in Python")
        meta["warnings"].append(f"compiled stepping loop unavailable ({note}); {instead}")
        return False
    if note:
        meta["notes"].append(f"{meta['method']} compiled stepping loop: {note}")
    return True


def _auto_compile(eom, vm, xs, pv, t0, t1, rtol, uv, reason, meta):
    """method = auto on a non-stiff model: erk in the virtual machine, or the compiled dop853
    loop when compiling pays (simulation.crk.auto_choice); ``meta['compiled']`` says why."""
    from .simulation.crk import auto_choice

    pick, why, info = auto_choice(eom, vm, xs, pv, t0, t1, rtol, uv, rho=meta["auto"].get("spectral_radius"))
    meta["auto"]["compile"] = info
    if pick is None:
        meta["compiled"] = f"no: auto ({why})"
        return "erk", reason, None
    meta["compiled"] = f"auto ({why})"
    return pick, (reason.split(";")[0] + f"; compiled stepping loop {pick} (Dormand-Prince, C): {why}"), True


def record_inputs(drive, U, signals, meta) -> None:
    """The inputs as signals (named as declared); bound violations of run-time signals warn."""
    for j, name in enumerate(drive.names):
        signals[name] = U[:, j].copy()
    meta.setdefault("warnings", []).extend(drive.check_bounds(U))


def _no_state_result(eom, grid, pv, out_names, meta, wall0, drive) -> Result:
    X = np.zeros((len(grid), 0))
    U = drive.values(grid, X)
    signals = compute_signals(eom, grid, X, pv, out_names, U=U)
    record_inputs(drive, U, signals, meta)
    meta.update(method="none", method_reason="the model has no coordinates: nothing to integrate",
                versions=versions(), options={"t_start": float(grid[0]), "t_end": float(grid[-1]),
                                              "points": len(grid), "outputs": list(out_names),
                                              "parameters": dict(zip(eom.params, map(float, pv)))})
    stats = {"steps": 0, "points": len(grid), "wall_time": time.perf_counter() - wall0}
    return Result(t=grid.copy(), q=X, qd=X.copy(), coordinates=(), signals=signals, stats=stats, metadata=meta)


# --------------------------------------------------------------------------- dispatch and inputs


def _check_outputs(eom, outputs) -> tuple[str, ...]:
    if outputs is None:
        return tuple(eom.outputs)
    if isinstance(outputs, str):
        outputs = [outputs]
    names = []
    coordish = set(eom.coords) | {f"der({c})" for c in eom.coords} | set(ENERGY_NAMES)
    for o in outputs:
        if o in eom.outputs:
            if o not in names:
                names.append(o)
        elif o not in coordish:
            hint = did_you_mean(o, list(eom.outputs) + sorted(coordish))
            raise UsageError(f"'{o}' is not an output of {eom.name}" + (f"; {hint}" if hint else ""))
    return tuple(names)


# --------------------------------------------------------------------------- method choice


def choose_method(eom, funcs, x0, pv, t0, t1, rtol, u=NO_U) -> tuple[str, str, dict]:
    """method=auto: stiffness from the Jacobian's eigenvalues at the start, then the tolerance.

    Rules (docs/internals/numerics.md): stiff (a decay rate much faster than the slowest
    time scale and than the horizon) -> cvodes-bdf; otherwise erk (adaptive explicit
    Runge-Kutta 5(4)), which beat cvodes-adams, idas and scipy at every tolerance from 1e-4
    to 1e-12 on the work-precision benchmark.
    """
    span = t1 - t0
    info: dict[str, Any] = {}
    u = default_inputs(eom, u)
    try:
        J = FastFunction(funcs["ode_jacobian"])(t0, x0, u, pv)
        lam = jacobian_eigenvalues(J) if np.isfinite(J).all() else None
    except Exception:  # noqa: BLE001
        lam = None
    if lam is None:
        return "cvodes-bdf", "the Jacobian at the start is not finite; BDF is the most robust choice", info
    mag = np.abs(lam)
    rho = float(mag.max()) if mag.size else 0.0
    decay = float(max(0.0, (-lam.real).max())) if lam.size else 0.0
    nonzero = mag[mag > 1e-9 * max(rho, 1.0)]
    slow = max(1.0 / span, float(nonzero.min()) if nonzero.size else 0.0)
    ratio = decay / slow
    info.update(spectral_radius=rho, fastest_decay_rate=decay, slowest_rate=slow, stiffness_ratio=ratio,
                horizon=span)
    if ratio > 1e3 and decay * span > 1e2:
        return ("cvodes-bdf",
                f"stiff: the fastest mode decays at {decay:.3g}/s, {ratio:.3g} times the slowest rate "
                f"{slow:.3g}/s (Jacobian eigenvalues at t = {t0:g}); BDF takes steps the explicit methods cannot", info)
    return ("erk", f"not stiff (stiffness ratio {ratio:.3g} < 1e3 from the Jacobian at t = {t0:g}); the adaptive "
            f"explicit Runge-Kutta 5(4) needs no Jacobian and was fastest for a given accuracy in "
            f"benchmarks/integrators.py", info)


def jacobian_eigenvalues(J: np.ndarray) -> np.ndarray:
    """Eigenvalues of the Jacobian of x' = (qd, qdd(q, qd)).  When d qdd / d qd vanishes (no
    damping, at rest: every conservative model's start from rest) J = [[0, I], [A, 0]] and its
    eigenvalues are +-sqrt(mu) for the eigenvalues mu of A: a decomposition of half the size,
    8x less work (a 400 x 400 eigen decomposition costs 0.05-0.5 s of CPU on a loaded machine,
    most of it the BLAS threads' spinning)."""
    n = J.shape[0] // 2
    if (J.shape[0] == 2 * n and n > 0 and not J[:n, :n].any() and not J[n:, n:].any()
            and np.array_equal(J[:n, n:], np.eye(n))):
        root = np.sqrt(np.linalg.eigvals(J[n:, :n]).astype(complex))
        return np.concatenate([root, -root])
    return np.linalg.eigvals(J)


def default_inputs(eom, u):
    """u as given, or the model's input defaults when none was given (NO_U)."""
    if u is NO_U and eom is not None and getattr(eom, "inputs", ()):
        return np.asarray(eom.input_defaults, float)
    return u


def fixed_step_count(method, funcs, x0, pv, t0, t1, rtol, dt, budget=10_000_000, u=NO_U) -> tuple[int, str]:
    """Steps for the fixed-step methods: h = dt, or h * omega = 0.5 rtol^(1/order), omega the
    fastest rate seen at the start: the spectral radius of the Jacobian, sqrt(max |qdd|) and
    max |qd| (coordinates in units of order 1), and 2 pi / horizon."""
    span = t1 - t0
    if dt is not None:
        dt = float(dt)
        if not dt > 0:
            raise UsageError(f"dt must be positive (got {dt})")
        return max(1, math.ceil(span / dt - 1e-9)), f"dt = {dt:g} given"
    omega, rho = time_scale(funcs, x0, pv, t0, t1, u)
    h = 0.5 * rtol ** (1.0 / I.FIXED_ORDER[method]) / omega
    steps = min(max(1, math.ceil(span / h)), int(budget))
    return steps, ("(capped at the budget) " if steps == int(budget) else "") + (f"h = {span / steps:.3g} from rtol = {rtol:g} and the time scale 1/{omega:.3g} s at the start "
                   f"(Jacobian spectral radius {rho:.3g}/s, sqrt(|qdd|), |qd|)")


def time_scale(funcs, x0, pv, t0, t1, u=NO_U, rho=None) -> tuple[float, float]:
    """(omega, rho): the fastest rate seen at the start, max of the Jacobian's spectral radius
    rho, sqrt(max |qdd|) and max |qd| (coordinates in units of order one: the Jacobian alone is
    ~0 for a pendulum released from the horizontal), and 2 pi / horizon.  ``rho``: the spectral
    radius when known (choose_method computed it; eigenvalues of a 400 x 400 Jacobian cost
    0.05-0.5 s of CPU)."""
    span = t1 - t0
    omega_acc = 0.0
    u = default_inputs(getattr(funcs, "eom", None), u)
    try:
        if rho is None:
            rho = 0.0
            J = FastFunction(funcs["ode_jacobian"])(t0, x0, u, pv)
            rho = float(np.abs(jacobian_eigenvalues(J)).max()) if np.isfinite(J).all() else 0.0
        f = FastFunction(funcs["ode"])(t0, x0, u, pv)
        n = len(x0) // 2
        if np.isfinite(f).all():  # time scales of the motion itself: sqrt(|qdd|) and |qd| (units of 1)
            omega_acc = max(float(np.sqrt(np.abs(f[n:]).max(initial=0.0))), float(np.abs(x0[n:]).max(initial=0.0)))
    except Exception:  # noqa: BLE001
        pass
    return max(rho, omega_acc, 2 * math.pi / span), rho


def _run(method, funcs, grid, xs, pv, rtol, atol, max_steps, dt, extra, bar, eom, t0, t1, meta_notes, budget,
         u=NO_U):
    """One run of the integrator plug-in of ``method`` over the output grid."""
    fixed, steps = None, None
    if method in I.FIXED_STEP:
        steps, why = fixed_step_count(method, casadi_functions(eom, names=("ode", "ode_jacobian")),
                                      xs, pv, t0, t1, rtol, dt, budget, u=u)
        fixed = {"target_steps": steps, "why": why}
    elif dt is not None:
        meta_notes.append(f"dt = {dt} ignored: {method} chooses its own steps (dt applies to {', '.join(I.FIXED_STEP)})")
    try:
        run = I.plugin(method).advance(method, funcs, grid, xs, pv, rtol=rtol, atol=atol, max_steps=max_steps,
                                       fixed_steps=steps, extra=extra, progress=bar, hmin=min_step(t0, t1),
                                       u=u)
    except RuntimeError as e:  # bad integrator options
        raise UsageError(f"integrator {method} rejected its options: {str(e).strip().splitlines()[-1]}") from None
    return run, fixed


MAX_PIECES = 100_000      # input-table breakpoints a run restarts at (one integrator call each)


def _run_pieces(method, funcs, grid, xs, pv, rtol, atol, max_steps, dt, extra, bar, eom, t0, t1, notes, budget,
                drive, breaks):
    """``_run`` piece by piece between the input tables' breakpoints, each piece from the state
    where the last ended, the zero-order holds' values as the constant u of the piece: no step
    crosses a jump (or a kink of a linear table).  Returns one Run over ``grid``."""
    if breaks.size > MAX_PIECES:
        raise UsageError(f"the input tables have {breaks.size} samples inside the run; at most {MAX_PIECES} "
                         "(each is a restart of the integrator): resample the table")
    edges = np.r_[t0, breaks, t1]
    if method in I.FIXED_STEP and dt is None:    # the step of the whole run, not of each piece's span
        steps, why = fixed_step_count(method, casadi_functions(eom, names=("ode", "ode_jacobian")), xs, pv, t0, t1,
                                      rtol, None, budget, u=drive.vector(t0))
        dt = (t1 - t0) / steps
    else:
        why = None
    full = np.union1d(grid, edges)
    on_grid = np.isin(full, grid)
    Xf = np.full((full.size, xs.size), np.nan)
    Xf[0] = xs
    stats: dict = {}
    messages, fixed, x = [], None, xs
    error = fail_time = fail_state = None
    for a, b in zip(edges[:-1], edges[1:]):
        idx = np.flatnonzero((full >= a) & (full <= b))
        run, fx = _run(method, funcs, full[idx], x, pv, rtol, atol, max_steps, dt, extra, bar, eom, a, b,
                       notes if fixed is None else [], budget, u=drive.vector(a))
        fixed = fixed or fx
        Xf[idx[1:run.reached]] = run.X[1:run.reached]
        for k, v in (run.stats or {}).items():
            stats[k] = stats.get(k, 0) + v if isinstance(v, (int, float)) and not isinstance(v, bool) else v
        messages.append(run.messages)
        if run.error is not None or run.reached < idx.size:
            error, fail_time, fail_state = run.error or "integration stopped", run.fail_time, run.fail_state
            break
        x = run.X[-1]
    X = Xf[on_grid]
    reached = I._count_filled(X, 0)
    if fixed is not None:
        fixed = {**fixed, "pieces": int(edges.size - 1), **({"why": why} if why else {})}
    notes.append(f"integrated in {edges.size - 1} pieces, restarting at the input tables' samples inside the run "
                 "(no step crosses a jump of a zero-order hold)")
    return I.Run(X=X, reached=reached, stats=stats, error=error, messages="".join(messages),
                 fail_time=fail_time, fail_state=fail_state), fixed


def min_step(t0, t1) -> float:
    """Steps below this are noise in double precision: the run is declared failed instead."""
    return 1e-12 * max(t1 - t0, abs(t0), abs(t1))


def _counts(method, raw):
    return I.plugin(method).counts(method, raw)


# --------------------------------------------------------------------------- failure


def diagnose(eom, funcs, post, method, run, grid, xs, pv, rtol, atol, max_steps, extra, u=NO_U) -> Failure:
    """Say when and why a run stopped: locate the failure inside the last output interval
    (re-integrating it on a fine grid) and look at the state there."""
    k = max(run.reached - 1, 0)
    t_last, x_last = float(grid[k]), (run.X[k] if run.reached else xs)
    t_fail = run.fail_time
    x_fail = run.fail_state
    unstable = False
    if x_fail is None and k + 1 < len(grid) and I.plugin(method).zoom:
        # zoom in: re-integrate the failing interval on finer grids (3 levels of 50 subintervals);
        # a fixed-step method is checked with the adaptive erk instead
        zoom = "erk" if method in I.FIXED_STEP else method
        a, b, xa = t_last, float(grid[k + 1]), x_last
        hmin = min_step(float(grid[0]), float(grid[-1]))
        try:
            opts = I.casadi_options(zoom, rtol, atol, max_steps, None, extra if zoom == method else {}, hmin=hmin)
            for level in range(3):
                if b - a <= 100 * hmin:
                    break
                fine = np.linspace(a, b, 51)
                sub = I.run_casadi(zoom, funcs["ode"], fine, xa, pv, opts, I.Progress(False, 0, 1), u=u)
                if sub.error is None:
                    unstable = level == 0 and zoom != method
                    break
                j = max(sub.reached - 1, 0)
                a, b, xa = float(fine[j]), float(fine[min(j + 1, 50)]), (sub.X[j] if sub.reached else xa)
                if sub.fail_time is not None and a <= sub.fail_time <= b:
                    t_fail = sub.fail_time
            x_fail = xa
            if t_fail is None or not (t_last <= t_fail <= float(grid[k + 1])):
                t_fail = b
        except Exception:  # noqa: BLE001 - diagnosis must not fail the run
            x_fail = x_last
    if unstable:
        return Failure(time=float(grid[k + 1]), cause="fixed step too large",
                       detail=(f"{method} became unstable between t = {t_last:.10g} and {float(grid[k + 1]):.10g}, "
                               f"where the adaptive erk integrates without trouble; pass a smaller dt; "
                               f"integrator: {_short(run.error or '')}"))
    if x_fail is None:
        x_fail = x_last
    if t_fail is None:
        t_fail = float(grid[min(k + 1, len(grid) - 1)])
    cause, detail = _classify(eom, post, funcs, run.error or "", x_fail, xs, pv, t_fail, u)
    where = f"last output point reached: t = {t_last:.10g}"
    return Failure(time=float(t_fail), cause=cause, detail=f"{detail}; {where}" if detail else where)


def _classify(eom, post, funcs, error, x, x0, pv, t, u=NO_U):
    n = eom.n
    err = error.upper()
    if not np.isfinite(x).all():
        return "non-finite state", f"state became {x[~np.isfinite(x)][0]} (integrator: {_short(error)})"
    try:
        mm = FastFunction(post["mass_matrix"])
        arg = x[:n] if post["mass_matrix"].name_in(0) == "q" else x
        M = mm(arg, t, pv) if post["mass_matrix"].name_in(0) == "q" else mm(t, arg, u, pv)
        M0 = mm(x0[:n], t, pv) if post["mass_matrix"].name_in(0) == "q" else mm(t, x0, u, pv)
        M = np.atleast_2d(M)
        M0 = np.atleast_2d(M0)
        ev = np.linalg.eigvalsh(0.5 * (M + M.T))
        ev0 = np.linalg.eigvalsh(0.5 * (M0 + M0.T))
        scale = max(float(np.abs(ev0).max()), 1e-300)
        # heuristic: M lost (nearly) all stiffness in some direction compared with the start
        if not np.isfinite(ev).all() or ev.min() <= 1e-4 * scale or ev.min() <= 1e-10 * max(abs(ev.max()), 1e-300):
            w, V = np.linalg.eigh(0.5 * (M + M.T))
            vec = V[:, 0]
            who = [eom.coords[i] for i in np.argsort(-np.abs(vec))[:3] if abs(vec[i]) > 0.3]
            return ("singular mass matrix",
                    f"smallest eigenvalue of M is {ev.min():.3g} (largest at the start {scale:.3g})"
                    + (f"; coordinates involved: {', '.join(who)}" if who else ""))
    except Exception:  # noqa: BLE001
        pass
    try:
        f = FastFunction(funcs["ode"])(t, x, u, pv)
        if not np.isfinite(f).all():
            return "non-finite right-hand side", f"accelerations are not finite at t = {t:.6g}"
    except Exception:  # noqa: BLE001
        pass
    big = float(np.abs(x).max())
    if big > 1e8 * (1.0 + float(np.abs(x0).max())):
        return "solution blows up", f"|x| reached {big:.3g}; integrator: {_short(error)}"
    if "TOO_MUCH_WORK" in err or "MAX_NUM_STEPS" in err or "MORE THAN" in err:
        return "too many steps", (f"the step limit per output interval was reached (raise max_steps, or try a "
                                  f"stiff method such as cvodes-bdf); integrator: {_short(error)}")
    if "TOO_MUCH_ACC" in err:
        return "tolerance too small", f"integrator: {_short(error)}"
    if "ERR_FAIL" in err or "CONV_FAIL" in err or "STEP SIZE" in err or "MIN_STEP" in err or "LESS THAN SPACING" in err:
        return "step size too small", f"integrator: {_short(error)}"
    if "ROOTFINDER" in err:
        return "step size too large", f"the Newton iteration of the implicit step failed; pass a smaller dt; integrator: {_short(error)}"
    if "RHSFUNC" in err or "RES_FAIL" in err or "NAN" in err:
        return "non-finite right-hand side", f"integrator: {_short(error)}"
    return "integrator failure", _short(error)


def _short(error: str) -> str:
    lines = [ln.strip() for ln in (error or "").strip().splitlines() if ln.strip()]
    if not lines:
        return "no message"
    s = lines[-1]
    s = s.split(": ", 1)[1] if s.startswith(".../") and ": " in s else s
    return s[:300]


# --------------------------------------------------------------------------- signals


def compute_signals(eom, t, X, pv, out_names, U=None) -> dict[str, np.ndarray]:
    """What an unconstrained run records (simulation/record.py: outputs, energies, residuals,
    invariants, first integrals, singularity monitors) on the sample times.  U: the inputs on
    the sample times (rows = times; None: the inputs' defaults)."""
    from .simulation import record as R

    t = np.asarray(t, float).reshape(-1)
    N, n = len(t), eom.n
    if N == 0:
        return {}
    X = np.asarray(X, float).reshape(N, 2 * n)
    UT = (np.tile(np.asarray(eom.input_defaults, float).reshape(-1, 1), (1, N)) if U is None
          else np.asarray(U, float).reshape(N, -1).T)
    steady = UT[:, 0] if UT.size and np.all(UT == UT[:, :1]) else (UT[:, 0] if not UT.size else None)
    f, folded = _integral_search(eom, pv, steady)
    cols = R.model_columns(eom, out_names, f, folded)
    return R.record(eom, cols, t, X[:, :n], X[:, n:], pv, UT.T, using=(f,))


def _singularity_report(eom, signals, t, meta, threshold):
    mons = getattr(eom, "singularity_monitors", None) or {}
    if not mons or len(t) == 0:
        return
    report = {}
    for name, spec in mons.items():
        thr = spec[1] if isinstance(spec, tuple) and len(spec) > 1 else threshold
        v = np.abs(signals[f"singularity({name})"])
        i = int(np.argmin(v))
        report[name] = {"closest": float(v[i]), "time": float(t[i]), "threshold": float(thr)}
        if v[i] < thr:
            meta["warnings"].append(
                f"the run came within {v[i]:.3g} of the singular configuration of {name} at t = {t[i]:.6g} "
                f"(Euler/Cardan angles lose a degree of freedom there; accuracy degrades; a quaternion "
                f"parametrization avoids this)")
    meta["singularity"] = report


MAX_INTEGRAL_SEARCH = 20   # coordinates: beyond this the search costs more than a typical run


def _integral_search(eom, pv, u=None):
    """(the first integrals' Function (t, x, p) or None, whether it is of the folded model):
    cyclic momenta and the Jacobi integral, recorded so their drift measures the integrator.
    The search is kept in the workspace (and on disk).  u: the inputs' constant values (None:
    time-varying, then no integrals are searched); with inputs the search runs on the model
    with them as trailing parameters."""
    if eom.inputs:
        if u is None:
            return None, False
        from .eom import fold_inputs

        key = tuple(float(v) for v in u)
        folded = eom.workspace.folded(key, lambda: fold_inputs(eom, u))
        return _integral_search(folded, np.r_[pv, u])[0], True
    searchable = eom.n <= MAX_INTEGRAL_SEARCH and eom.model is not None and not eom.model.contacts

    def search():
        from .analysis.integralcache import integral_function      # (the search, cached on disk)

        # shared by the EOM's replace copies with the same equations (other Models of the same
        # structure): one Function object, so the recorder's Function is shared too
        return eom.workspace.by_content(eom, ("q", "qd", "t", "p", "T", "V", "D", "Q", "g"),
                                        ("first_integrals", np.asarray(pv, float).tobytes()),
                                        lambda: integral_function(eom, pv))

    return eom.workspace.first_integrals(search if searchable else lambda: None), False


def _integral_drift(signals, eom) -> dict:
    fs = [eom.workspace.first_integrals()]
    if eom.inputs:      # the integrals were searched on the model with constant inputs folded in
        fs = [v.workspace.first_integrals() for v in eom.workspace.folded_variants()]
    out = {}
    for name in [n for f in fs if f is not None for n in f.name_out()]:
        v = signals.get(name)
        if v is not None and len(v) and np.isfinite(v).all():
            out[name] = float(np.abs(v - v[0]).max())
    return {"first_integral_drift": out} if out else {}


def _energy_drift(signals) -> dict:
    """accuracy.energy_drift without the keys it cannot fill (a back end's own statistics)."""
    from .simulation.accuracy import energy_drift

    return {k: v for k, v in energy_drift(signals).items() if v is not None}


def is_conservative(eom) -> bool:
    """D = 0, Q = 0 and T, V independent of time.  Builds Q when the recursive route has not
    yet: an answer that depended on whether another caller had built it would make the
    metadata and ``--emit problem`` depend on what ran before in the process."""
    import casadi as ca

    try:
        D, Q = ca.SX(eom.D), ca.SX(eom.Q)
        return bool(D.is_zero() and Q.is_zero()
                    and not ca.depends_on(ca.vertcat(ca.SX(eom.T), ca.SX(eom.V)), eom.t))
    except Exception:  # noqa: BLE001
        return False


def _dedup(text: str) -> list[str]:
    seen, out = set(), []
    for ln in text.splitlines():
        ln = ln.strip()
        if ln and ln not in seen:
            seen.add(ln)
            out.append(ln)
        if len(out) >= 20:
            break
    return out


def versions() -> dict[str, str]:
    import platform

    import casadi

    from . import __version__

    return {"mechdsl": __version__, "casadi": casadi.__version__, "numpy": np.__version__,
            "scipy": _scipy_version(), "python": platform.python_version()}


def _scipy_version() -> str:
    """scipy.__version__ without importing scipy (8 ms) when the run did not: its version.py
    is a file of plain assignments, read on its own."""
    import sys

    mod = sys.modules.get("scipy")
    if mod is None:
        import importlib.util
        import os

        try:
            spec = importlib.util.find_spec("scipy")
            where = os.path.join(os.path.dirname(spec.origin), "version.py")
            vspec = importlib.util.spec_from_file_location("_mechdsl_scipy_version", where)
            vmod = importlib.util.module_from_spec(vspec)
            vspec.loader.exec_module(vmod)
            return str(vmod.version)
        except Exception:     # another layout: ask scipy itself
            pass
        import scipy as mod
    return str(mod.__version__)
