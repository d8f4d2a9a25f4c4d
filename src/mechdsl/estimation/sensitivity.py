"""``Model.sensitivities``: how the recorded motion depends on parameters and start values.

    S = m.sensitivities(5.0, params=["L", "g"], starts=["theta"])           forward, on the grid
    S["x", "L"]                      d x / d L over S.t, in m per m (declared units)
    S.to_xarray()                    one variable d(x)/d(L) per pair, its unit in attrs
    S = m.sensitivities(5.0, params=names, method="adjoint", outputs=["x"], times=[2.5, 5.0])
    S = m.sensitivities(5.0, params=names, method="adjoint", integral=["energy"])    d/dp of
                                     the integral of the energy over the run (a number per name)

One prepared problem, one Function (``Prepared.trajectory``: the run's integrator, options
and recorder), its derivatives CasADi's: ``forward(k)`` for k names at once (forward
sensitivities), ``reverse(m)`` for m chosen outputs and times or integrals (adjoint).  The
unknowns' directions through dependent parameters, start values written as expressions and
a constrained model's consistent initialization: ``unknowns.Unknowns.seeds``.
"""
from __future__ import annotations

import time
import types

import numpy as np

from ..diagnostics import Diagnostic, MechError, UsageError, did_you_mean
from ..eom import parameter_vector
from ..simulation.prepared import prepare
from .unknowns import unknowns

METHODS = ("forward", "adjoint")
CODE_CONTACTS = "E770"


class Sensitivities:
    """Derivatives of recorded signals with respect to parameters and start values.

    ``S[output, name]``: the derivative over ``S.t`` (an array; an integral's derivative under
    the adjoint method is one number), in the output's unit per the unknown's declared unit.
    ``S.values[output]``: the output itself; ``S.units[output, name]`` the unit of a derivative.
    """

    def __init__(self, model: str, t, outputs, names, data: dict, values: dict, units: dict,
                 output_units: dict, name_units: dict, method: str, metadata: dict):
        self.model, self.t, self.outputs, self.names = model, np.asarray(t, float), tuple(outputs), tuple(names)
        self._data, self.values, self.units = data, values, units
        self.output_units, self.name_units = output_units, name_units
        self.method, self.metadata = method, metadata

    def __getitem__(self, key):
        if not (isinstance(key, tuple) and len(key) == 2):
            raise KeyError("index a Sensitivities object by (output, name), e.g. S['x', 'L']")
        out, name = key
        if out not in self.outputs:
            hint = did_you_mean(str(out), self.outputs)
            raise KeyError(f"'{out}' is not an output of these sensitivities" + (f"; {hint}" if hint else
                           f" (outputs: {', '.join(self.outputs)})"))
        if name not in self.names:
            hint = did_you_mean(str(name), self.names)
            raise KeyError(f"'{name}' is not one of the names differentiated by" + (f"; {hint}" if hint else
                           f" (names: {', '.join(self.names)})"))
        return self._data[out, name]

    def __contains__(self, key) -> bool:
        return key in self._data

    def matrix(self, outputs=None) -> np.ndarray:
        """The sensitivity matrix: rows (output, time) output by output, one column per name."""
        outs = self.outputs if outputs is None else tuple(outputs)
        return np.column_stack([np.concatenate([np.atleast_1d(self[o, n]) for o in outs]) for n in self.names])

    def to_xarray(self):
        """An xarray Dataset: the outputs over ``time`` and one variable ``d(<output>)/d(<name>)``
        per pair, each with its unit in ``attrs["units"]`` (needs the 'table' extra)."""
        try:
            import xarray as xr
        except ImportError:
            raise UsageError("to_xarray needs xarray: pip install 'mechdsl[table]'") from None
        vars_ = {}
        for o in self.outputs:
            v = self.values[o]
            vars_[o] = (("time",) if np.ndim(v) else (), v, {"units": self.output_units[o]})
            for n in self.names:
                d = self._data[o, n]
                vars_[f"d({o})/d({n})"] = (("time",) if np.ndim(d) else (), d,
                                           {"units": self.units[o, n], "output": o, "name": n})
        return xr.Dataset(vars_, coords={"time": ("time", self.t, {"units": "s"})},
                          attrs={"model": self.model, "method": self.method, "generator": "mechdsl",
                                 "names": list(self.names), "name_units": [self.name_units[n] for n in self.names]})

    def to_dict(self) -> dict:
        return {"model": self.model, "method": self.method, "t": self.t.tolist(), "names": list(self.names),
                "name_units": dict(self.name_units), "outputs": list(self.outputs),
                "derivatives": {f"d({o})/d({n})": {"unit": self.units[o, n], "values": np.atleast_1d(d).tolist()}
                                for (o, n), d in self._data.items()}, "metadata": self.metadata}

    def __repr__(self) -> str:
        return (f"<Sensitivities of {self.model} ({self.method}): {len(self.outputs)} output(s) x "
                f"{len(self.names)} name(s) ({', '.join(self.names)}) on {self.t.size} time(s)>")


