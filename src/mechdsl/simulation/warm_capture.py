"""What a prepared warm run of ``mech simulate`` is made of (warm_run.py), taken from a run
that just ran the normal way: the compiled stepping loop's calls (the run's and the error
estimate companion's), the recorder's program and the Result's metadata that no number of
the run decides.  Anything else (another back end, inputs, events, a failure, a warning, a
first-integral search that found nothing to name...) makes no prepared run: the next run
goes the normal way."""
from __future__ import annotations

from array import array
from types import SimpleNamespace

from ..eom import vmprog

from .backends import payback
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
    _count_evaluations(call, setup)
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
        _count_evaluations(comp, other)
    elif s.error_estimate != "off":
        return None, "no error estimate"
    meta = {k: plain(plain_copy(v)) for k, v in m.items() if k not in NUMBERS}
    if call["loop"]["engine"] == "compiled":      # what a warm run says of its library
        prefix = f"{m['method']} compiled stepping loop: "
        meta["notes"] = [prefix + f"loaded compiled model from cache {call['loop']['library']}"
                         if n.startswith(prefix) else n for n in meta.get("notes", [])]
    return {"run": _plain_call(call), "companion": comp and _plain_call(comp), "recorder": _plain_recorder(rec),
            "metadata": meta, "settings": _settings(s),
            "invariants": tuple(problem.invariants), "coordinates": list(r.coordinates), "units": units,
            "estimate_off": None if comp is not None else {k: plain(acc.get(k)) for k in
                                                           ("error_estimate", "error_estimate_unavailable")}}, ""


# --------------------------------------------------------------------------- plain data
# A prepared run holds no numpy value (warm_run reads it without importing numpy; a payload that
# asks for numpy is refused there): arrays as array.array, numbers as Python's.

def plain(x):
    """``x`` with numpy arrays and scalars (in dicts, lists and tuples) as lists and Python
    numbers: what the JSON sidecar and the summary make of them anyway."""
    import numpy as np

    if type(x) is dict:
        return {k: plain(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return type(x)(plain(v) for v in x) if type(x) in (list, tuple) else x
    if isinstance(x, np.ndarray):
        return plain(x.tolist())
    if isinstance(x, np.bool_):
        return bool(x)
    if isinstance(x, np.integer):
        return int(x)
    if isinstance(x, np.floating):
        return float(x)
    return x


def _doubles(v) -> array:
    import numpy as np

    return vmprog.plain(np.ascontiguousarray(np.ravel(v), float), "d")


def _number(v):
    return v if type(v) in (int, float) else float(v)


def _count_evaluations(call: dict, setup) -> None:
    """An interpreted loop call goes on counting its evaluations towards its compile (payback.py):
    where (the count's file) and up to what, for warm_run."""
    if call["loop"]["engine"] == "interpreted":
        ode = setup.funcs.loop_ode
        call["payback"] = {"path": str(payback.count_path(ode)), "limit": int(payback.threshold(ode))}


def _plain_call(c: dict) -> dict:
    """A loop call (OdeSetup.loop_call) as plain data."""
    return {**c, "grid": _doubles(c["grid"]), "x0": _doubles(c["x0"]), "p": _doubles(c["p"]),
            "u": None if c["u"] is None else _doubles(c["u"]), "rtol": _number(c["rtol"]),
            "atol": _number(c["atol"]), "max_steps": int(c["max_steps"]), "hmin": float(c["hmin"]), "n": int(c["n"]),
            **({"factor": _number(c["factor"])} if "factor" in c else {})}


def _plain_recorder(rec: dict) -> dict:
    return {**rec, "nnz_in": [int(k) for k in rec["nnz_in"]], "nout": int(rec["nout"]), "dense": int(rec["dense"]),
            "where": None if rec["where"] is None else [int(k) for k in rec["where"]],
            "sizes": tuple(int(k) for k in rec["sizes"]), "integrals": list(rec["integrals"])}


def _settings(s) -> SimpleNamespace:
    """What the replay's accuracy report, warning and estimate read of the settings."""
    return SimpleNamespace(rtol=_number(s.rtol), atol=_number(s.atol), t_start=_number(s.t_start),
                           t_end=_number(s.t_end), error_estimate=s.error_estimate,
                           dt=None if s.dt is None else _number(s.dt))
