"""Small test models built directly in CasADi (Lagrangian route), shared by the benchmarks.

Until the .mech front end is on main the benchmarks build their EOMs with
eom.from_lagrangian; the same models appear as .mech text in models/ later.
"""
from __future__ import annotations

import casadi as ca
import numpy as np

from mechdsl import eom as E


def chain(N: int, theta0: float = np.pi / 2):
    """N point masses m on massless rods of length l in series (planar), gravity g; angles absolute."""
    q = ca.SX.sym("q", N)
    qd = ca.SX.sym("qd", N)
    t = ca.SX.sym("t")
    p = ca.SX.sym("p", 3)
    m, l, g = p[0], p[1], p[2]
    T = 0
    V = 0
    x = y = vx = vy = 0
    for i in range(N):
        x = x + l * ca.sin(q[i])
        y = y - l * ca.cos(q[i])
        vx = vx + l * ca.cos(q[i]) * qd[i]
        vy = vy + l * ca.sin(q[i]) * qd[i]
        T = T + 0.5 * m * (vx ** 2 + vy ** 2)
        V = V + m * g * y
    return E.from_lagrangian(f"chain{N}", [f"theta{i + 1}" for i in range(N)], ["m", "l", "g"], [1.0, 1.0, 9.81],
                             q, qd, t, p, T, V, q0=[theta0] + [0.0] * (N - 1), outputs={"x_tip": x, "y_tip": y})