def per(a: str, b: str) -> str:
    """The unit a / b as text: ``per("m", "kg")`` = "m/kg", ``per("rad", "m/s2")`` = "rad/(m/s2)"."""
    a, b = a or "", b or ""
    if not b:
        return a or "1"
    wrap = f"({b})" if any(c in b for c in "/.*") else b
    return f"{a or '1'}/{wrap}"


def signal_units(model, names) -> dict[str, str]:
    """The unit of each recorded signal, as a Result labels it (output.plot.signal_units)."""
    from ..output.plot import signal_units as units_of

    coords = tuple(model.coordinates)
    states = set(coords) | {f"der({c})" for c in coords}
    fake = types.SimpleNamespace(coordinates=coords, signals={n: None for n in names if n not in states})
    return units_of(fake, model)


def check_kind(model, problem) -> None:
    """Sensitivities exist for ODE and constrained runs: contacts are refused at the contact
    (E770), the fixed-step canonical methods by name."""
    if problem.kind == "hybrid":
        contacts = getattr(model.model, "contacts", ()) or ()
        span = contacts[0].span if contacts else model.model.span
        raise MechError(Diagnostic(
            CODE_CONTACTS, f"sensitivities of {model.name}: its contact"
            + (f" '{contacts[0].name}'" if contacts else "s") + " make the motion jump at impacts, and the "
            "jump of the derivatives there (the saltation at events) is not computed", span=span,
            help="differentiate a stretch of motion between impacts (a model or scene without the contact), "
                 "or compare runs at nearby values with Model.sweep (finite differences)"))
    if problem.kind == "canonical":
        raise UsageError(f"method '{problem.settings.method}' is a fixed-step method in canonical variables, which "
                         "has no CasADi integrator: sensitivities need one of cvodes-bdf, cvodes-adams, idas, erk, "
                         "rosenbrock, rk (classical RK4 with fixed steps), collocation, or auto")


def _method(method: str) -> str:
    if method not in METHODS:
        hint = did_you_mean(str(method), METHODS)
        raise UsageError(f"method must be 'forward' or 'adjoint' (got {method!r})" + (f"; {hint}" if hint else ""))
    return method


