"""Sensitivities and parameter estimation (issue 28): ``Model.sensitivities``, ``Model.fit``.

    sensitivity.py   Sensitivities: forward and adjoint derivatives of recorded signals
    unknowns.py      the names varied (parameters, start values), their units and directions
    data.py          measured data: tables, DataFrames, CSV files; experiments
    fit.py           least squares: Gauss-Newton / Levenberg-Marquardt with exact sensitivities
    identify.py      identifiability: the combinations the data cannot determine

Built on the simulation layer's one prepared problem (``Prepared.trajectory``).  The face
imports its modules on first use.
"""
from __future__ import annotations


def __getattr__(name):
    if name in ("Sensitivities", "sensitivities"):
        from . import sensitivity

        return getattr(sensitivity, name)
    if name in ("FitResult", "fit"):
        from . import fit

        return getattr(fit, name)
    raise AttributeError(name)
