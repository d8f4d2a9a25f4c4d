"""What a sweep's files say about themselves (issue 27): each variable's unit and long name,
and the provenance: mechdsl's version, the model's name and hash, the settings, the design.

The same three hashes decide whether ``resume=True`` may continue a sweep from its output:
``model_hash`` (the model's source text, target, overrides, parameter values and scene
settings: what a worker rebuilds it from; not the file's name), ``settings_hash`` (the
resolved settings without the per-run p and x0) and ``design_hash`` (the swept names and
every run's values).
"""
from __future__ import annotations

import hashlib
import json

import numpy as np

STATUS_META = {     # status column -> (units, long name)
    "success": ("1", "the run reached the end time"),
    "failure_time": ("s", "time of the failure (NaN: none)"),
    "cause": ("", "cause of the failure"),
    "detail": ("", "detail of the failure"),
    "steps": ("1", "integrator steps (-1: not counted)"),
    "rhs_evals": ("1", "right-hand side evaluations (-1: not counted)"),
    "rejected_steps": ("1", "rejected steps (-1: not counted)"),
    "points": ("1", "output points recorded"),
    "cpu_time": ("s", "CPU time of the run"),
    "wall_time": ("s", "wall time of the run"),
    "energy_drift": ("J", "max |E - E(0)|"),
    "energy_drift_relative": ("1", "max |E - E(0)| / max(|E(0)|, scale)"),
}


def model_hash(model) -> str:
    """SHA-256 of what the Model is rebuilt from (Model.__reduce__), without the file's name."""
    text, _filename, units, target, overrides, values, settings = model.__reduce__()[1][0]
    return hashlib.sha256(repr((text, bool(units), tuple(target), _plain(overrides), tuple(values),
                                settings)).encode("utf-8")).hexdigest()


def _plain(x):
    if isinstance(x, dict):
        return tuple(sorted((str(k), _plain(v)) for k, v in x.items()))
    if isinstance(x, (list, tuple)):
        return tuple(_plain(v) for v in x)
    return x


def settings_text(settings) -> str:
    """The resolved settings as JSON (without the per-run p and x0), keys sorted."""
    d = settings.as_dict()
    d.pop("p", None)
    d.pop("x0", None)
    return json.dumps(d, sort_keys=True, default=lambda v: type(v).__name__)


def design_hash(labels: list[str], values: dict) -> str:
    h = hashlib.sha256()
    for name in labels:
        h.update(name.encode("utf-8") + b"\0")
        h.update(np.ascontiguousarray(np.asarray(values[name], np.float64)).tobytes())
    return h.hexdigest()


def identity(model, settings, labels, values) -> dict:
    """The attributes that name a sweep (stored in its files, compared by resume)."""
    from .. import __version__

    text = settings_text(settings)
    return {"generator": f"mechdsl {__version__}", "mechdsl_version": __version__, "model": model.name,
            "model_hash": model_hash(model),
            "settings": text, "settings_hash": hashlib.sha256(text.encode()).hexdigest(),
            "design_hash": design_hash(labels, values)}


def differences(old: dict, new: dict) -> list[str]:
    """What differs between two identities (model, settings, design), in words."""
    out = []
    if old.get("model_hash") != new["model_hash"]:
        out.append(f"the model ({old.get('model', '?')} then, {new['model']} now, or its text, parameter values "
                   "or scene changed)")
    if old.get("settings_hash") != new["settings_hash"]:
        try:
            a, b = json.loads(old.get("settings") or "{}"), json.loads(new["settings"])
            keys = sorted(k for k in set(a) | set(b) if a.get(k) != b.get(k))
            shown = ", ".join(f"{k}: {a.get(k)!r} then, {b.get(k)!r} now" for k in keys[:4])
        except ValueError:
            shown = ""
        out.append("the settings" + (f" ({shown})" if shown else ""))
    if old.get("design_hash") != new["design_hash"]:
        out.append("the design (the swept names or values)")
    return out


def variable_meta(model, states, variables, labels: dict, starts: dict) -> dict:
    """name -> {"units", "long_name"} for every variable and coordinate of the Dataset."""
    ir = model.model
    coords = {c.name: c for c in ir.coordinates}
    outputs = {o.name: o for o in ir.outputs}
    params = {p.name: p for p in ir.parameters}
    meta = {"run": {"units": "1", "long_name": "run index"}, "time": {"units": "s", "long_name": "time"}}
    for name in states:
        base = name[4:-1] if name.startswith("der(") else name
        c = coords.get(base)
        unit = (c.unit or "") if c is not None else ""
        doc = (getattr(c, "doc", "") or "") if c is not None else ""
        if name.startswith("der("):
            meta[name] = {"units": f"{unit}/s" if unit else "", "long_name": f"rate of {base}"
                          + (f" ({doc})" if doc else "")}
        else:
            meta[name] = {"units": unit, "long_name": doc or f"coordinate {name}"}
    for name in variables:
        if name == "energy":
            meta[name] = {"units": "J", "long_name": "total energy T + V"}
        else:
            o = outputs.get(name)
            meta[name] = {"units": (o.unit or "") if o is not None else "",
                          "long_name": ((getattr(o, "doc", "") or "") if o is not None else "") or f"output {name}"}
    for name, label in labels.items():
        key = starts.get(name)
        if key is None:
            p = params.get(name)
            meta[label] = {"units": (p.unit or "") if p is not None else "",
                           "long_name": ((getattr(p, "doc", "") or "") if p is not None else "")
                           or f"swept parameter {name}"}
        else:
            base = key[4:-1] if key.startswith("der(") else key
            c = coords.get(base)
            unit = (c.unit or "") if c is not None else ""
            if key.startswith("der("):
                meta[label] = {"units": f"{unit}/s" if unit else "", "long_name": f"start speed of {base}"}
            else:
                meta[label] = {"units": unit, "long_name": f"start value of {base}"}
    for name, (unit, long_name) in STATUS_META.items():
        meta[name] = {"units": unit, "long_name": long_name}
    return meta
