"""The records of an equilibrium search (analysis.equilibrium): one :class:`Equilibrium` with its
classification, the :class:`Search` that says how the search went, and :class:`Equilibria`, the list
of both."""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from ..output import display as _display
from .core import named_multipliers


@dataclass
class Equilibrium:
    """One equilibrium: coordinate values, kind, stability and the eigenvalues that decide it.

    kind: 'static' (scleronomic), 'relative' (steady moving frame, V_eff = V - T0),
    'accelerated-reference' (relative equilibrium about a uniformly accelerated motion whose
    acceleration is ``acceleration``).
    ``hessian_eigenvalues``: eigenvalues of the stiffness K (Hessian of the effective potential)
    transverse to the symmetry directions (``symmetry_directions``), ascending.  Constrained
    models: K is the Hessian of V + lambda'g and the eigenvalues are those of its restriction
    to the tangent space of the constraints (``tangent_basis``); ``multipliers`` / ``lambdas``
    are the constraint forces at rest.
    """

    coords: tuple[str, ...]
    q: np.ndarray
    stable: bool | None
    hessian_eigenvalues: np.ndarray
    kind: str = "static"
    residual: float = 0.0
    reason: str = ""
    hessian: np.ndarray | None = None
    acceleration: np.ndarray | None = None
    linear_eigenvalues: np.ndarray | None = None
    symmetry_directions: np.ndarray | None = None
    t: float = 0.0
    notes: list[str] = field(default_factory=list)
    # constrained models: multipliers of every constraint (0 for dropped redundant ones), the
    # constraints that were kept, and the orthonormal basis Z of the tangent space the
    # classification used (hessian_eigenvalues are those of Z'(K + sum lambda_l d2g_l/dq2)Z)
    multipliers: np.ndarray | None = None
    constraint_names: tuple[str, ...] = ()
    active_constraints: tuple[str, ...] = ()
    # the unit of each multiplier (eom.multiplier_units: N, N.m, N/m, ...; None: unknown)
    multiplier_units: tuple = ()
    tangent_basis: np.ndarray | None = None
    admissible: bool = True          # False: the state penetrates one of the model's contacts (notes)
    # rotation joints: the classification was made in a chart (analysis.charts) whose
    # coordinates are these; hessian, symmetry_directions and the eigenvalues refer to them
    chart_coords: tuple[str, ...] = ()

    @property
    def lambdas(self) -> dict[str, float]:
        """Multipliers by constraint name (empty for unconstrained models), unscaled, each in its
        unit (``multiplier_units``; docs/constraints.md)."""
        return named_multipliers(self.constraint_names, self.multipliers)

    @property
    def lambda_units(self) -> dict[str, str | None]:
        """The unit of each multiplier, by constraint name."""
        return dict(zip(self.constraint_names, self.multiplier_units))

    @property
    def values(self) -> dict[str, float]:
        """The coordinates' values at the equilibrium, by name."""
        return {c: float(v) for c, v in zip(self.coords, self.q)}

    _repr_html_ = _display.equilibrium_html          # notebook displays (mechdsl.output.display)
    _repr_markdown_ = _display.equilibrium_markdown

    def __repr__(self) -> str:
        """One line: kind, stability and where (the HTML display and ``to_dict()`` hold the rest)."""
        where = ", ".join(f"{c} = {v:.6g}" for c, v in list(self.values.items())[:6])
        more = f", ... ({len(self.coords) - 6} more)" if len(self.coords) > 6 else ""
        return f"<Equilibrium {self.kind}, {self.stability}: {where}{more}>"

    @property
    def stability(self) -> str:
        """"stable", "unstable" or "undetermined" (``stable`` True, False or None; ``reason`` says why)."""
        return {True: "stable", False: "unstable", None: "undetermined"}[self.stable]

    def __getitem__(self, name: str) -> float:
        return self.values[name]

    def to_dict(self) -> dict:
        """Plain JSON types: kind, values, stability and reason, eigenvalues, Hessian, notes, ..."""
        d = {"kind": self.kind, "values": self.values, "stable": self.stable, "admissible": self.admissible,
             "stability": self.stability, "reason": self.reason,
             "hessian_eigenvalues": [float(v) for v in self.hessian_eigenvalues],
             "residual": float(self.residual), "t": float(self.t), "notes": list(self.notes)}
        if self.hessian is not None:
            d["hessian"] = self.hessian.tolist()
        if self.acceleration is not None:
            d["acceleration"] = {c: float(v) for c, v in zip(self.coords, self.acceleration)}
        if self.linear_eigenvalues is not None:
            d["linear_eigenvalues"] = [[float(v.real), float(v.imag)] for v in self.linear_eigenvalues]
        if self.symmetry_directions is not None and self.symmetry_directions.size:
            d["symmetry_directions"] = [{c: float(v) for c, v in zip(self.chart_coords or self.coords, col)}
                                        for col in self.symmetry_directions.T]
        if self.chart_coords:
            d["chart_coordinates"] = list(self.chart_coords)
        if self.multipliers is not None:
            d["multipliers"] = self.lambdas
            d["multiplier_units"] = self.lambda_units
            d["active_constraints"] = list(self.active_constraints)
            d["tangent_basis"] = [{c: float(v) for c, v in zip(self.coords, col)} for col in self.tangent_basis.T]
        return d


@dataclass
class Search:
    """How the search went, for saying why nothing was found: starting guesses tried, how many
    converged, the smallest force at rest reached (relative to the force scale) and where, and
    how many runs ran off to coordinates far beyond their start (a force that decays without
    vanishing, as a central attraction's)."""

    guesses: int = 0
    converged: int = 0
    best_residual: float = math.inf
    best_q: np.ndarray | None = None
    runaway: int = 0

    def why_none(self, coords) -> str:
        """The reason no equilibrium was found, in words (empty when nothing is known)."""
        if not self.guesses:
            return ""
        out = f"none of {self.guesses} starting guesses converged"
        if self.best_q is not None and math.isfinite(self.best_residual):
            where = ", ".join(f"{c} = {v:.4g}" for c, v in zip(coords, self.best_q))
            out += (f"; the smallest force at rest reached was {self.best_residual:.3g} of the force "
                    f"scale (at {where})")
        if self.runaway:
            out += (f"; {self.runaway} of the searches ran off to coordinates more than {RUNAWAY:g} times "
                    "farther out than their start: the force at rest decays without vanishing, so the model "
                    "has no static equilibrium (a central attraction, e.g. the Kepler problem, has none: "
                    "bodies released at rest fall towards each other)")
        return out


class Equilibria(list):
    """The equilibria found (a list of :class:`Equilibrium`) with ``search``, a :class:`Search`, and
    ``notes`` on the search as a whole (contacts that are not equilibrium conditions)."""

    search: Search
    notes: list


def equilibria_result(eqs, search: Search, notes=()) -> Equilibria:
    """The list of equilibria with its search and notes."""
    out = Equilibria(eqs)
    out.search = search
    out.notes = list(notes)
    return out


RUNAWAY = 10.0           # a failed run that ends this many times farther out than its start ran away

