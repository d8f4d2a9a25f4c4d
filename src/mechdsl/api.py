"""The Python API (a contract relied upon by other tools).

    m = mechdsl.load(path, model=None, scene=None)      # or mechdsl.loads(text)
    m2 = m.with_params(m=2.0, L=0.5)                     # a new Model; m is unchanged
    r = m.simulate(10.0, rtol=1e-8, atol=1e-10, method="auto", points=501)
    fns = m.casadi()                                     # CasADi Functions (t, x, u, p): "ode", "energy", ...
    m.parameter_values                                   # numeric vector for the "p" input
    m.parameter_vector(l=0.5)                            # p with dependent parameters recomputed
    m.inputs                                             # the control inputs u: name, unit, bounds, default
    m.simulate(3.0, inputs={"F": lambda t, x: -k @ x})   # inputs: number, table, u(t), u(t, x), Function
    m.export_fmu("model.fmu", fmi_version=2)             # an FMU (docs/export.md)

Phases: parse -> analyze (here) -> derive (mechdsl.mechanics) -> generate/simulate.  Each
Model caches its derived equations; models that differ only in parameter values share them.
"""
from __future__ import annotations

import dataclasses
import logging
import math
import threading
from typing import TYPE_CHECKING, Any

import numpy as np

from .model import ir
from .model.records import record
from .diagnostics import Diagnostic, MechError, Span, UsageError, did_you_mean
from .numbers import declared_value
from .overrides import (add_override, dependents_of, in_declared_unit_of, key_value, merge_overrides, number,
                        overrides_of, with_values)

# the front end (lark, ast, semantic) is imported on use: a model served from the model cache
# (mechdsl.eom.modelcache) never needs it
if TYPE_CHECKING:
    from .semantic import Program
    from .semantic.mods import Mod

log = logging.getLogger(__name__)

_EOM_CACHE: dict[Any, Any] = {}
_EOM_CACHE_MAX = 32
_EOM_LOCK = threading.Lock()


def _program(path_or_text: str, is_text: bool, filename: str, units: bool = True):
    from .frontend.parser import parse
    from .semantic import analyze

    if is_text:
        text = path_or_text
    else:
        from .frontend.source import read_source

        filename, text = read_source(path_or_text)
    program = analyze(parse(text, filename), units=units)
    program.source_text = text          # a Model pickles by its source text (Model.__reduce__)
    return program


def load(path, model: str | None = None, scene: str | None = None, units: bool = True,
         cache: bool = True) -> "Model":
    """Load a model (or a scene of it) from a .mech file: see ``mechdsl.load``."""
    from .frontend.source import read_source

    filename, text = read_source(str(path))
    return _load_text(text, filename, model, scene, units, cache)


def loads(text: str, model: str | None = None, scene: str | None = None, filename: str = "<string>",
          units: bool = True, cache: bool = True) -> "Model":
    """Load a model from .mech source text: see ``mechdsl.loads``."""
    return _load_text(text, filename, model, scene, units, cache)


def _load_text(text: str, filename: str, model, scene, units: bool, cache: bool) -> "Model":
    info = _Cache((text, filename, bool(units)), (model, scene), ()) if cache else None
    hit = info.lookup() if info is not None else None
    if hit is not None:
        log.debug("%s: model %s read from the model cache", filename, hit.name)
        return hit
    log.debug("%s: parsing and analysing", filename)
    m = Model._from_program(_program(text, True, filename, units), model, scene)
    if info is not None:
        info.claim(m)
        m._cache = info
    return m


def load_model_ir(path, model: str | None = None, scene: str | None = None) -> ir.Model:
    """The resolved model (ir.Model) of a file: for tools that work on the IR."""
    return load(path, model=model, scene=scene).model


def select_target(program: Program, model: str | None, scene: str | None) -> tuple[str, str]:
    if model is not None and scene is not None:
        raise UsageError("give either a model or a scene, not both")
    if scene is not None:
        if scene not in program.scene_names():
            hint = did_you_mean(scene, program.scene_names())
            raise UsageError(f"no scene named '{scene}' (scenes: {', '.join(program.scene_names()) or 'none'})"
                             + (f"; {hint}" if hint else ""))
        return "scene", scene
    if model is not None:
        if model not in program.model_names():
            hint = did_you_mean(model, program.model_names())
            raise UsageError(f"no model named '{model}' (models: {', '.join(program.model_names())})"
                             + (f"; {hint}" if hint else ""))
        return "model", model
    return program.default_target()


