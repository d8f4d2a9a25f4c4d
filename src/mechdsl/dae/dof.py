"""Degrees of freedom, constraint rank, redundant constraints and partitions.

Rank decisions use the *scaled* constraint Jacobian S G D (``system.scale_jacobian``:
coordinates weighted by the mass metric, each constraint row normalized), so they do not
depend on units or on how a constraint happens to be written (metres or millimetres).

An independent subset of the constraints is chosen by a QR factorization of (S G D)^T
with column pivoting (LAPACK geqp3: deterministic for the same input; ties go to the
earlier constraint); the chosen rows are returned in their original order.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..eom import EOM
from .constrained_system import scale_jacobian


RANK_TOL = 1e-9   # singular values below RANK_TOL * largest count as zero (redundancy)


@dataclass
class DofReport:
    coordinates: int
    constraints: int
    rank: int
    dof: int
    redundant: int
    redundant_names: tuple[str, ...] = ()
    independent: tuple[int, ...] = ()          # indices of a maximal independent subset
    singular_values: tuple[float, ...] = ()    # of the scaled Jacobian, descending
    t: float = 0.0
    vanishing: tuple[str, ...] = ()            # redundant ones whose gradient is zero here

    @property
    def predicted_dof(self) -> int:
        """The count a joint/constraint census predicts (coordinates - constraints)."""
        return self.coordinates - self.constraints

    def lines(self) -> list[str]:
        """Human-readable lines for ``mech check``."""
        out = [f"coordinates: {self.coordinates}",
               f"constraints: {self.constraints} (rank {self.rank} at t = {self.t:g})",
               f"degrees of freedom: {self.dof}"]
        if self.redundant:
            out.append(f"redundant constraints: {self.redundant} ({short_list(self.redundant_names)}); "
                       f"the count {self.coordinates} - {self.constraints} = {self.predicted_dof} "
                       f"predicts {self.predicted_dof} degrees of freedom, the rank gives {self.dof}; "
                       "the redundant ones are dropped during simulation")
            if self.vanishing:
                out.append(f"  of these, {short_list(self.vanishing)} have a zero gradient (satisfied whatever the "
                           "coordinates do nearby, e.g. the out-of-plane conditions of a planar loop)")
        if self.dof < 0:
            out.append("over-constrained: more independent constraints than coordinates")
        return out

    def as_dict(self) -> dict:
        return {"coordinates": self.coordinates, "constraints": self.constraints, "rank": self.rank,
                "dof": self.dof, "redundant": self.redundant, "redundant_names": list(self.redundant_names),
                "independent": list(self.independent), "t": self.t, "vanishing": list(self.vanishing),
                "min_singular_ratio": (self.singular_values[self.rank - 1] / self.singular_values[0]
                                       if self.rank and self.singular_values[0] > 0 else None)}


def short_list(names, limit: int = 8) -> str:
    """'a, b, c' or 'a, b, ..., z (120 in all)' for long lists in messages."""
    names = list(names)
    if len(names) <= limit:
        return ", ".join(names)
    return ", ".join(names[:limit - 2]) + f", ..., {names[-1]} ({len(names)} in all)"


def numeric_rank(Gs: np.ndarray, tol: float = RANK_TOL) -> tuple[int, np.ndarray]:
    if Gs.size == 0:
        return 0, np.zeros(0)
    s = np.linalg.svd(Gs, compute_uv=False)
    if s[0] == 0:
        return 0, s
    return int(np.sum(s > tol * s[0])), s


def independent_rows(Gs: np.ndarray, rank: int) -> tuple[int, ...]:
    """Indices of `rank` well-conditioned independent rows of Gs (pivoted QR of Gs^T)."""
    import scipy.linalg as sla

    if rank == 0:
        return ()
    _, _, piv = sla.qr(Gs.T, mode="economic", pivoting=True)
    return tuple(sorted(int(i) for i in piv[:rank]))


def dependent_columns(Gs: np.ndarray) -> tuple[int, ...]:
    """The m columns of a full-row-rank Gs that form the best-conditioned square block."""
    import scipy.linalg as sla

    m = Gs.shape[0]
    _, _, piv = sla.qr(Gs, mode="economic", pivoting=True)
    return tuple(sorted(int(i) for i in piv[:m]))


def dof_report(eom: EOM, q=None, t: float = 0.0, p=None, tol: float = RANK_TOL) -> DofReport:
    """Count coordinates, constraints, the rank of G at q (default: the start values), the
    degrees of freedom and the redundant constraints (with the names of those dropped)."""
    import casadi as ca

    n, m = eom.n, eom.m
    pv = eom.param_values if p is None else np.asarray(p, float)
    if q is None:
        q, _ = eom.start(pv)
    q = np.asarray(q, float)
    if m == 0:
        return DofReport(coordinates=n, constraints=0, rank=0, dof=n, redundant=0, t=t)
    f = eom.workspace.memo("dof_GM", lambda: ca.Function("GM", [eom.q, eom.t, eom.p], [ca.jacobian(eom.g, eom.q), eom.M]))
    Gv, Mv = f(q, t, pv)
    G = np.array(Gv, float).reshape(m, n)
    M = np.array(Mv, float).reshape(n, n)
    Gs = scale_jacobian(G, M)
    rank, s = numeric_rank(Gs, tol)
    keep = independent_rows(Gs, rank)
    redundant = tuple(eom.constraint_names[i] for i in range(m) if i not in keep)
    gnorm = np.linalg.norm(G, axis=1)
    vanishing = tuple(eom.constraint_names[i] for i in range(m)
                      if i not in keep and gnorm[i] <= 1e-12 * max(1.0, float(np.max(gnorm))))
    return DofReport(coordinates=n, constraints=m, rank=rank, dof=n - rank, redundant=m - rank,
                     redundant_names=redundant, independent=keep,
                     singular_values=tuple(float(x) for x in s), t=float(t), vanishing=vanishing)


def singular_ratio(Gs: np.ndarray, rank: int) -> float:
    """sigma_rank / sigma_1 of the scaled Jacobian: 0 at a singular configuration."""
    if rank == 0:
        return 1.0
    s = np.linalg.svd(Gs, compute_uv=False)
    if s[0] == 0:
        return 0.0
    return float(s[rank - 1] / s[0]) if len(s) >= rank else 0.0


def singular_ratios(Gs: np.ndarray, rank: int) -> np.ndarray:
    """:func:`singular_ratio` of a stack of scaled Jacobians (K, m, n), in one batched SVD."""
    K = Gs.shape[0]
    if rank == 0 or Gs.shape[1] == 0:
        return np.ones(K)
    s = np.linalg.svd(Gs, compute_uv=False)
    if s.shape[1] < rank:
        return np.zeros(K)
    top = s[:, 0]
    return np.where(top > 0, s[:, rank - 1] / np.where(top > 0, top, 1.0), 0.0)
