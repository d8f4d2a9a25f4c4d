"""Levenberg-Marquardt for the small nonlinear systems of the analyses (equilibria, steady
motions): dense, deterministic, no scipy (Nielsen's damping update)."""
from __future__ import annotations

import numpy as np


def levenberg_marquardt(f, jac, x0, max_iter: int = 200, tol: float = 1e-15):
    """Minimize |f(x)|^2 (Levenberg-Marquardt with Nielsen's damping update); None if f is not finite."""
    x = np.asarray(x0, float).copy()
    with np.errstate(all="ignore"):
        r = f(x)
        if not np.all(np.isfinite(r)):
            return None
        J = jac(x)
        A, g = J.T @ J, J.T @ r
        mu = 1e-3 * max(np.max(np.diag(A), initial=0.0), 1e-12)
        nu = 2.0
        cost = r @ r
        for _ in range(max_iter):
            if cost <= 1e-32 or np.max(np.abs(g), initial=0.0) <= 1e-30:
                break
            step = np.linalg.solve(A + mu * np.eye(len(x)), -g)
            if not np.all(np.isfinite(step)):
                return None
            xn = x + step
            rn = f(xn)
            cn = rn @ rn if np.all(np.isfinite(rn)) else np.inf
            pred = -(step @ g) * 0.5 + 0.5 * mu * (step @ step)     # predicted decrease / 1
            rho = (cost - cn) / max(pred * 2.0, 1e-300) if np.isfinite(cn) else -1.0
            if rho > 0:
                x, r, cost = xn, rn, cn
                J = jac(x)
                A, g = J.T @ J, J.T @ r
                mu *= max(1.0 / 3.0, 1.0 - (2.0 * rho - 1.0) ** 3)
                nu = 2.0
                if np.max(np.abs(step), initial=0.0) <= tol * (1.0 + np.max(np.abs(x), initial=0.0)):
                    break
            else:
                mu *= nu
                nu *= 2.0
                if mu > 1e30:
                    break
    return x

