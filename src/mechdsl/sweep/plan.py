"""What a sweep runs (mechdsl.sweep): the checked arguments, the job every chunk gets (settings
resolved once, method auto resolved once from the first run's start, the recorded variables and
state names), the scheduler it can use and the chunk size."""
from __future__ import annotations

import math

import numpy as np

from ..diagnostics import UsageError
from ..model.names import split_state


def check_arguments(options: dict, workers, chunk_size, resume: bool, out) -> None:
    """Usage errors of sweep()'s own arguments, before anything runs."""
    for bad in ("p", "x0"):
        if options.get(bad) is not None:
            raise UsageError(f"sweep: give swept values as params=/starts=, not {bad}=")
    if workers is not None and (isinstance(workers, bool) or not isinstance(workers, int) or workers < 1):
        raise UsageError(f"workers must be an integer >= 1 (got {workers!r})")
    if chunk_size is not None and (isinstance(chunk_size, bool) or not isinstance(chunk_size, int) or chunk_size < 1):
        raise UsageError(f"chunk_size must be an integer >= 1 (got {chunk_size!r})")
    if resume and out is None:
        raise UsageError("resume=True continues the sweep an output file holds: give out= (-o)")


def plan(model, d, names, t_end, scheduler, workers, options):
    """(job, settings, scheduler, workers, method note): the settings resolved once (argument >
    scene > default, one time grid for every run), method auto resolved once, the scheduler
    chosen (vectorized when one mapped integrator can run every run) or checked."""
    from ..simulation import formulate
    from ..simulation.settings import DEFAULT_POINTS
    from .runs import Job, default_threads

    settings = model.settings(t_end=t_end, **options)
    if settings.points is None:
        settings = settings.replace(points=DEFAULT_POINTS)     # one time grid for every run
    if settings.estimate_error:
        raise UsageError("estimate_error is not available in sweeps (run the runs of interest alone)")
    problem = formulate(model.eom, settings)
    job = Job(model=model, settings=settings, real=names.real, structural=names.structural, starts=names.starts,
              variables=(), grid=np.linspace(settings.t_start, settings.t_end, settings.points))
    method_note = None
    vector_why = _vectorizable(problem, names)
    if problem.kind == "ode" and settings.method == "auto" and not names.structural:
        # once for the sweep (the runs are prepared once and share the method, whatever the scheduler)
        settings, method_note = _resolve_auto(job, d, settings)
        job.settings = settings
        vector_why = _vectorizable(problem, names, settings.method)
    if scheduler is None:
        scheduler = "vectorized" if vector_why is None else "processes"
    elif scheduler == "vectorized" and vector_why is not None:
        raise UsageError(f"the vectorized scheduler cannot run this sweep: {vector_why}; use "
                         "scheduler='processes' (--scheduler processes) or 'dask'")
    job.vectorized = vector_why is None
    # threads of the mapped integrator only when asked (workers=): on the 2-core test machine
    # CasADi's thread map of the erk integrator used 1.8 cores for no gain in wall time
    # (benchmarks/sweep.py, docs/performance.md); processes do use both cores
    job.threads = (workers or 1) if scheduler == "vectorized" else 1
    workers = workers or default_threads()
    job.variables = _variables(model, problem)
    job.states = states_of(model, d, names)
    return job, settings, scheduler, workers, method_note


def chunk_size(n: int, scheduler: str, workers: int) -> int:
    """Runs per chunk: up to 256 in-process, else about four chunks per worker."""
    if scheduler == "vectorized":
        return max(1, min(256, n))
    return max(1, min(256, math.ceil(n / (4 * workers))))


def states_of(model, d, names) -> tuple[str, ...]:
    """Every state name of the sweep: Integer parameters may change the coordinates."""
    models = [model]
    if names.structural:
        combos = sorted({tuple(float(d.values[n][i]) for n in names.structural) for i in range(d.n)})
        for combo in combos:
            try:
                models.append(model.with_params(**{n: int(v) if v.is_integer() else v
                                                   for n, v in zip(names.structural, combo)}))
            except Exception:  # noqa: BLE001 - that run becomes an 'invalid run' row
                pass
    out: list[str] = []
    for m in models:
        for c in list(m.coordinates) + [f"der({c})" for c in m.coordinates]:
            if c not in out:
                out.append(c)
    return tuple(out)


def label(name: str, starts: dict) -> str:
    """The coordinate name of a swept value: parameters by name, start values as c.start / c.speed."""
    key = starts.get(name)
    if key is None:
        return name
    coord, speed = split_state(key)
    return f"{coord}.speed" if speed else f"{coord}.start"


def _vectorizable(problem, names, method: str | None = None) -> str | None:
    """None when one mapped integrator can run the sweep, else why not."""
    from ..simulation import registry as R

    if names.structural:
        return (f"{', '.join(names.structural)} is an Integer/Boolean parameter: it changes the model's "
                "structure, so the runs do not share one integrator")
    if getattr(problem.eom, "nu", 0):
        return "the model has inputs"
    if problem.kind != "ode":
        return {"dae": "the model has constraints (a DAE)", "hybrid": "the model has contacts (events)",
                "canonical": f"method {problem.settings.method} is a fixed-step canonical method"}[problem.kind]
    m = method or problem.settings.method
    if m != "auto" and R.spec(m).family not in ("casadi", "crk"):
        return f"method {m} is neither the stepping loop nor a CasADi integrator"
    if problem.settings.ode.functions is not None:
        return "the functions option replaces the model's Functions"
    if problem.settings.error_estimate != "off":
        return "each run carries an error estimate (error_estimate on): a companion run of its own"
    return None


def _resolve_auto(job, d, settings):
    """method=auto, once for the sweep: the method a single run at the first run's start would
    use (prepared as that run: the stepping loop where a single run takes it)."""
    from ..simulation import formulate
    from ..simulation.prepared import prepare
    from .runs import _prepare

    row = {k: float(v[0]) for k, v in d.values.items()}
    try:
        eom, s, _ = _prepare(job, row)
    except Exception:  # noqa: BLE001 - an invalid first run: decide at the model's own start
        eom, s = job.model.eom, settings.replace(p=job.model.parameter_values, x0=None)
        from ..eom.start import start_vector

        s = s.replace(x0=start_vector(eom, None, s.p))
    prep = prepare(formulate(eom, s))
    method = prep.method
    reason = (prep.setup.meta.get("method_reason") if prep.setup is not None else None) or "auto"
    return settings.replace(method=method), f"auto -> {method} (from the first run's start: {reason})"


def _variables(model, problem) -> tuple[str, ...]:
    """Recorded signals kept per run: the model's scalar outputs and the energy."""
    eom = model.eom
    names = []
    for name in problem.outputs:
        expr = (getattr(eom, "outputs", None) or {}).get(name)
        shape = getattr(expr, "shape", (1, 1))
        if tuple(shape) in ((1, 1), (1,), ()):
            names.append(name)
    return tuple(names) + ("energy",)