class Model:
    """A resolved model, optionally with a scene's settings, ready to derive and simulate."""

    def __init__(self, program, model: ir.Model, scene: ir.Scene | None = None,
                 overrides: dict | None = None, target: tuple[str, str] | None = None):
        self._program = program           # semantic.Program; None: parsed again on use (a cached Model)
        self.model = model
        self.scene = scene
        self._ov = overrides or {}        # None: built from self._cache.items on use
        self._target = target or (("scene", scene.name) if scene else ("model", model.name))
        self._eom = None
        self._warnings = None             # the front end's warnings for this model (None: the program's)
        self._cache: _Cache | None = None     # where the derived form is remembered (None: nowhere)

    @property
    def program(self):
        """The analysed file (mechdsl.semantic.Program); a Model read from the model cache
        parses its source again only when this is asked for."""
        if self._program is None:
            text, filename, units = self._cache.source
            self._program = _program(text, True, filename, units)
        return self._program

    @property
    def _overrides(self) -> dict:
        if self._ov is None:
            self._ov = overrides_of(self._cache.items, self.model) if self._cache is not None else {}
        return self._ov

    @classmethod
    def _from_program(cls, program: Program, model: str | None, scene: str | None,
                      overrides: dict[str, Mod] | None = None) -> "Model":
        kind, name = select_target(program, model, scene)
        if kind == "scene":
            sc = program.scene(name, overrides)
            m = cls(program, sc.model, sc, overrides, (kind, name))
        else:
            m = cls(program, program.model(name, overrides), None, overrides, (kind, name))
        m._warnings = list(getattr(program, "last_warnings", []))
        return m

    # ------------------------------------------------------------------ description
    @property
    def name(self) -> str:
        """The model's name (``model NAME ... end NAME;``), also when a scene selected it."""
        return self.model.name

    @property
    def coordinates(self) -> tuple[str, ...]:
        """The generalized coordinates' names, in the order of ``q`` (``Result.q`` columns, the
        CasADi state ``x = [q; der(q)]``): a joint's own, e.g. ``("j1.phi", "j2.phi")``."""
        return self.model.coordinate_names

    @property
    def parameters(self) -> dict[str, float]:
        """Every parameter's numeric value (Real and Integer), by name."""
        return {p.name: p.value for p in self.model.parameters}

    @property
    def parameter_names(self) -> tuple[str, ...]:
        """The Real parameters' names in the order of the CasADi input "p" (``parameter_values``)."""
        return tuple(p.name for p in self.model.real_parameters)

    @property
    def parameter_values(self) -> np.ndarray:
        """Numeric vector for the CasADi input "p" (Real parameters in declaration order)."""
        return np.array([p.value for p in self.model.real_parameters], dtype=float)

    @property
    def inputs(self) -> tuple["InputInfo", ...]:
        """The control inputs (``input Real F``): the entries of the CasADi input "u", in order."""
        return tuple(InputInfo(p.name, p.unit, p.min, p.max, float(p.value), p.doc) for p in self.model.inputs)

    def parameter_vector(self, **overrides) -> np.ndarray:
        """The full CasADi "p" with ``overrides`` (free parameters by name) applied and every
        dependent parameter (a binding such as ``I = m * l^2 / 3``) recomputed."""
        by_name = {p.name: p for p in self.model.parameters}
        for k in overrides:
            p = by_name.get(k)
            if p is not None and p.input:
                raise UsageError(f"'{k}' is an input of {self.name}, not a parameter: drive it with "
                                 f"inputs={{'{k}': ...}} or pass it as the CasADi input u")
            if p is not None and p.binding is not None and not p.integer:
                raise UsageError(f"'{k}' is a dependent parameter of {self.name} (computed from others); "
                                 "override the parameters it is computed from")
            if p is not None and p.integer:
                raise UsageError(f"'{k}' is an Integer/Boolean parameter: structural, not part of p; "
                                 "use with_params")
        return self.with_params(**overrides).parameter_values if overrides else self.parameter_values

    @property
    def scene_settings(self) -> dict[str, Any]:
        """The scene's settings (``stop_time``, ``rtol``, ``method``, ...) by name; {} without a scene."""
        return dict(self.scene.settings) if self.scene else {}

    @property
    def warnings(self) -> list[Diagnostic]:
        """The front end's warnings about this model (Diagnostics with severity "warning")."""
        if self._warnings is not None:
            return list(self._warnings)
        return list(getattr(self.program, "last_warnings", []))

    def _repr_html_(self):                      # notebook displays (mechdsl.output.display)
        from .output.display import model_html

        return model_html(self)

    def _repr_markdown_(self):
        from .output.display import model_markdown

        return model_markdown(self)

    # ------------------------------------------------------------------ pickling
    def __reduce__(self):
        """Pickled by its source text, target, overrides, parameter values and scene settings
        (sweeps on worker processes and Dask); the equations are derived again on the other
        side, once per process (``_restore`` caches by the pickled state)."""
        if self._program is None:
            text, filename, units = self._cache.source
        else:
            text = getattr(self.program, "source_text", None)
            filename, units = self.program.file.filename, bool(self.program.units)
        if text is None:
            raise TypeError("this Model was not loaded from source text (mechdsl.load/loads) and cannot be pickled")
        # values of the independent parameters; bound ones are evaluated again from their bindings
        values = tuple((p.name, float(p.value)) for p in self.model.real_parameters if p.binding is None)
        settings = tuple(self.scene.settings) if self.scene is not None else None
        state = (text, filename, units, self._target, self._overrides, values, settings)
        return (_restore, (state,))

    def __repr__(self) -> str:
        scene = f", scene {self.scene.name}" if self.scene else ""
        n = len(self.coordinates)
        return f"<mechdsl.Model {self.name}{scene}: {n} coordinate{'' if n == 1 else 's'}>"

    # ------------------------------------------------------------------ new models
    def with_params(self, **values) -> "Model":
        """A new Model with parameter values (and start values, as 'q.start' / 'q.speed') changed.

        A bare number means the unit the parameter (or coordinate) is declared in (``alpha=45`` is
        45 degrees for ``alpha(unit = "deg")``, as a scene modifier); ``"45 deg"``,
        ``mechdsl.deg(45)`` or ``mechdsl.Quantity(0.785, "rad")`` say theirs (mechdsl.numbers).
        Real parameters only change numbers (derived equations are shared); Integer and
        Boolean parameters and start values re-analyze the model.
        """
        if not values:
            return self
        by_name = {p.name: p for p in self.model.parameters}
        coords = set(self.coordinates)
        real: dict[str, float] = {}
        structural: list[tuple[str, Any]] = []
        for k, v in values.items():
            if k in by_name and not by_name[k].integer:
                real[k] = declared_value(v, by_name[k].unit, k)       # a bare number: the declared unit
            elif k in by_name or "." in k or k in coords:
                structural.append((k, in_declared_unit_of(self.model, k, v)))
            else:
                hint = did_you_mean(k, list(by_name) + [f"{c}.start" for c in coords])
                raise UsageError(f"'{k}' is not a parameter of {self.name}" + (f"; {hint}" if hint else ""))
        m: Model = self
        if structural:
            kind, name = self._target
            info = self._cache.more(tuple((k, key_value(v)) for k, v in structural)) if self._cache is not None else None
            m = info.lookup() if info is not None else None      # stored only if the items were valid
            if m is None:
                tree: dict = {}
                for k, v in structural:
                    add_override(tree, k, v, by_name, coords)
                ov = merge_overrides(self._overrides, tree)
                m = Model._from_program(self.program, name if kind == "model" else None,
                                        name if kind == "scene" else None, ov)
                if info is not None:
                    info.claim(m)
                    m._cache = info
        if real:
            m = m._with_real(real)
        return m

    def _with_real(self, values: dict[str, float]) -> "Model":
        model = with_values(self.model, values)
        from .semantic.physical import errors, value_problems

        problems = errors(value_problems(model))
        if problems:
            raise MechError(problems)
        scene = dataclasses.replace(self.scene, model=model) if self.scene else None
        return self._sibling(model, scene)

    def _sibling(self, model, scene) -> "Model":
        """A Model of the same structure (other values or settings): same program, overrides,
        cache place (it stores the equations under its origin's key) and warnings."""
        new = Model(self._program, model, scene, self._ov, self._target)
        new._ov, new._cache, new._warnings = self._ov, self._cache, self._warnings   # _ov may be lazy (None)
        return new

    def with_settings(self, **settings) -> "Model":
        """A new Model whose scene settings (stop_time, rtol, method, ...) are updated."""
        base = self.scene or ir.Scene(f"{self.name}", self.model)
        merged = dict(base.settings)
        merged.update({k: v for k, v in settings.items() if v is not None})
        scene = dataclasses.replace(base, settings=tuple(merged.items()))
        return self._sibling(self.model, scene)

    # ------------------------------------------------------------------ derived forms
    @property
    def eom(self):
        """The equations of motion (mechdsl.eom.EOM), derived once per model structure.  Frozen:
        ``eom.replace(field=...)`` makes a changed copy; what is derived from it is kept in
        ``Model.workspace``."""
        if self._eom is None:
            key = _structure_key(self.model)
            base = _EOM_CACHE.get(key)
            if base is None:
                from .mechanics import derive

                log.info("deriving the equations of motion of %s", self.name)
                base = derive(self.model)
                from .eom.modelcache import record_callables

                base = record_callables(base)     # point positions a run asks for are stored with it
                with _EOM_LOCK:             # models simulated in several threads
                    if len(_EOM_CACHE) >= _EOM_CACHE_MAX:
                        _EOM_CACHE.pop(next(iter(_EOM_CACHE)), None)
                    _EOM_CACHE[key] = base
            self._eom = base.replace(param_values=self.parameter_values, model=self.model,   # keeps lazy fields lazy
                                     input_defaults=tuple(float(p.value) for p in self.model.inputs))
        return self._eom

    @property
    def workspace(self):
        """What is derived from the equations and kept (Functions, the recorder's, searches):
        ``mechdsl.eom.workspace.Workspace`` of this model's EOM, alive as long as the model."""
        return self.eom.workspace

    def _remember(self) -> None:
        """Store the derived equations (and what a run or an analysis built on them) in the
        model cache: once after the work, so a first run packs them once."""
        if self._cache is not None and self._eom is not None:
            self._cache.remember(self._eom)

    def casadi(self, compiled: bool = False, fixed_parameters=None, *, derivatives: int = 0,
               compile_budget: int | None = None):
        """The CasADi Functions of the problem a run solves (mechdsl.eom.codegen,
        mechdsl.simulation.functions.problem_functions): "ode" (t, x=[q; qd], u, p -> xdot),
        "ode_jacobian", "mass_matrix", "bias", "energy", "outputs", "parameters" (free parameters
        -> p), ...  u holds the inputs (``Model.inputs``; empty without), p is
        ``parameter_vector()``.  A model with constraints: "ode" is the index-1 ODE the run
        integrates (the accelerations with the multipliers solved), "outputs" its outputs
        (reactions included), and the DAE pieces "multipliers", "constraints" (g, gdot),
        "constraint_jacobian", "mass_matrix", "bias" (mechdsl.dae.functions).  An SX Function
        called in an MX graph (an Opti problem) with p given as numbers calls itself with those
        numbers built in (mechdsl.eom.numeric_p: the same values, CasADi folds the arithmetic on
        them); p given as a symbol keeps every derivative with respect to p.

        compiled: each Function is compiled to C when it is first asked for, and only it;
        derivatives=1 or 2 adds its directional derivatives to its library (fwd1_, adj1_; with 2
        also fwd1_adj1_, forward over reverse), which casadi.external finds by name (CasADi
        assembles Jacobians from their sweeps; an exact Hessian for IPOPT).  A compile
        that cannot be done raises (E804: no compiler or a failed build; E805: more than
        compile_budget bytes of C, default 16 MB), never returning the virtual machine's
        Functions silently.

        fixed_parameters: parameters an optimizer does not vary, built into the Functions as
        numbers so that CasADi folds the arithmetic on them (a leaner expression: the
        cart-pole ``ode`` has 30 instructions instead of 38; codegen.drop_cancelled, eom.lean,
        eom.fold).  True fixes them all at the model's values (p is then empty: pass ``[]``); a list of names fixes those at the
        model's values, a dict {name: value} at the given values.  A dependent parameter
        (``I = m * l^2 / 3``) computed only from fixed ones is fixed with them, at its
        recomputed value, so it cannot go stale.  p then holds the other parameters, in
        order, named by ``.parameter_names`` of the returned mapping."""
        from .simulation.functions import problem_functions

        if isinstance(derivatives, bool) or derivatives not in (0, 1, 2):
            raise UsageError(f"derivatives must be 0, 1 or 2 (got {derivatives!r})")
        if compile_budget is not None and (isinstance(compile_budget, bool) or not isinstance(compile_budget, int)
                                           or compile_budget < 1):
            raise UsageError(f"compile_budget must be a number of bytes >= 1 (got {compile_budget!r})")
        fixed = self._fixed_entries(fixed_parameters)
        # sx: ode is an SX Function for every model up to codegen.SX_SOLVE_MAX coordinates (SX
        # glue works for all); the simulator keeps its numeric QR solve
        return problem_functions(self.eom, compiled=compiled, derivatives=derivatives if compiled else 0, sx=True,
                                 fixed=fixed, each=bool(compiled), budget=compile_budget)

    def fast_function(self, name: str = "ode", *, compiled: bool = True, p=None, u=None):
        """``casadi()[name]`` for calls from Python in a loop: compiled to C (when a compiler
        exists; ``compiled=False``: the virtual machine) and called through preallocated
        buffers, with the parameters ``p`` (default: the model's values) and the inputs ``u``
        (default: their declared defaults) bound once.  ``f = m.fast_function(); xdot = f(t,
        x)``: one call of a 7-joint arm's ``ode`` costs a few microseconds, against 30-120 us
        for a plain call of the Function (docs/control.md, benchmarks/python_call.py).  The
        result is a new array; ``f.function`` is the Function called."""
        from .eom.fastcall import fast_function

        return fast_function(self.eom, name, compiled=compiled,
                             p=self.parameter_vector() if p is None else p, u=u)

    def integrator(self, dt: float, *, method: str | None = None, rtol: float | None = None,
                   atol: float | None = None, steps: int | None = None, fixed_parameters=None):
        """The simulation layer's own integrator over one interval, as a CasADi Function
        ``(t0, x0, u, p) -> xf``: the state at t0 + dt from x0 at t0, the inputs u held constant (a
        zero-order hold, as ``m.simulate(inputs={"F": table(...)})`` integrates each sample
        interval).  For direct multiple shooting: the optimizer's dynamics are then the
        simulator's, so the optimal control replayed through ``simulate`` with the same
        method and tolerances reproduces the optimizer's states (docs/control.md).

        method: an ODE method with a CasADi plug-in (default: the scene's, else "auto"
        resolved at the start values as ``simulate`` does); rtol, atol: as ``simulate``;
        steps: fixed steps a call for "rk" / "collocation" (default: from rtol, as
        ``simulate``); fixed_parameters: as ``casadi()`` (p then holds the other parameters)."""
        from .simulation.functions import problem_functions
        from .simulation.prepared import prepare

        if self.eom.g is not None and self.eom.m > 0 or self.model.contacts:
            raise UsageError(f"{self.name} has constraints or contacts: an integrator Function exists for ODE "
                             "models only (multiple shooting on a DAE needs its own formulation)")
        dt = number("dt", dt)
        if not (math.isfinite(dt) and dt > 0):
            raise UsageError(f"dt must be a positive, finite interval (got {dt!r})")
        if steps is not None and (isinstance(steps, bool) or not isinstance(steps, (int, np.integer)) or steps < 1):
            raise UsageError(f"steps must be a whole number of at least 1 (got {steps!r})")
        # the run's own preparation over [0, dt] (method auto resolved at the start values, as a
        # run resolves it; never the compiled stepping loop: it has no CasADi integrator)
        prep = prepare(self.problem(t_start=0.0, t_end=dt, rtol=rtol, atol=atol, method=method, compiled=False))
        funcs = problem_functions(self.eom, names=("ode", "ode_jacobian"), sx=True,
                                  fixed=self._fixed_entries(fixed_parameters))
        return prep.interval_function(funcs, steps)

    def _fixed_entries(self, spec) -> tuple:
        """(index in p, value) pairs of ``casadi(fixed_parameters=spec)``."""
        if spec is None or spec is False:
            return ()
        names = self.parameter_names
        if spec is True:
            return tuple(enumerate(float(v) for v in self.parameter_values))
        if isinstance(spec, str) or not hasattr(spec, "__iter__"):
            raise UsageError("fixed_parameters must be True, a list of parameter names or a dict "
                             f"{{name: value}} (got {spec!r})")
        chosen = list(spec)
        for k in chosen:
            if k not in names:
                hint = did_you_mean(str(k), list(names))
                what = "an input" if any(i.name == k for i in self.inputs) else "a Real parameter"
                raise UsageError(f"fixed_parameters: '{k}' is not {what} of {self.name} (p holds "
                                 f"{', '.join(names) or 'nothing'})" + (f"; {hint}" if hint else ""))
        values = self.parameter_vector(**dict(spec)) if isinstance(spec, dict) else self.parameter_values
        idx = {names.index(k) for k in chosen}
        idx |= dependents_of(self.eom, idx)
        return tuple((i, float(values[i])) for i in sorted(idx))

    def simulate(self, t_end: float | None = None, *, rtol: float | None = None, atol: float | None = None,
                 method: str | None = None, points: int | None = None, progress=None, **kw):
        """Integrate from the start values to t_end; returns a mechdsl.output.result.Result.

        Settings resolve once, argument > scene > default (mechdsl.simulation.settings):
        t_end, rtol, atol, method, points and every other field of SimulationSettings
        (t_start, formulation, outputs, dt, reactions, compiled, budget, estimate_error, ...)."""
        from .simulation import formulate, simulate
        from .simulation.prepared import prepare, unchanged

        args = dict(t_end=t_end, rtol=rtol, atol=atol, method=method, points=points, **kw)
        eom = self.eom
        kept = self._kept_run(args)          # a warm run of the same arguments: settings and problem kept
        if kept is not None and (kept[0] is not eom or not unchanged(kept[1])):
            kept = None
        try:
            # a first run prepares inside the timed run (its statistics count the set-up)
            problem = kept[1] if kept is not None else formulate(eom, self.settings(**args))
            r = simulate(eom, problem.problem.settings if kept is not None else problem.settings,
                         progress=progress, problem=problem)
        finally:
            if kept is None:                 # a repeated run derives nothing new
                self._remember()             # with what the run derived on the way (lazy M, bias)
        if kept is None and problem.drive is None and self._keeps(args):
            self._keep_run(args, (eom, prepare(problem)))     # the setup the run built, kept (ode.kept_setup)
        r.source_model = self                    # for r.animate() / r.plot(); see mechdsl.output.display
        return r

    RUNS_KEPT = 8       # argument sets whose settings and problem a Model keeps (Model.simulate)

    def _kept_run(self, args: dict):
        """(EOM, Prepared problem) kept for a run with these arguments, or None (also when they
        cannot be a key: a list of start values, a table of inputs)."""
        runs = self.__dict__.get("_runs")
        if not runs:
            return None
        try:
            return runs.get(_args_key(args))
        except TypeError:
            return None

    def prepared_run(self, t_end: float | None = None, *, rtol=None, atol=None, method=None, points=None, **kw):
        """The Prepared problem (simulation/prepared.py) ``simulate`` kept for these arguments
        (the same as its own, ``progress`` left out), or None: what a prepared warm run of
        ``mech simulate`` is made from (simulation/warm_capture.py)."""
        kept = self._kept_run(dict(t_end=t_end, rtol=rtol, atol=atol, method=method, points=points, **kw))
        return None if kept is None or kept[0] is not self.eom else kept[1]

    @staticmethod
    def _keeps(args: dict) -> bool:
        try:
            _args_key(args)
        except TypeError:
            return False
        return True

    def _keep_run(self, args: dict, value) -> None:
        """Keep the settings, problem and back-end setup of a run by its arguments: the next run
        with the same arguments resolves, validates, formulates and prepares nothing again (the
        scene's settings and the equations are the Model's own, fixed once it is loaded)."""
        try:
            key = _args_key(args)
        except TypeError:
            return
        runs = self.__dict__.setdefault("_runs", {})
        if len(runs) >= self.RUNS_KEPT:
            runs.pop(next(iter(runs)))
        runs[key] = value

    def sensitivities(self, t_end: float | None = None, params=(), starts=(), outputs=None,
                      method: str = "forward", points: int | None = None, *, times=None, integral=None,
                      **settings):
        """Derivatives of the recorded motion with respect to parameters and start values
        (mechdsl.estimation.sensitivity; docs/fitting.md): a Sensitivities object, ``S[output,
        name]`` the derivative over ``S.t`` in the output's unit per the name's declared unit,
        ``S.to_xarray()`` a Dataset with units.

        params: Real parameters (not dependent ones); starts: start values ``c`` / ``c.start``
        and speeds ``der(c)`` / ``c.speed``.  outputs: the recorded signals (coordinates,
        speeds, outputs, energies; default all).  method "forward": every point of the output
        grid (``points``), one integration with len(params + starts) directions; "adjoint": the
        outputs at ``times`` (default t_end), and d/dname of ``integral`` (names of signals
        whose integral over the run is the objective), one backward integration per output
        and time.  Other keywords: the run's settings (rtol, atol, method of integration as
        ``integrator``... see ``simulate``).  ODE, constrained and input-driven runs; a model
        with contacts is refused (E770)."""
        from .estimation.sensitivity import sensitivities

        if "integrator" in settings:          # the run's method (``method`` names the derivatives')
            settings["method"] = settings.pop("integrator")
        try:
            return sensitivities(self, t_end, params, starts, outputs, method, points, times, integral, settings)
        finally:
            self._remember()

    def fit(self, data, params=(), starts=(), weights=None, bounds=None, experiments=None, *, method: str = "lm",
            max_iterations: int = 100, rank_tol: float | None = None, t_end: float | None = None, **settings):
        """Least-squares estimates of parameters and start values from measured motion
        (mechdsl.estimation.fit; docs/fitting.md): a FitResult with estimates, standard errors,
        correlations, residuals and the combinations the data cannot determine.

        data: a table (pandas DataFrame, dict of arrays, CSV path) with a time column
        (``time`` or ``t``) and columns named like recorded signals (coordinates, der(c),
        outputs, energies), or a list of them (one per experiment).  experiments: one dict per
        table of that experiment's settings (``x0``, ``inputs``, ``p``).  weights: {column:
        weight} (default 1); bounds: {name: (lo, hi)} (default the parameters' min / max).
        method: "lm" (Gauss-Newton / Levenberg-Marquardt with exact sensitivities) or "ipopt"
        (IPOPT over the run's CasADi graph, exact derivatives, Gauss-Newton Hessian; ODE models);
        max_iterations; rank_tol: singular values of the (log-scaled) sensitivity matrix below
        this fraction of the largest count as directions the data cannot determine (default
        1e-6); t_end: end of the runs (default: each experiment's last sample).  Other
        keywords: the runs' settings (rtol, atol, ``integrator`` = the integration method, ...)."""
        from .estimation.fit import RANK_TOL, fit

        if "integrator" in settings:
            settings["method"] = settings.pop("integrator")
        try:
            return fit(self, data, params, starts, weights, bounds, experiments, method=method,
                       max_iterations=max_iterations, rank_tol=RANK_TOL if rank_tol is None else rank_tol,
                       t_end=t_end, settings=settings)
        finally:
            self._remember()

    def export_fmu(self, path, *, fmi_version: int = 2, fmi_type: str | None = None, overwrite: bool = False):
        """Write this model as a Functional Mock-up Unit (mechdsl.export.export_fmu; docs/export.md):
        fmi_version 2 or 3; fmi_type "me", "cs", "both" or None (every interface the model can
        have: co-simulation only with contacts).  Returns an ExportInfo."""
        from .export import export_fmu

        return export_fmu(self, path, fmi_version=fmi_version, fmi_type=fmi_type, overwrite=overwrite)

    def sweep(self, params=None, starts=None, t_end: float | None = None, **kw):
        """A parameter sweep or Monte Carlo ensemble -> xarray.Dataset (mechdsl.sweep.sweep;
        docs/sweeps.md).  params/starts: a grid (dict), mechdsl.sweep.table(...) or a DataFrame,
        or a sampler (mechdsl.sample.uniform/normal/sobol/latin_hypercube); scheduler:
        vectorized | processes | dask | tcp://host:port; out: a .nc file (streamed) or a .csv
        table with its sidecar; resume=True continues the sweep out holds; other keywords:
        settings.  A sweep's runs carry no error estimate unless asked (error_estimate="on") and
        keep their warnings in the status table instead of issuing MechWarnings."""
        from .sweep import sweep

        kw.setdefault("error_estimate", "off")
        kw.setdefault("warn", False)
        return sweep(self, params, starts, t_end, **kw)

    def settings(self, **args):
        """The resolved, validated SimulationSettings of a run (argument > scene > default)."""
        from .simulation import resolve

        return resolve(self.scene_settings, args, where=self.scene.span if self.scene is not None else None)

    def problem(self, **args):
        """The problem a run would solve (mechdsl.simulation.Problem; ``mech compile --emit problem``)."""
        from .simulation import formulate

        return formulate(self.eom, self.settings(**args))

    def equilibria(self, guesses=None, **kw):
        """The equilibria (rest states) of the model with their stability: a list of
        mechdsl.analysis.equilibrium.Equilibrium.

        ``guesses``: starting points, a list of {coordinate: value} (coordinates not named keep
        their start values); without them a spread over each coordinate's range is searched.
        Other keywords (``t``, ``p``, ...): mechdsl.analysis.equilibrium.equilibria.  Each one
        has ``values`` ({coordinate: value}), ``stability`` ("stable", "unstable" or
        "undetermined"), ``reason`` (the Lagrange-Dirichlet or eigenvalue argument) and
        ``hessian_eigenvalues``.  See docs/analysis.md.

            >>> m = mechdsl.load(mechdsl.examples.path("pendulum"), model="PendulumLagrange")
            >>> sorted(e.stability for e in m.equilibria())
            ['stable', 'unstable']
        """
        from .analysis.equilibrium import equilibria

        try:
            return equilibria(self.eom, guesses, **kw)
        finally:
            self._remember()

    def linearize(self, at="equilibrium", **kw):
        """The linear model ``M dq'' + C dq' + K dq = B du`` about a point, and its modes: a
        mechdsl.analysis.linearize.Linearization (``M``, ``C``, ``K``, ``A``, ``B``, ``modes()``).

        ``at``: "equilibrium" (the one nearest to the start values; ``guesses=`` steers the
        search), an Equilibrium from ``equilibria()``, "t=T" (the state reached at time T),
        "start", or {name: value} (``der(name)`` for speeds).  ``inputs=``: the parameters
        treated as inputs u (default: the model's ``input`` parameters).  See docs/analysis.md.
        """
        from .analysis.linearize import linearize

        try:
            return linearize(self.eom, at, **kw)
        finally:
            self._remember()

    def steady_motions(self, pins: dict, **kw):
        """Steady motions (relative equilibria of the Routh-reduced system): see
        mechdsl.analysis.steady.steady_motions and docs/analysis.md#steady-motions."""
        from .analysis.steady import steady_motions

        return steady_motions(self.eom, pins, **kw)

    def first_integrals(self):
        """The conserved quantities found in the equations, each a
        mechdsl.analysis.integrals.FirstIntegral: ``name``, ``kind`` ("energy", "jacobi",
        "momentum" of an ignorable coordinate, "angular_momentum" of a rotational symmetry),
        ``expression`` (text) and ``verified`` ("symbolic" or "numeric").  See docs/analysis.md."""
        from .analysis.integrals import first_integrals

        try:
            return first_integrals(self.eom)
        finally:
            self._remember()

    def draw(self, t: float | None = None, q=None, **kw):
        """The mechanism as a matplotlib Figure: at coordinates q, else at time t of a run from the
        start values, else at the start (docs/animate.md)."""
        from .output.display import draw_model

        return draw_model(self, t, q, **kw)

    def view(self, t_end: float | None = None, q=None, **kw):
        """The interactive 3-D view (mechdsl.view.View; ``.save("x.html")``, inline in Jupyter): the
        motion of a run of t_end seconds from the start values, else the mechanism at coordinates
        q (default: the start values) to turn around; up, trails (and fps, speed for a run) as
        for animate (docs/animate.md)."""
        from .output.display import view_model

        return view_model(self, t_end, q, **kw)

    def equations(self, form: str = "lagrange"):
        """The equations of motion as sympy equations: form "lagrange" (M q'' = bias, one per
        coordinate) or "hamilton" (q' = dH/dp, p' = -dH/dq).  Displays typeset in notebooks."""
        from .output.display import equations

        return equations(self, form)

    def summary(self, derive: bool = False) -> str:
        """Counts and formulation; derive=True asks the mechanics which route it takes."""
        from .model.formulation import describe

        route = None
        if derive:
            try:
                route = self.eom.route
            except MechError:
                route = None
        return describe(self.model, route)


