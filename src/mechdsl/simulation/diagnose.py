"""Why a run stopped: locate an ODE run's failure inside its last output interval and classify it.

``diagnose`` re-integrates the failing interval on finer grids and looks at the state there
(singular mass matrix, non-finite right-hand side, blow-up, the integrator's own message).
"""
from __future__ import annotations

import numpy as np

from .. import integrators as I
from ..eom.codegen import FastFunction
from ..output.result import Failure
from .choose import NO_U, min_step
from .registry import spec


def diagnose(eom, funcs, post, method, run, grid, xs, pv, rtol, atol, max_steps, extra, u=NO_U) -> Failure:
    """Say when and why a run stopped: locate the failure inside the last output interval
    (re-integrating it on a fine grid) and look at the state there."""
    k = max(run.reached - 1, 0)
    t_last, x_last = float(grid[k]), (run.X[k] if run.reached else xs)
    t_fail = run.fail_time
    x_fail = run.fail_state
    unstable = False
    if x_fail is None and k + 1 < len(grid) and spec(method).family == "casadi":   # the plug-in can zoom
        # zoom in: re-integrate the failing interval on finer grids (3 levels of 50 subintervals);
        # a fixed-step method is checked with the adaptive erk instead
        zoom = "erk" if spec(method).fixed_step else method
        zs = spec(zoom)
        a, b, xa = t_last, float(grid[k + 1]), x_last
        hmin = min_step(float(grid[0]), float(grid[-1]))
        try:
            opts = I.casadi_options(zs.plugin, zs.options, rtol, atol, max_steps, None, extra if zoom == method else {},
                                    hmin=hmin)
            for level in range(3):
                if b - a <= 100 * hmin:
                    break
                fine = np.linspace(a, b, 51)
                sub = I.run_casadi(zs.plugin, funcs["ode"], fine, xa, pv, opts, I.Progress(False, 0, 1), u=u)
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

