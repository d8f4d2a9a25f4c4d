"""The linear model of a run about a state: ``Linearization`` (M, C, K, A, B, modes, LQR,
JSON), and its input columns (``declared_inputs``, ``input_columns``), shared by the
unconstrained linearization (linearize.py) and the reduced one on the constraint manifold
(reduced.py)."""
from __future__ import annotations

import json
import re
from dataclasses import dataclass, field

import numpy as np

from ..diagnostics import Diagnostic, MechError, UsageError, did_you_mean
from ..model.units import coordinate_units, matrix_units
from ..output import display as _display
from .core import dense, named_multipliers, parts
from .lqr import lqr
from .matrices import skew, sym
from .modes import Modes, modes_of
from .symbolic import symbolic_linearization


@dataclass
class Linearization:
    coords: tuple[str, ...]
    M: np.ndarray
    C: np.ndarray
    K: np.ndarray
    A: np.ndarray
    B: np.ndarray                    # (2n, m) first-order input matrix
    Bq: np.ndarray                   # (n, m): M dq'' + C dq' + K dq = Bq du
    inputs: tuple[str, ...]
    q: np.ndarray                    # reference state
    qd: np.ndarray
    t: float
    acceleration: np.ndarray         # reference acceleration (0 at an equilibrium)
    kind: str                        # 'equilibrium' | 'accelerated-reference' | 'state'
    p: np.ndarray
    equilibrium: object | None = None
    notes: list[str] = field(default_factory=list)
    eom: object | None = field(default=None, repr=False)
    _modes: Modes | None = field(default=None, repr=False)
    # constrained models (see analysis.reduced): M, C, K, A, B are those of the reduced model in
    # the coordinates ``reduced_coords`` (dq = basis dz); multipliers at the reference state for
    # every constraint (0 for dropped redundant ones); stiffness: the full n x n K including the
    # geometric stiffness sum lambda_l d2g_l/dq2, before the reduction
    basis: np.ndarray | None = None
    reduced_coords: tuple[str, ...] = ()
    multipliers: np.ndarray | None = None
    constraint_names: tuple[str, ...] = ()
    active_constraints: tuple[str, ...] = ()
    # the unit of each multiplier (eom.multiplier_units: N, N.m, N/m, ...; None: unknown)
    multiplier_units: tuple = ()
    stiffness: np.ndarray | None = None

    _repr_html_ = _display.linearization_html        # notebook displays (mechdsl.output.display)
    _repr_markdown_ = _display.linearization_markdown

    def __repr__(self) -> str:
        """One line: about what, how many coordinates, the modes' frequencies (the HTML display
        and ``to_dict()`` hold the matrices)."""
        where = {"equilibrium": "about the equilibrium", "accelerated-reference": "about the accelerated reference",
                 "state": f"about the state at t = {self.t:g}"}.get(self.kind, self.kind)
        n = len(self.matrix_coords)
        md = self.modes()
        w = ", ".join(f"{v:.6g}" for v in md.frequencies[:4]) + (", ..." if len(md.frequencies) > 4 else "")
        return (f"<Linearization {where}: {n} coordinate{'' if n == 1 else 's'}, "
                f"{len(md)} mode{'' if len(md) == 1 else 's'}" + (f", w = {w} rad/s" if w else "") + ">")

    @property
    def constrained(self) -> bool:
        """True for a constrained model: M, C, K are then those of the reduced coordinates."""
        return self.basis is not None

    @property
    def matrix_coords(self) -> tuple[str, ...]:
        """Names of the rows and columns of M, C, K (the reduced coordinates when constrained)."""
        return self.reduced_coords if self.constrained else self.coords

    @property
    def lambdas(self) -> dict[str, float]:
        """The constraint multipliers at the reference state, by constraint name ({} if none), each in
        its unit (``lambda_units``)."""
        return named_multipliers(self.constraint_names, self.multipliers)

    @property
    def lambda_units(self) -> dict[str, str | None]:
        """The unit of each multiplier, by constraint name."""
        return dict(zip(self.constraint_names, self.multiplier_units))

    @property
    def n(self) -> int:
        """The number of coordinates."""
        return len(self.coords)

    @property
    def D(self) -> np.ndarray:
        """Damping: the symmetric part of C."""
        return sym(self.C)

    @property
    def G(self) -> np.ndarray:
        """Gyroscopic matrix: the skew-symmetric part of C."""
        return skew(self.C)

    @property
    def values(self) -> dict[str, float]:
        """The coordinates' values at the reference state, by name."""
        return {c: float(v) for c, v in zip(self.coords, self.q)}

    def modes(self) -> Modes:
        """The modes (mechdsl.analysis.modes.Modes): frequencies [rad/s], ``hz``, damping
        ratios, shapes (in the original coordinates) and kinds, slowest first."""
        if self._modes is None:
            md = modes_of(self.M, self.C, self.K, self.A, self.matrix_coords)
            self._modes = md.in_coordinates(self.basis, self.coords) if self.constrained else md
        return self._modes

    @property
    def eigenvalues(self) -> np.ndarray:
        """The eigenvalues of the first-order system matrix A [1/s]."""
        return self.modes().eigenvalues

    def lqr(self, Q, R):
        """The LQR state feedback du = -K dx for this linear model (analysis.lqr)."""
        return lqr(self, Q, R)

    def symbolic(self, exact: bool = True):
        """M, C, K derived by sympy from T, V, D, Q at this state (see analysis.symbolic)."""
        if self.constrained:
            raise MechError(Diagnostic("E901", "the symbolic linearization is available for models in "
                                               "independent coordinates only; the numeric M, C, K of the "
                                               "reduced model are exact to rounding"))

        return symbolic_linearization(self.eom, self.q, self.qd, self.t, self.acceleration,
                                      inputs=self.inputs, exact=exact)

    def to_dict(self) -> dict:
        """Plain JSON types: coordinates, state, M, C, K, A, B, modes, eigenvalues, notes, ..."""
        md = self.modes().to_dict()
        return {"coordinates": list(self.coords), "kind": self.kind, "t": self.t,
                "state": {"q": self.values, "qd": {c: float(v) for c, v in zip(self.coords, self.qd)}},
                "acceleration": {c: float(v) for c, v in zip(self.coords, self.acceleration)},
                "inputs": list(self.inputs), "M": self.M.tolist(), "C": self.C.tolist(), "K": self.K.tolist(),
                "A": self.A.tolist(), "B": self.B.tolist(), "modes": md["modes"],
                "eigenvalues": md["eigenvalues"], "notes": list(self.notes),
                "equilibrium": None if self.equilibrium is None else self.equilibrium.to_dict(),
                **self._units_dict(), **self._constrained_dict()}

    def _units_dict(self) -> dict:
        """``units``: each coordinate's SI unit ('' unknown); ``matrix_units``: those of M, C, K
        when the matrices' coordinates share one unit ({} otherwise: each entry has its own)."""
        units = dict(zip(self.eom.coords, coordinate_units(self.eom))) if self.eom is not None else {}
        return {"units": {c: units.get(c, "") for c in self.coords},
                "matrix_units": matrix_units([units.get(c, "") for c in self.matrix_coords])}

    def _constrained_dict(self) -> dict:
        if not self.constrained:
            return {}
        return {"reduced_coordinates": list(self.reduced_coords),
                "basis": [{c: float(v) for c, v in zip(self.coords, col)} for col in self.basis.T],
                "multipliers": self.lambdas, "multiplier_units": self.lambda_units, "active_constraints": list(self.active_constraints),
                "stiffness_full": self.stiffness.tolist()}

    def to_json(self) -> str:
        """``to_dict()`` as JSON text (what ``mech linearize -o OUT.json`` writes)."""
        return json.dumps({"generator": "mechdsl", **self.to_dict()}, indent=2) + "\n"