# ---------------------------------------------------------------------------- helpers

_RESTORED: dict = {}
_RESTORED_MAX = 16


def _restore(state) -> "Model":
    """The Model of a pickled state; rebuilt once per process (a worker gets the same state
    with every chunk of a sweep and derives the equations once)."""
    import hashlib
    import pickle

    key = hashlib.sha256(pickle.dumps(state)).hexdigest()
    with _EOM_LOCK:
        hit = _RESTORED.get(key)
    if hit is not None:
        return hit
    text, filename, units, (kind, name), overrides, values, settings = state
    program = _program(text, True, filename, units)
    m = Model._from_program(program, name if kind == "model" else None, name if kind == "scene" else None,
                            overrides or None)
    m = m._with_real(dict(values))
    if settings is not None:
        base = m.scene or ir.Scene(m.name, m.model)
        m = Model(m.program, m.model, dataclasses.replace(base, settings=tuple(settings)), m._overrides, m._target)
    with _EOM_LOCK:
        if len(_RESTORED) >= _RESTORED_MAX:
            _RESTORED.pop(next(iter(_RESTORED)))
        _RESTORED[key] = m
    return m



@record
class InputInfo:
    """One control input: its name, unit, declared bounds (None: none) and default value."""
    name: str
    unit: str | None
    min: float | None
    max: float | None
    default: float
    doc: str = ""


