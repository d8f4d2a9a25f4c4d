"""The ODE back end: minimal coordinates, CasADi integrator plug-ins, scipy or the compiled loop.

``simulate_ode(eom, settings, progress, drive) -> Result`` integrates M(q) q'' = bias on the
output grid with the plug-in of the method (plugins.py; method = auto: choose.py, and the
compiled dop853 loop when compiling pays, crk.py), locates and classifies a failure
(diagnose.py) and records the signals (monitors.py).  A failed run never raises: the Result
keeps every output point reached and ``Result.failure`` says when and why.  See
docs/simulate.md (users) and docs/internals/numerics.md (design).
"""
from __future__ import annotations

import copy
import math
import threading
import time
from typing import Any

import numpy as np

from ... import integrators as I
from ...diagnostics import UsageError, did_you_mean
from ...eom import codegen, parameter_vector, sxcode
from ...eom.codegen import casadi_functions
from ...eom.start import start_vector
from ...output.result import INTERRUPTED, Failure, Result
from .. import monitors as Mon
from ..choose import NO_U, choose_method, fixed_step_count, min_step
from ..diagnose import diagnose
from ..drive import build_drive
from ..record import ENERGY_NAMES
from ..registry import ODE_FAMILIES, ode_methods, spec
from ..settings import DEFAULT_POINTS
from . import Backend
from . import crk
from . import payback
from . import plugins as P
from .crk import LoopFunctions, auto_choice, compiled_mapped, compiler, engine_for, library, loop_ode, mapped, scipy_name


class _Quiet:
    """The progress of a companion run: nothing shown."""

    def update(self, t: float) -> None:
        pass


_QUIET = _Quiet()
MAX_STEPS_TOTAL = 2_000_000          # default max_steps = max(20000, this / output intervals)


