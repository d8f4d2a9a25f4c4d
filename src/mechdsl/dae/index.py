"""The differentiation index of a semi-explicit DAE, and a guard in front of IDAS.

IDAS is a BDF code for index-1 DAEs.  It also integrates Hessenberg index-2 systems when
the algebraic variables are left out of the error test, but handed the plain index-3
form of a mechanism it may run without complaint and return nonsense.  So nothing here
calls IDAS without first computing the index of what it is given:

    x' = f(x, z, t),   0 = h(x, z, t)

Numerically at a consistent point: if dh/dz has full rank the index is 1.  Otherwise the
combinations of h that do not involve z (the left null space N of dh/dz) are replaced by
their time derivatives N^T (h_x f + h_t) and the test repeats; each round adds one to the
index.  Rank decisions are made after Ruiz equilibration of dh/dz, so units do not matter.
"""
from __future__ import annotations

import numpy as np

from ..diagnostics import Diagnostic, MechError
from ..integrators import make_integrator


CODE_INDEX = "E823"
RANK_TOL = 1e-10


def _ruiz(A: np.ndarray, iters: int = 8) -> tuple[np.ndarray, np.ndarray]:
    """Row and column scalings r, c with diag(r) A diag(c) equilibrated (zero rows stay)."""
    r = np.ones(A.shape[0])
    c = np.ones(A.shape[1])
    B = A.copy()
    for _ in range(iters):
        rn = np.sqrt(np.max(np.abs(B), axis=1)) if B.shape[1] else np.ones(B.shape[0])
        cn = np.sqrt(np.max(np.abs(B), axis=0)) if B.shape[0] else np.ones(B.shape[1])
        rn[rn == 0] = 1.0
        cn[cn == 0] = 1.0
        r /= rn
        c /= cn
        B = A * r[:, None] * c[None, :]
    return r, c


def dae_index(dae: dict, x0, z0, p0, t0: float = 0.0, max_index: int = 3, tol: float = RANK_TOL) -> int:
    """Differentiation index of the semi-explicit DAE ``dae`` (CasADi dict with keys x, z, p,
    t, ode, alg) at the point (x0, z0, p0, t0).  Returns max_index + 1 when the index exceeds
    max_index (or the system is singular)."""
    import casadi as ca

    x, z, p, t = dae["x"], dae.get("z", ca.SX.zeros(0, 1)), dae.get("p", ca.SX.zeros(0, 1)), dae.get("t", ca.SX.sym("t"))
    f, h = dae["ode"], dae.get("alg", ca.SX.zeros(0, 1))
    nz = z.numel()
    if nz == 0:
        return 0
    args = [x, z, p, t]
    vals = [np.asarray(x0, float), np.asarray(z0, float), np.asarray(p0, float), float(t0)]
    for index in range(1, max_index + 1):
        Hz = np.array(ca.Function("Hz", args, [ca.jacobian(h, z)])(*vals), float).reshape(h.numel(), nz)
        r, c = _ruiz(Hz)
        Hs = Hz * r[:, None] * c[None, :]
        U, s, _ = np.linalg.svd(Hs)
        rank = int(np.sum(s > tol * (s[0] if s.size and s[0] > 0 else 1.0))) if s.size else 0
        if rank == nz:
            return index
        # rows of h (in scaled form) along U[:, :rank] keep depending on z; the rest do not
        hs = h * ca.DM(r)
        N = U[:, rank:]
        keep = ca.mtimes(ca.DM(U[:, :rank]).T, hs)
        free = ca.mtimes(ca.DM(N).T, hs)
        dfree = ca.jtimes(free, x, f) + ca.jacobian(free, t)
        h = ca.vertcat(keep, dfree)
    return max_index + 1


def refuse_high_index(index: int, allowed: int, what: str) -> None:
    if index > allowed:
        shown = f"{index}" if index <= 3 else "higher than 3 (or the system is singular)"
        raise MechError(Diagnostic(
            CODE_INDEX,
            f"refusing to hand {what} to IDAS: its differentiation index is {shown}, IDAS is reliable "
            f"only up to index {allowed} here",
            help="reduce the index first: formulation = \"ggl\" (stabilized index 2), \"baumgarte\", "
                 "\"projection\" or \"partitioning\" (index-1 ODEs)"))


def check_for_idas(dae: dict, x0, z0, p0, t0: float, opts: dict, allowed_index: int = 1,
                   what: str = "this DAE", force: bool = False) -> int:
    """The DAE's index at (x0, z0, p0, t0); a MechError (E823) if IDAS must not get it.

    Index 2 is accepted only when ``allowed_index >= 2`` *and* the algebraic variables are
    left out of the error test (option suppress_algebraic).  ``force=True`` skips the
    refusal (benchmarks that demonstrate what goes wrong without it)."""
    index = dae_index(dae, x0, z0, p0, t0)
    if not force:
        if index >= 2 and not opts.get("suppress_algebraic", False):
            allowed_index = 1
        refuse_high_index(index, allowed_index, what)
    return index


def guarded_idas(name: str, dae: dict, x0, z0, p0, t0: float, tout, opts: dict, allowed_index: int = 1,
                 what: str = "this DAE", force: bool = False):
    """Build a CasADi IDAS integrator only after :func:`check_for_idas`.  Returns (integrator, index)."""
    import casadi as ca

    index = check_for_idas(dae, x0, z0, p0, t0, opts, allowed_index, what, force)
    return make_integrator(name, "idas", dae, t0, tout, opts), index
