"""Linear-quadratic regulator from a linearization: ``Linearization.lqr(Q, R) -> Lqr``.

Minimizes the integral of dx' Q dx + du' R du for dx' = A dx + B du (dx = [dq; dq'] about
the linearization's state, du = u - u_ref, one column of B per input), by the continuous
algebraic Riccati equation (scipy.linalg.solve_continuous_are): du = -K dx.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..diagnostics import UsageError


@dataclass
class Lqr:
    K: np.ndarray                    # (m, 2n) gain: du = -K (x - x_ref)
    P: np.ndarray                    # (2n, 2n) Riccati solution
    x_ref: np.ndarray                # [q; qd] of the linearization
    u_ref: np.ndarray                # input values at the linearization
    inputs: tuple[str, ...]
    closed_loop_eigenvalues: np.ndarray

    def u(self, x) -> np.ndarray:
        """All inputs for the state x = [q; qd]: u_ref - K (x - x_ref)."""
        return self.u_ref - self.K @ (np.asarray(x, float).ravel() - self.x_ref)

    def controller(self, name: str | None = None):
        """The state feedback of one input as ``u(t, x)`` (for ``simulate(inputs={name: ...})``)."""
        if name is None:
            if len(self.inputs) != 1:
                raise UsageError(f"several inputs ({', '.join(self.inputs)}): name the one to control")
            name = self.inputs[0]
        if name not in self.inputs:
            raise UsageError(f"'{name}' is not an input of this regulator ({', '.join(self.inputs)})")
        j = self.inputs.index(name)
        k, x_ref, u_ref = self.K[j].copy(), self.x_ref.copy(), float(self.u_ref[j])
        return lambda t, x: u_ref - float(k @ (np.asarray(x, float).ravel() - x_ref))

    def controllers(self) -> dict:
        """{input name: u(t, x)} for every input."""
        return {n: self.controller(n) for n in self.inputs}


def lqr(lin, Q, R) -> Lqr:
    from scipy.linalg import solve_continuous_are

    if lin.constrained:
        raise UsageError("lqr needs a model in independent coordinates (this linearization is of a reduced, "
                         "constrained model)")
    m = len(lin.inputs)
    if m == 0:
        raise UsageError("the linearization has no inputs: declare `input Real ...` or pass inputs=[...]")
    nx = lin.A.shape[0]
    Q = np.atleast_2d(np.asarray(Q, float))
    R = np.atleast_2d(np.asarray(R, float))
    if Q.shape == (1, nx) or Q.shape == (nx, 1):
        Q = np.diag(Q.ravel())
    if R.shape == (1, m) and m > 1:
        R = np.diag(R.ravel())
    if Q.shape != (nx, nx) or R.shape != (m, m):
        raise UsageError(f"Q must be {nx}x{nx} (states {', '.join(lin.coords)} then their speeds) and R {m}x{m} "
                         f"(inputs {', '.join(lin.inputs)}); got {Q.shape} and {R.shape}")
    if not (np.isfinite(Q).all() and np.isfinite(R).all()):
        raise UsageError("Q and R must be finite")
    if np.linalg.eigvalsh(0.5 * (R + R.T)).min() <= 0:
        raise UsageError("R must be positive definite")
    try:
        P = solve_continuous_are(lin.A, lin.B, Q, R)
    except (np.linalg.LinAlgError, ValueError) as e:
        raise UsageError(f"no stabilizing LQR solution ({e}); is (A, B) stabilizable?") from None
    K = np.linalg.solve(R, lin.B.T @ P)
    eom = lin.eom
    names = list(getattr(eom, "params", ()))
    u_ref = np.array([float(lin.p[names.index(n)]) if n in names else 0.0 for n in lin.inputs])
    return Lqr(K=K, P=P, x_ref=np.r_[lin.q, lin.qd], u_ref=u_ref, inputs=tuple(lin.inputs),
               closed_loop_eigenvalues=np.linalg.eigvals(lin.A - lin.B @ K))