def default_max_steps(s, points: int) -> int:
    """Integrator steps per output interval of a run on ``points`` output times: the setting
    ``max_steps``, else max(20000, MAX_STEPS_TOTAL / intervals) (also the FMU's steps per
    communication step, mechdsl.export)."""
    return int(s.max_steps or max(20_000, MAX_STEPS_TOTAL // (points - 1)))


class OdeBackend(Backend):
    name = "ode"
    noun = "an ODE"
    groups = ("ode", "fixed_step")
    accepts = {"formulation": ("ode",)}     # the unconstrained problem's own name: no note

    def prepare(self, problem) -> "OdeSetup":
        if problem.drive is not None:         # a drive carries what its signals did during a run
            return OdeSetup.build(problem.eom, problem.settings, problem.drive)
        return kept_setup(problem.eom, problem.settings,
                          lambda: OdeSetup.build(problem.eom, problem.settings, problem.drive))

    def run(self, problem, progress, setup=None):
        setup = setup if setup is not None else self.prepare(problem)
        pv, xs = setup.start_of(problem.settings)
        return setup.run(pv, xs, progress)

    def integration(self, problem, setup, pv, xs):
        if setup.method is None:
            raise UsageError(f"{problem.model} has no coordinates: nothing is integrated")
        return setup.method, setup.funcs, setup.reason

    def describe(self, r):
        method = r.metadata.get("method")
        m = spec(method) if method in ode_methods() else None
        plugin = "none" if m is None else f"{m.family}:{m.plugin}"
        return {"formulation": "ode", "integrator": plugin, "method": method}


def simulate_ode(eom, s, progress=None, drive=None) -> Result:
    """One ODE run (settings ``s`` validated by mechdsl.simulation.settings; ``drive``: the
    inputs' signals, mechdsl.simulation.drive, built by formulate): ``OdeSetup.build`` then
    ``OdeSetup.run`` at the settings' parameters and start values."""
    setup = OdeSetup.build(eom, s, drive)
    pv = parameter_vector(eom, s.p)
    return setup.run(pv, start_vector(eom, s.x0, pv), progress)


class OdeSetup:
    """What an ODE run builds before it integrates, built once (``prepare`` of the simulation
    layer): the method (``auto`` resolved at the settings' start values and parameters), the
    Functions it integrates (virtual machine, compiled, or the compiled stepping loop), the
    output grid, the step budget and the integrator's options.  ``run(pv, xs)`` integrates
    from any start and parameter values with them: nothing is built again (CasADi plug-ins:
    ``integrator()`` is the integrator a run uses, cached with its Functions)."""

    def __init__(self, eom, s, drive, grid, method, reason, funcs, post, meta, loop_compiled, out_names):
        self.eom, self.settings, self.drive, self.grid = eom, s, drive, grid
        pv = parameter_vector(eom, s.p)
        self._start = (pv, start_vector(eom, s.x0, pv))      # of the settings it was built for
        self.method, self.reason, self.funcs, self.post = method, reason, funcs, post
        self.meta, self.loop_compiled, self.out_names = meta, loop_compiled, out_names
        self._named, self._recorders = None, {}
        self._mapper = None       # (recorder Function, its compiled code in the loop's library) or None
        self.max_steps = default_max_steps(s, len(grid))
        self.extra = dict(s.integrator_options or {})
        self._direct = None       # the compiled loop's call of a plain run, worked out once (_direct_call)
        self._pairs = {}          # id(companion setup) -> (it, its _direct_call, crk.KeptPair or None)
        self.partner = None       # the error estimate's companion of these runs (Partner, estimate.py)

    @classmethod
    def build(cls, eom, s, drive=None) -> "OdeSetup":
        functions = s.ode.functions
        method = s.method
        if method != "auto" and spec(method).family not in ODE_FAMILIES:
            raise UsageError(f"method '{method}' does not apply to an ODE model (methods: "
                             f"{', '.join(['auto', *ode_methods()])}, or a fixed-step method)")
        t0, t1, rtol, npts = s.t_start, s.t_end, s.rtol, s.points or DEFAULT_POINTS
        pv = parameter_vector(eom, s.p)
        xs = start_vector(eom, s.x0, pv)
        out_names = _check_outputs(eom, s.outputs)
        compiled = s.compiled
        if drive is None:
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
            return cls(eom, s, drive, grid, None, None, vm, post, meta, None, out_names)
        auto_compiled = None
        if method == "auto":
            method, reason, info = choose_method(eom, vm, xs, pv, t0, t1, rtol, u=uv, rows=crk.interpreted_rows(vm))
            meta["auto"] = info
            if method == "erk" and compiled is not False and functions is None:
                method, reason, auto_compiled = _auto_compile(eom, vm, xs, pv, t0, t1, rtol, uv, reason, meta)
        else:
            reason = "requested"
        if spec(method).compiled_loop and compiled is False:     # compiled = false wins: never compile
            method, reason = scipy_name(method), (f"{method} requested with compiled = false: its loop would "
                                                  f"compile; {scipy_name(method)} is the same method stepped in Python")
        if "compiled" not in meta:
            meta["compiled"] = "requested" if compiled else ("off (requested)" if compiled is False else "no")
        meta.update(method=method, method_reason=reason, integrator=spec(method).description)
        loop_compiled = mapper = None
        if functions is not None:
            funcs = functions
        elif spec(method).compiled_loop:     # the stepping loop, the model compiled or interpreted (crk.py)
            rec = None if eom.inputs else (lambda: Mon.recorder_function(eom, pv, out_names))
            funcs, loop_compiled, mapper = _compile_loop(eom, vm, meta, fallback="erk" if auto_compiled else None,
                                                         compiled=compiled, drive=drive, record=rec)
            if auto_compiled and not loop_compiled:     # could not build it: the automatic choice falls back
                method, loop_compiled = "erk", None
                meta.update(method=method, integrator=spec(method).description,
                            method_reason=reason.split(";")[0] + "; the compiled stepping loop it would pick "
                                                                 "could not be built (see the warning): erk in "
                                                                 "the virtual machine")
                meta["compiled"] = "no: auto (the compiled loop could not be built)"
        elif compiled:
            funcs = casadi_functions(eom, compiled=True,
                                     names=("ode", "ode_jacobian") if spec(method).needs_jacobian else ("ode",),
                                     jacobian="forward" if spec(method).forward_only else "full")
            funcs["ode"]  # compile now (notes below)
            funcs = drive.closed(funcs)
        else:
            funcs = vm
        unavailable = compiled and loop_compiled is None and not getattr(funcs, "compiled", False)
        if unavailable:     # said once, as a warning (not also as a note)
            meta["warnings"].append("compiled code unavailable: " + "; ".join(getattr(funcs, "notes", [])))
        else:
            meta["notes"] += list(getattr(funcs, "notes", []))
        setup = cls(eom, s, drive, grid, method, meta["method_reason"], funcs, post, meta, loop_compiled, out_names)
        setup._mapper = mapper
        return setup

    def start_of(self, s):
        """(parameter vector, start vector) of the settings ``s`` (copies: kept for a warm run)."""
        same = s is self.settings
        if not same:
            try:
                same = bool(s == self.settings)
            except (ValueError, TypeError):       # arrays among the values: compared as keys
                same = _frozen(s) == _frozen(self.settings)
        if same:
            return self._start[0].copy(), self._start[1].copy()
        pv = parameter_vector(self.eom, s.p)
        return pv, start_vector(self.eom, s.x0, pv)

    def options(self, fixed_steps: int | None = None, hmin: float | None = None) -> dict:
        """The CasADi integrator options a run of this setup uses (CasADi plug-ins)."""
        s, m = self.settings, spec(self.method)
        return I.casadi_options(m.plugin, m.options, s.rtol, s.atol, self.max_steps, fixed_steps, self.extra,
                                hmin=min_step(s.t_start, s.t_end) if hmin is None else hmin)

    def integrator(self, ode=None):
        """The casadi.integrator a run of this setup integrates with over its output grid (a
        CasADi plug-in without fixed steps): the same cached Function a run builds."""
        m = spec(self.method)
        if m.family != "casadi" or m.fixed_step:
            raise ValueError(f"{self.method} has no CasADi integrator over a grid")
        return I.cached_integrator(m.plugin, self.funcs["ode"] if ode is None else ode, self.grid, self.options())

    def run(self, pv, xs, progress=None) -> Result:
        """Integrate from the start ``xs`` at the parameters ``pv`` (nothing is built again)."""
        wall0 = time.perf_counter()
        meta = plain_copy(self.meta)
        if self.method is None:
            return _no_state_result(self.eom, self.grid, pv, self.out_names, meta, wall0, self.drive)
        t, X, run, failure = self.integrate(pv, xs, meta, progress)
        return self.record(t, X, pv, xs, meta, run, failure, self.loop_compiled, wall0)

    def _direct_run(self, call, pv, xs, bar):
        """The direct loop call of a run; with the error estimate's companion in the same C call
        when estimate.py registered it for this setup's runs (``self.partner``: its setup and
        start), its States then left in ``partner.ready`` for the estimate (crk_calls.run_pair)."""
        loop, method, grid, u, rtol, atol, max_steps, hmin = call
        partner = self.partner
        if partner is None:
            return crk.run_compiled(loop, method, grid, xs, pv, u, rtol, atol, max_steps, hmin, bar)
        partner.ready = None
        other = partner.setup._direct_call()
        if not other or other[0].rt is not loop.rt:
            return crk.run_compiled(loop, method, grid, xs, pv, u, rtol, atol, max_steps, hmin, bar)
        loop2, method2, grid2, u2, rtol2, atol2, max_steps2, hmin2 = other
        kept = self._pairs.get(id(partner.setup))
        if kept is None or kept[0] is not partner.setup or kept[1] is not other:
            kp = crk.kept_pair(loop, (method, grid, xs, pv, u, rtol, atol, max_steps, hmin), loop2,
                               (method2, grid2, partner.xs, partner.pv, u2, rtol2, atol2, max_steps2, hmin2))
            if len(self._pairs) >= 4:
                self._pairs.clear()
            kept = self._pairs[id(partner.setup)] = (partner.setup, other, kp)
        kp = kept[2]
        got = None
        if kp is not None and kp.fits(xs, pv, partner.xs, partner.pv):   # the buffers kept for this pair (the same call)
            got = crk.run_kept_pair(kp, xs, pv, partner.xs, partner.pv, bar, (max_steps, hmin), (max_steps2, hmin2))
        if got is not None:
            run, second = got
        else:
            run, second = crk.run_pair(loop, (method, grid, xs, pv, u, rtol, atol, max_steps, hmin), loop2,
                                       (method2, grid2, partner.xs, partner.pv, u2, rtol2, atol2, max_steps2, hmin2),
                                       bar)
        if second is crk.COMPANION_INTERRUPTED:       # the estimate raises it (estimate._kept_states)
            partner.ready = second
        elif second is not None:
            ready = partner.setup._states_of(second, partner.xs)
            if ready is not None:       # the call's seconds that were the companion's: the estimate's, not the run's
                ready.stats.update(cpu_time=second.stats["cpu_time"], wall_time=second.stats["wall_time"])
                run.stats.update(companion_cpu_time=second.stats["cpu_time"],
                                 companion_wall_time=second.stats["wall_time"])
            partner.ready = ready
        return run

    def _direct_call(self):
        """(loop, method, grid, u, rtol, atol, max_steps, hmin) when a run of this setup is one
        call of the compiled model's stepping loop, as ``_run`` and the loop's plug-in make it
        (no inputs, tables, fixed step, integrator options or interpreted model that may switch
        engines: payback.py); False otherwise.  Worked out once: a warm run skips the layers
        between (the same call, the same bits)."""
        if self._direct is None:
            funcs, s = self.funcs, self.settings
            loop = getattr(funcs, "loop", None)
            plain = (isinstance(funcs, LoopFunctions) and funcs.drive is None and not self.eom.inputs
                     and self.method is not None and spec(self.method).compiled_loop
                     and not spec(self.method).fixed_step and s.fixed_step.dt is None and not self.extra
                     and not self.drive.breakpoints(s.t_start, s.t_end).size and loop is not None
                     and loop.engine == "compiled")
            self._direct = (loop, self.method, self.grid, self.drive.vector(s.t_start), s.rtol, s.atol,
                            self.max_steps, min_step(s.t_start, s.t_end)) if plain else False
        return self._direct

    def states(self, pv, xs) -> "States":
        """The trajectory alone (no signals recorded, no metadata): what the default error
        estimate's companion run needs (simulation/estimate.py)."""
        if self.method is None:
            return States(self.grid.copy(), np.zeros((len(self.grid), 0)), None, {})
        call = self._direct_call()
        if call:                        # one call of the loop; a run that did not simply succeed goes the long way
            loop, method, grid, u, rtol, atol, max_steps, hmin = call
            done = self._states_of(crk.run_compiled(loop, method, grid, xs, pv, u, rtol, atol, max_steps, hmin,
                                                    _QUIET), xs)
            if done is not None:
                return done
        t, X, run, failure = self.integrate(pv, xs, {"notes": [], "warnings": []})
        bad = np.flatnonzero(~np.isfinite(X).all(axis=1))
        if bad.size:                    # as the template's check_finite cuts a run's states
            k = int(bad[0])
            t, X = t[:k], X[:k]
            if failure is None:
                failure = Failure(float(self.grid[k]), "non-finite state", "a state became non-finite")
        return States(t, X[:, :self.eom.n], failure, _counts(self.method, run.stats))

    def _states_of(self, run, xs) -> "States | None":
        """``states``' answer from a direct loop call's Run that reached its end with every state
        finite (as ``integrate`` and ``states`` make it), else None."""
        if (run.error is None and not run.interrupted and run.reached == len(self.grid)
                and math.isfinite(np.add.reduce(run.X, axis=None))):
            X = run.X.copy()
            X[0] = xs
            return States(self.grid.copy(), X[:, :self.eom.n], None, crk.counts(run.stats))
        return None

    def integrate(self, pv, xs, meta, progress=None):
        """(t, X, the integrator's Run, Failure or None): the states on the output times reached."""
        eom, s, drive, grid = self.eom, self.settings, self.drive, self.grid
        method, funcs, max_steps, extra = self.method, self.funcs, self.max_steps, self.extra
        t0, t1, rtol, atol = s.t_start, s.t_end, s.rtol, s.atol
        uv = drive.vector(t0)
        bar = I.Progress(progress, t0, t1, label=f"{eom.name} ({method})")
        breaks = drive.breakpoints(t0, t1)
        call = self._direct_call()
        try:
            if call:                    # one call of the compiled loop, as _run would make it
                loop, method, grid, u, rtol, atol, max_steps, hmin = call
                run, fixed = self._direct_run(call, pv, xs, bar), None
            elif breaks.size and getattr(funcs, "drive", None) is None:     # (the loop reads tables itself)
                run, fixed = _run_pieces(method, funcs, grid, xs, pv, rtol, atol, max_steps, s.fixed_step.dt, extra,
                                         bar, eom, t0, t1, meta["notes"], 10 * s.budget, drive, breaks)
            else:
                run, fixed = _run(method, funcs, grid, xs, pv, rtol, atol, max_steps, s.fixed_step.dt, extra, bar,
                                  eom, t0, t1, meta["notes"], 10 * s.budget, u=uv)
        finally:
            bar.close()
        if fixed is not None:
            meta["fixed_steps"] = fixed
        engine = (run.stats or {}).get("engine")
        if engine and meta.get("loop_engine") and engine != meta["loop_engine"]:     # payback.py
            meta["loop_engine"] = engine
            after = run.stats.get("compiled_after")
            meta["notes"].append("the model, run interpreted (too large to compile up front, or not compiled yet), "
                                 "has been evaluated long enough to pay for its compile: " + (f"compiled after {after} evaluations of this run"
                                                                      if after else "compiled") +
                                 " (the same bits as interpreted)")
        failure = None
        if run.interrupted:             # Ctrl-C: the rows reached are kept, nothing to diagnose
            failure = Failure(float(grid[max(run.reached, 1) - 1]), "interrupted", INTERRUPTED)
            meta["interrupted"] = True
        elif run.error is not None or run.reached < len(grid):
            u_fail = drive.vector(float(grid[max(run.reached - 1, 0)]))
            failure = diagnose(eom, funcs, self.post, method, run, grid, xs, pv, rtol, atol, max_steps, extra,
                               u=u_fail)
        n_ok = max(run.reached, 1)
        X = run.X[:n_ok].copy()
        X[0] = xs
        t = grid[:n_ok].copy()
        return t, X, run, failure

    def record(self, t, X, pv, xs, meta, run, failure, loop_compiled, wall0) -> Result:
        """The Result of a trajectory X on the times t: signals, statistics, metadata."""
        eom, s, drive, funcs = self.eom, self.settings, self.drive, self.funcs
        method, max_steps, extra, out_names = self.method, self.max_steps, self.extra, self.out_names
        names = self._names()
        U = drive.values(t, X) if drive.names else np.zeros((len(t), 0))     # (no inputs: nothing to look up)
        if eom.inputs:
            signals = Mon.compute_signals(eom, t, X, pv, out_names, U=U)
        else:                         # no inputs: the recorder of these parameter values, kept
            rec = self._recorders.get(pv.tobytes())
            if rec is None:
                if len(self._recorders) >= 4:
                    self._recorders.clear()
                rec = self._recorders[pv.tobytes()] = Mon.signal_recorder(eom, pv, out_names, self._mapper)
                # the first integrals' names (the search ran with the recorder's columns and is
                # memoized in the workspace: the same names on every later run)
                rec.integrals = Mon.integral_names(eom)
            signals = rec(t, X)
        record_inputs(drive, U, signals, meta)
        Mon.singularity_report(eom, signals, t, meta, s.ode.singularity_threshold)
        stats = {**{k: v for k, v in _counts(method, run.stats).items() if v is not None},
                 "points": int(len(t)), "wall_time": time.perf_counter() - wall0}
        stats.update(Mon.energy_drift_stats(signals))
        stats.update(Mon.integral_drift_of(signals, rec.integrals) if not eom.inputs else
                     Mon.integral_drift(signals, eom))
        stats["raw"] = run.stats
        if run.messages.strip():
            meta["integrator_messages"] = _dedup(run.messages)
        meta["conservative"] = names["conservative"]
        n, coords = names["n"], names["coords"]
        meta["options"] = {"t_start": s.t_start, "t_end": s.t_end, "rtol": s.rtol, "atol": s.atol,
                           "points": len(self.grid), "method": method,
                           "compiled": (bool(getattr(funcs, "compiled", False)) if loop_compiled is None
                                        else bool(loop_compiled) and meta.get("loop_engine") == "compiled"),
                           "max_steps": max_steps, "outputs": list(out_names),
                           "parameters": dict(zip(names["params"], pv.tolist())),
                           "start": {**dict(zip(coords, xs[:n].tolist())), **dict(zip(names["speeds"], xs[n:].tolist()))},
                           **({"integrator_options": extra} if extra else {})}
        return Result(t=t, q=X[:, :n], qd=X[:, n:], coordinates=coords, signals=signals,
                      stats=stats, metadata=meta, failure=failure)

    def loop_call(self, pv, xs) -> dict | None:
        """What a run of this setup from (pv, xs) calls, as plain data for a prepared warm run
        (simulation/warm_run.py): the compiled stepping loop's spec and the call's arguments,
        as ``integrate`` passes them.  None: the run is not one call of the loop (another method,
        inputs, a fixed step, integrator options)."""
        funcs, s = self.funcs, self.settings
        if (not isinstance(funcs, LoopFunctions) or funcs.drive is not None or self.eom.inputs or self.method is None
                or s.fixed_step.dt is not None or self.extra or self.drive.breakpoints(s.t_start, s.t_end).size):
            return None
        loop = getattr(funcs, "loop", None)      # the library the run used (its recorder compiled beside the ode)
        if loop is None:
            loop, _ = library(funcs.loop_ode, tag=getattr(getattr(funcs, "eom", None), "name", "model"),
                              engine=getattr(funcs, "engine", None))
        if loop is None or getattr(loop, "spec", None) is None:
            return None
        return {"loop": loop.spec, "method": self.method, "grid": self.grid.copy(), "x0": np.array(xs, float),
                "p": np.array(pv, float), "u": self.drive.vector(s.t_start), "rtol": s.rtol, "atol": s.atol,
                "max_steps": self.max_steps, "hmin": min_step(s.t_start, s.t_end), "n": self.eom.n}

    def recorder_program(self, pv) -> dict | None:
        """The recorder a run at the parameters ``pv`` used, as plain data (the interpreter's
        program of its Function, its column names and sizes, the first integrals' names), for a
        prepared warm run; None when this setup has not recorded at ``pv`` or cannot say."""
        ev = getattr(self._recorders.get(np.asarray(pv, float).tobytes()), "evaluate", None)
        m = None if ev is None else mapped(ev.function)
        if m is None:
            return None
        return {"names": list(ev.names), "program": m.prog.arrays(), "nnz_in": list(m.nnz_in), "nout": m.nout,
                "dense": m.dense, "where": m.where, "sizes": tuple(ev.sizes[:3]),
                "integrals": Mon.integral_names(self.eom)}

    def _names(self) -> dict:
        """What every run's record reads of the equations, read once (their fields are lazy)."""
        if self._named is None:
            eom = self.eom
            coords = tuple(eom.coords)
            self._named = {"n": eom.n, "coords": coords, "params": tuple(eom.params),
                           "speeds": tuple(f"der({c})" for c in coords), "conservative": Mon.is_conservative(eom)}
        return self._named


_LEAVES = frozenset((str, int, float, bool, type(None)))       # kept as they are, without a call


def plain_copy(v):
    """A deep copy of plain data (dicts, lists, strings, numbers; anything else deep-copied):
    a setup's metadata for one run, at a third of copy.deepcopy's cost (leaves of the plain
    types are taken without a call each)."""
    if type(v) is dict:
        return {k: x if type(x) in _LEAVES else plain_copy(x) for k, x in v.items()}
    if type(v) is list:
        return [x if type(x) in _LEAVES else plain_copy(x) for x in v]
    if isinstance(v, dict):
        return {k: plain_copy(x) for k, x in v.items()}
    if isinstance(v, list):
        return [plain_copy(x) for x in v]
    if v is None or isinstance(v, (str, int, float, bool, tuple)) and (type(v) is not tuple or
                                                                        all(isinstance(x, (str, int, float)) for x in v)):
        return v
    return copy.deepcopy(v)


def plain_copier(v):
    """A function of no arguments that returns ``plain_copy(v)`` of this value, which must not
    change afterwards (a frozen settings object's plain form): its containers found once, each
    copy is then dict.copy/list.copy of them (a third of plain_copy's cost on the settings)."""
    if type(v) is dict:
        subs = [(k, plain_copier(x)) for k, x in v.items() if type(x) not in _LEAVES]
    elif type(v) is list:
        subs = [(i, plain_copier(x)) for i, x in enumerate(v) if type(x) not in _LEAVES]
    else:
        return lambda: plain_copy(v)
    if not subs:
        return v.copy

    def copy():
        out = v.copy()
        for k, f in subs:
            out[k] = f()
        return out
    return copy


class Partner:
    """The default error estimate's companion of a setup's runs (``OdeSetup.partner``, which
    estimate.py sets once its plan and the companion's setup are kept): the companion's OdeSetup
    and start (``pv``, ``xs``), run in the same C call as the run when both are direct loop
    calls; ``ready``: the companion's States of the last run, for the estimate to take."""

    __slots__ = ("setup", "pv", "xs", "ready")

    def __init__(self, setup, pv, xs):
        self.setup, self.pv, self.xs, self.ready = setup, pv, xs, None


def partner(run_setup, setup, pv, xs) -> Partner:
    """Register (or find) the companion ``setup`` at (pv, xs) of the runs of ``run_setup`` (an
    OdeSetup: kept per settings by value, so its runs' companion is the same by value too)."""
    hit = run_setup.partner
    if hit is not None and hit.setup is setup:
        return hit
    hit = run_setup.partner = Partner(setup, pv.copy(), xs.copy())
    return hit


SETUPS_KEPT = 16          # OdeSetups kept for repeated runs (a warm Model, the error estimate's companion)
_SETUPS: dict = {}
_SETUPS_LOCK = threading.Lock()


def kept_setup(eom, s, build) -> "OdeSetup":
    """``build()``'s OdeSetup for the equations ``eom`` and the validated settings ``s``, kept for
    the next run of the same equations and settings (a warm ``Model.simulate`` builds nothing
    again: the method, Functions, compiled loop and output grid depend on these alone, and on
    whether there is a C compiler).  Settings that cannot be hashed (a dict of start values,
    Functions given by hand) are built every time.  The most recently used SETUPS_KEPT are
    kept; holding the EOM keeps its id unique while its entry lives."""
    try:
        key = (id(eom), _frozen(s), setup_environment())
        hash(key)
    except TypeError:
        return build()
    with _SETUPS_LOCK:
        hit = _SETUPS.pop(key, None)
        if hit is not None and hit[0] is eom:
            _SETUPS[key] = hit            # most recently used last
            return hit[1]
    setup = build()
    with _SETUPS_LOCK:
        while len(_SETUPS) >= SETUPS_KEPT:
            _SETUPS.pop(next(iter(_SETUPS)))
        _SETUPS[key] = (eom, setup)
    return setup


def peek_setup(eom, s) -> "OdeSetup | None":
    """The setup ``kept_setup`` keeps for (eom, s), or None (nothing is built)."""
    try:
        key = (id(eom), _frozen(s), setup_environment())
        with _SETUPS_LOCK:
            hit = _SETUPS.get(key)
    except TypeError:
        return None
    return hit[1] if hit is not None and hit[0] is eom else None


def _frozen(s):
    """``s`` with array or list start and parameter values as hashable values of their own (a
    benchmark passes the parameter vector as an array): a key for kept_setup."""
    def freeze(v):
        if isinstance(v, np.ndarray):
            return ("array", v.dtype.str, v.shape, v.tobytes())
        if isinstance(v, list):
            return ("list", tuple(freeze(x) for x in v))
        if isinstance(v, dict):
            return ("dict", tuple(sorted((k, freeze(x)) for k, x in v.items())))
        return v

    if isinstance(s.p, (np.ndarray, list, dict)) or isinstance(s.x0, (np.ndarray, list, dict)):
        return s.replace(p=freeze(s.p), x0=freeze(s.x0))
    return s


def setup_environment() -> tuple:
    """What a setup depends on besides its equations and settings: whether there is a C
    compiler, the compile threshold and the loop's method rule (crk), and the caches its
    Functions and compiled loop came from (a new cache, e.g. emptied by a test, builds anew), and
    whether a model run interpreted until now is to be compiled (payback.bought)."""
    return (compiler(), crk.COMPILE_OPS, crk.DOPRI5_RTOL, id(crk._LIBS), id(crk._RUNTIME), id(codegen._SETS),
            crk.library, codegen.compile_functions, codegen.find_compiler, payback.BOUGHT[0])


class States:
    """A run's trajectory without its signals (``OdeSetup.states``): times ``t``, coordinates
    ``q`` (rows = times), ``failure`` (None: it reached the end), the integrator's ``stats``
    (steps, rhs_evals, ...)."""

    __slots__ = ("t", "q", "failure", "stats")

    def __init__(self, t, q, failure, stats):
        self.t, self.q, self.failure, self.stats = t, q, failure, stats


def _compile_loop(eom, funcs, meta, fallback=None, compiled=None, drive=None, record=None):
    """(Functions of the run, whether the loop runs, (recorder Function, its compiled Mapped) or
    None) for a dopri5/dop853 run: the stepping loop with the model compiled or interpreted
    (crk.engine_for; compiled = true compiles), built or loaded from the cache; a fallback to
    scipy's stepping in Python (or to ``fallback``) is a warning of the run.  ``record``: a
    thunk of the recorder's Function, compiled into the same library when the model is compiled
    and the recorder is small enough to be (engine_for): one compile, and the signals on the
    output grid at compiled speed (the same bits as the interpreter, tests/test_sxcode.py)."""
    ode = loop_ode(funcs)
    engine = "compiled" if compiled else engine_for(ode)
    extra = {}
    if record is not None and engine == "compiled":
        F = record()
        if F is not None and sxcode.supported(F) and engine_for(F) == "compiled":
            extra = {"record": F}
    # a model not compiled yet runs interpreted until that has cost what its compile costs (payback.py)
    rent = not compiled and engine == "compiled" and not payback.buys(ode)
    loop, note = library(ode, tag=eom.name, engine=engine, extra=extra, rent=rent)
    if loop is None and extra:        # the recorder's code would not build: the loop alone
        extra = {}
        loop, note = library(ode, tag=eom.name, engine=engine, rent=rent)
    if loop is not None and getattr(loop, "rented", False):
        engine, extra = loop.engine, {}
        meta["notes"].append(f"{meta['method']} stepping loop: the model runs interpreted until its evaluations "
                             "have paid for its compile (the same bits as compiled)")
    if loop is None:
        instead = (f"{fallback} runs instead" if fallback else
                   f"{meta['method']} runs as scipy's same method stepped in Python")
        meta["warnings"].append(f"compiled stepping loop unavailable ({note}); {instead}")
        return funcs, False, None
    meta["loop_engine"] = engine
    if note:
        meta["notes"].append(f"{meta['method']} compiled stepping loop: {note}")
    loop_funcs = LoopFunctions(funcs, ode, engine, drive, loop=loop)
    if loop_funcs.drive is not None:
        meta["notes"].append("the input tables are read by the stepping loop (data, not code); steps end on the "
                             "zero-order holds' samples")
    mapper = (extra["record"], compiled_mapped(loop, "record", extra["record"])) if extra else None
    return loop_funcs, True, mapper


def _auto_compile(eom, vm, xs, pv, t0, t1, rtol, uv, reason, meta):
    """method = auto on a non-stiff model: erk in the virtual machine, or the compiled dop853
    loop when compiling pays (simulation.crk.auto_choice); ``meta['compiled']`` says why."""
    pick, why, info = auto_choice(eom, vm, xs, pv, t0, t1, rtol, uv, rho=meta["auto"].get("spectral_radius"))
    meta["auto"]["compile"] = info
    if pick is None:
        meta["compiled"] = f"no: auto ({why})"
        return "erk", reason, None
    meta["compiled"] = f"auto ({why})"
    return pick, (reason.split(";")[0] + f"; stepping loop {pick} (Dormand-Prince, C): {why}"), True


def record_inputs(drive, U, signals, meta) -> None:
    """The inputs as signals (named as declared); bound violations of run-time signals warn."""
    for j, name in enumerate(drive.names):
        signals[name] = U[:, j].copy()
    meta.setdefault("warnings", []).extend(drive.check_bounds(U))


def _no_state_result(eom, grid, pv, out_names, meta, wall0, drive) -> Result:
    X = np.zeros((len(grid), 0))
    U = drive.values(grid, X)
    signals = Mon.compute_signals(eom, grid, X, pv, out_names, U=U)
    record_inputs(drive, U, signals, meta)
    meta.update(method="none", method_reason="the model has no coordinates: nothing to integrate",
                options={"t_start": float(grid[0]), "t_end": float(grid[-1]),
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


def _run(method, funcs, grid, xs, pv, rtol, atol, max_steps, dt, extra, bar, eom, t0, t1, meta_notes, budget,
         u=NO_U):
    """One run of the integrator plug-in of ``method`` over the output grid."""
    fixed, steps = None, None
    if spec(method).fixed_step:
        steps, why = fixed_step_count(method, casadi_functions(eom, names=("ode", "ode_jacobian")),
                                      xs, pv, t0, t1, rtol, dt, budget, u=u)
        fixed = {"target_steps": steps, "why": why}
    elif dt is not None:
        fixed = [m for m in ode_methods() if spec(m).fixed_step]
        meta_notes.append(f"dt = {dt} ignored: {method} chooses its own steps (dt applies to {', '.join(fixed)})")
    try:
        run = P.plugin(method).advance(method, funcs, grid, xs, pv, rtol=rtol, atol=atol, max_steps=max_steps,
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
    if spec(method).fixed_step and dt is None:    # the step of the whole run, not of each piece's span
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
    interrupted = False
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
            interrupted = run.interrupted
            break
        x = run.X[-1]
    X = Xf[on_grid]
    reached = I._count_filled(X, 0)
    if fixed is not None:
        fixed = {**fixed, "pieces": int(edges.size - 1), **({"why": why} if why else {})}
    notes.append(f"integrated in {edges.size - 1} pieces, restarting at the input tables' samples inside the run "
                 "(no step crosses a jump of a zero-order hold)")
    return I.Run(X=X, reached=reached, stats=stats, error=error, messages="".join(messages),
                 fail_time=fail_time, fail_state=fail_state, interrupted=interrupted), fixed


def _counts(method, raw):
    return P.plugin(method).counts(method, raw)


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


