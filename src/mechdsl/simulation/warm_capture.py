"""What a prepared warm run of ``mech simulate`` is made of (warm_run.py), taken from a run
that just ran the normal way: the compiled stepping loop's calls (the run's and the error
estimate companion's), the recorder's program and the Result's metadata that no number of
the run decides.  Anything else (another back end, inputs, events, a failure, a warning, a
first-integral search that found nothing to name...) makes no prepared run: the next run
goes the normal way."""
from __future__ import annotations

from .backends.ode import OdeSetup, peek_setup, plain_copy
from .estimate import companion

NUMBERS = ("accuracy", "source", "target", "scene")    # metadata a run's numbers (or the command) decide
MAX_CPU = 0.5     # CPU seconds: longer runs are not prepared (a warm start does not matter there, and a
#                   prepared run stops at Ctrl-C without writing what it reached)


def payload(prepared, r, units) -> tuple[dict | None, str]:
    """(the prepared run's plain data, "") or (None, why not) for the Result ``r`` of the
    Prepared problem ``prepared`` (Model.prepared_run); ``units``: the declared unit of each
    coordinate and output by name (the columns' units are computed again from them)."""
    if prepared is None:
        return None, "no prepared problem kept"
    problem, setup = prepared.problem, prepared.setup
    m = r.metadata
    if problem.kind != "ode" or not isinstance(setup, OdeSetup) or problem.drive is not None:
        return None, "not an ODE run without inputs"
    if (r.failure is not None or r.events or m.get("warnings") or m.get("singularity") or m.get("interrupted")
            or m.get("integrator_messages") or m.get("fixed_steps") or m.get("friction") or m.get("aliases")):
        return None, "the run has a failure, events, warnings or reports a prepared run does not make"
    if (r.stats.get("cpu_time") or 0.0) + (r.stats.get("error_estimate_cpu_time") or 0.0) > MAX_CPU:
        return None, "a long run"
    s = problem.settings
    if s.estimate_error:
        return None, "estimate_error runs a second full run"
    pv, xs = setup.start_of(s)
    call = setup.loop_call(pv, xs)
    rec = setup.recorder_program(pv)
    if call is None or rec is None:
        return None, "not one call of the compiled stepping loop"
    rec["runtime"] = call["loop"]["runtime"]
    if list(r.signals) != rec["names"]:
        return None, "the recorded columns are not the recorder's"
    acc = m.get("accuracy") or {}
    comp = None
    if acc.get("error_estimate") is not None:
        tight, factor, how = companion(problem, r)
        other = None if tight is None else peek_setup(problem.eom, tight)
        if other is None or how != acc.get("error_estimate_method"):
            return None, "the companion run's setup is not kept"
        comp = other.loop_call(*other.start_of(tight))
        if comp is None:
            return None, "the companion is not one call of the compiled stepping loop"
        comp.update(factor=factor, how=how)
    elif s.error_estimate != "off":
        return None, "no error estimate"
    meta = {k: plain_copy(v) for k, v in m.items() if k not in NUMBERS}
    if call["loop"]["engine"] == "compiled":      # what a warm run says of its library
        prefix = f"{m['method']} compiled stepping loop: "
        meta["notes"] = [prefix + f"loaded compiled model from cache {call['loop']['library']}"
                         if n.startswith(prefix) else n for n in meta.get("notes", [])]
    return {"run": call, "companion": comp, "recorder": rec, "metadata": meta, "settings": s,
            "invariants": tuple(problem.invariants), "coordinates": list(r.coordinates), "units": units,
            "estimate_off": None if comp is not None else {k: acc.get(k) for k in
                                                           ("error_estimate", "error_estimate_unavailable")}}, ""