def sensitivities(model, t_end=None, params=(), starts=(), outputs=None, method="forward", points=None,
                  times=None, integral=None, settings=None) -> Sensitivities:
    """See ``Model.sensitivities`` (``settings``: the run's, ``method`` there the integrator's)."""
    settings = dict(settings or {})
    method = _method(method)
    cpu0 = time.process_time()
    if "compiled" in settings and settings["compiled"]:
        raise UsageError("compiled = true: sensitivities differentiate the run's Functions in CasADi's virtual "
                         "machine (leave compiled unset)")
    settings["compiled"] = False
    integral = [integral] if isinstance(integral, str) else list(integral or ())
    if method == "forward" and times is not None:
        raise UsageError("times= chooses the times of the adjoint method; the forward method gives every point of "
                         "the output grid (points=)")
    problem = model.problem(t_end=t_end, points=points, **settings)
    check_kind(model, problem)
    eom = problem.eom
    unk = unknowns(model, eom, params, starts)
    prep = prepare(problem)
    if method == "adjoint":
        asked = [problem.settings.t_end] if times is None else times
        tr = prep.trajectory(times=np.r_[np.atleast_1d(np.asarray(asked, float)),
                                         [problem.settings.t_end] if integral else []], integrals=integral)
    else:
        tr = prep.trajectory(integrals=integral)
    names = _outputs(tr, outputs, integral, method)
    pv = parameter_vector(eom, problem.settings.p)
    x, dx_dp, dx_dx = tr.start(pv, unk.start_overrides(eom, problem.settings.x0,
                                                        unk.values(pv, tr.start(pv)[0])))
    DX, DP = unk.seeds(eom, pv, dx_dp, dx_dx)
    f = unk.factors
    data, values = {}, {}
    if method == "forward":
        Y, Q, dY, dQ = tr.forward(x, pv, DX, DP)
        t = tr.times
        for o in names:
            row, src, dsrc = _where(tr, o, Y, Q, dY, dQ)
            values[o] = src[row]
            for j, n in enumerate(unk.names):
                data[o, n] = dsrc[j, row] * f[j]
    else:
        req = np.atleast_1d(np.asarray(asked, float))
        cols = [int(np.argmin(np.abs(tr.times - v))) for v in req]
        t = tr.times[cols]
        pairs = [(o, c) for o in names if not o.startswith("integral(") for c in cols]
        ints = [o for o in names if o.startswith("integral(")]
        Y, Q = tr.evaluate(x, pv)
        sy = np.zeros((len(pairs) + len(ints),) + Y.shape)
        sq = None if Q is None else np.zeros((len(pairs) + len(ints),) + Q.shape)
        for r, (o, c) in enumerate(pairs):
            sy[r, tr.names.index(o), c] = 1.0
        for r, o in enumerate(ints, start=len(pairs)):
            sq[r, tr.integrals.index(o[len("integral("):-1]), -1] = 1.0
        ax, ap, Y, Q = tr.reverse(x, pv, sy, sq, nominal=(Y, Q))
        G = (ax @ DX + ap @ DP) * f[None, :]
        for o in names:
            if o.startswith("integral("):
                r = len(pairs) + ints.index(o)
                values[o] = float(Q[tr.integrals.index(o[len("integral("):-1]), -1])
                for j, n in enumerate(unk.names):
                    data[o, n] = float(G[r, j])
            else:
                rows = [r for r, (oo, _) in enumerate(pairs) if oo == o]
                values[o] = Y[tr.names.index(o), cols]
                for j, n in enumerate(unk.names):
                    data[o, n] = G[rows, j]
    ounits = signal_units(model, tr.names)
    out_units = {o: _unit_of(o, ounits) for o in names}
    name_units = {u.name: u.unit for u in unk.items}
    units = {(o, n): per(out_units[o], name_units[n]) for o in names for n in unk.names}
    meta = {"integration": tr.describe(), "cpu_time": time.process_time() - cpu0, "t_start": problem.settings.t_start,
            "t_end": problem.settings.t_end, "parameters": dict(zip(eom.params, map(float, pv))),
            "start": dict(zip(list(eom.coords) + [f"der({c})" for c in eom.coords], map(float, x)))}
    return Sensitivities(model.name, t, names, unk.names, data, values, units, out_units, name_units, method, meta)


def _unit_of(o: str, units: dict) -> str:
    if o.startswith("integral("):
        inner = units.get(o[len("integral("):-1], "")
        return f"{inner}.s" if inner else "s"
    return units.get(o, "")


def _outputs(tr, outputs, integral, method) -> list[str]:
    ints = [f"integral({k})" for k in integral]
    if outputs is None:
        return ints if (method == "adjoint" and integral) else list(tr.names) + ints
    outputs = [outputs] if isinstance(outputs, str) else list(outputs)
    for o in outputs:
        if o not in tr.names:
            hint = did_you_mean(str(o), tr.names)
            raise UsageError(f"outputs: '{o}' is not a recorded signal of {tr.eom.name}" + (f"; {hint}" if hint else
                             f" (signals: {', '.join(tr.names)})"))
    return list(dict.fromkeys(outputs)) + ints


def _where(tr, o, Y, Q, dY, dQ):
    if o.startswith("integral("):
        return tr.integrals.index(o[len("integral("):-1]), Q, dQ
    i = tr.names.index(o)
    return i, Y, dY
