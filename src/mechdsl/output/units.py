"""The unit of every column of a result (the CSV's sidecar, --json, plot axes, DataFrames):
light, so a run that writes no plot does not import the plotting module."""
from __future__ import annotations


def signal_units(result, model=None) -> dict[str, str]:
    """The unit of every column of a result ('' when unknown): coordinates and outputs from the
    model (``model`` or the Model that ran it) in the SI unit of their declaration (the values
    are SI), their rates per second, energies in J."""
    model = model if model is not None else getattr(result, "source_model", None)
    ir_model = getattr(model, "model", model)
    units: dict[str, str] = {"time": "s"}
    from ..numbers import si_unit      # (the common SI units without importing the unit parser)

    # the values are SI (a coordinate declared in "deg" is held in rad): label them so
    coords = {c.name: si_unit(c.unit) or "" for c in getattr(ir_model, "coordinates", ())}
    outputs = {o.name: si_unit(o.unit) or "" for o in getattr(ir_model, "outputs", ())}
    for c in result.coordinates:
        u = coords.get(c, "")
        units[c] = u
        units[f"der({c})"] = (f"({u})/s" if "/" in u else f"{u}/s") if u else ""
    recorded = (getattr(result, "metadata", None) or {}).get("units") or {}    # multipliers (issue 23)
    for name in result.signals:
        if name in ("energy", "kinetic_energy", "potential_energy") or name.endswith("_energy"):
            units[name] = "J"
        else:
            units[name] = outputs.get(name, "") or recorded.get(name, "")
    return units