def declared_inputs(eom) -> list[str]:
    """The parameters declared `input` in the model (empty without a model)."""
    model = getattr(eom, "model", None)
    if model is None:
        return []
    return [p.name for p in model.inputs if p.name in eom.params]


def input_columns(eom, inputs, q, qd, t, pv):
    """(names, Bq): the columns of the input matrix, M dq'' + C dq' + K dq = Bq du, for inputs that
    are parameters (d bias / dp) or generalized forces on coordinates (``force(q)``)."""
    n = eom.n
    if not inputs:
        return (), np.zeros((n, 0))
    if isinstance(inputs, str):
        inputs = [s for s in re.split(r"[,\s]+", inputs) if s]
    cols, names = [], []
    dbp = None
    for name in inputs:
        m = re.fullmatch(r"\s*(?:force|Q)\((.+)\)\s*", name)
        key = m.group(1) if m else name.strip()
        if key in eom.coords and (m or key not in eom.params):
            e = np.zeros(n)
            e[eom.coords.index(key)] = 1.0
            cols.append(e)
            names.append(f"force({key})")
        elif key in eom.params and not m:
            if dbp is None:
                dbp = dense(parts(eom).fn("dbias_dp")(q, qd, t, pv))
            cols.append(dbp[:, eom.params.index(key)])
            names.append(key)
        else:
            hint = did_you_mean(key, list(eom.params) + list(eom.coords))
            raise UsageError(f"unknown input {name!r}: inputs are parameters or coordinates "
                             "(a generalized force on them)" + (f"; {hint}" if hint else ""))
    return tuple(names), np.array(cols).T