class _Cache:
    """Where a Model's resolved IR and derived equations are remembered on disk
    (mechdsl.eom.modelcache): its source, the target asked for and the structural overrides.
    Models of the same structure (other parameter values or settings) share it; the entry
    always holds the IR of the Model the key names (``owner``)."""

    def __init__(self, source: tuple[str, str, bool], request: tuple, items: tuple):
        self.source = source
        self.request = request
        self.items = items
        self.owner = None           # (ir.Model, ir.Scene, target, warnings) of the Model named by the key
        self.stored = None          # modelcache.content of the stored entry (None: no equations stored)
        self._key = None

    @property
    def key(self) -> str:
        if self._key is None:
            from .eom import modelcache

            text, filename, units = self.source
            self._key = modelcache.key(text, filename, units, self.request, self.items)
        return self._key

    def more(self, items: tuple) -> "_Cache":
        return _Cache(self.source, self.request, self.items + items)

    def lookup(self) -> "Model | None":
        """The Model stored under this key, with its equations, or None (not stored, unusable)."""
        from .eom import modelcache
        from .diagnostics import remember_source

        entry = modelcache.read(self.key)
        if entry is None:
            return None
        try:
            base = modelcache.unpack_eom(entry.eom, entry.model) if entry.eom is not None else None
        except Exception:       # a stream this CasADi cannot read: derived again
            return None
        m = Model(None, entry.model, entry.scene, None, tuple(entry.target))
        m._ov, m._cache, m._warnings = None, self, list(entry.warnings)     # overrides built from items on use
        self.owner = (entry.model, entry.scene, tuple(entry.target), list(entry.warnings))
        if base is not None:
            self.stored = modelcache.content(base)
            key = _structure_key(entry.model)
            with _EOM_LOCK:
                _EOM_CACHE.setdefault(key, base)
        text, filename, _ = self.source
        remember_source(filename, text)      # later diagnostics show their source line
        return m

    def claim(self, m: "Model") -> None:
        """``m`` is the Model this key names: store its IR now (a later run with other
        structural settings finds its parameters without parsing), the equations when derived."""
        from .eom import modelcache

        if self.owner is None:
            self.owner = (m.model, m.scene, m._target, m.warnings)
            modelcache.write(self.key, modelcache.Entry(*self.owner))

    def remember(self, eom) -> None:
        """Store the owner's IR with ``eom`` unless the entry already holds at least as much."""
        from .eom import modelcache

        if self.owner is None:
            return
        now = modelcache.content(eom)
        if self.stored is not None and now[0] >= self.stored[0] and now[1] <= self.stored[1] \
                and now[2] <= self.stored[2]:
            return                      # the entry holds at least as much
        data = modelcache.pack_eom(eom)
        if data is not None:
            model, scene, target, warnings = self.owner
            modelcache.write(self.key, modelcache.Entry(model, scene, target, list(warnings), data))
        self.stored = now               # (nothing storable: not tried again)


def _args_key(args: dict) -> tuple:
    """A hashable key of Model.simulate's arguments (TypeError when one cannot be hashed); the
    type is part of it (1 and 1.0 and True are the same key to a dict)."""
    key = tuple(sorted((k, type(v).__name__, v) for k, v in args.items() if v is not None))
    hash(key)
    return key


def _structure_key(model: ir.Model):
    """The model without parameter values: equations derived for one serve for all."""
    params = tuple(dataclasses.replace(p, value=0.0, binding=None, span=Span()) for p in model.parameters)
    return dataclasses.replace(model, parameters=params, span=Span())


__all__ = ["load", "loads", "load_model_ir", "Model", "MechError"]
