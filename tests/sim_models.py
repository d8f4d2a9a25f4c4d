"""EOMs for the simulation tests, built directly with eom.from_lagrangian (CasADi SX)."""
from __future__ import annotations

import casadi as ca
import numpy as np

from mechdsl import eom as E


def _syms(n, npar):
    return ca.SX.sym("q", n), ca.SX.sym("qd", n), ca.SX.sym("t"), ca.SX.sym("p", npar)


def pendulum(theta0=np.pi / 2, L=1.0, g=9.81, m=1.0):
    """Point mass on a massless rod: T = m L^2 th'^2 / 2, V = -m g L cos th."""
    q, qd, t, p = _syms(1, 3)
    mm, LL, gg = p[0], p[1], p[2]
    T = 0.5 * mm * LL ** 2 * qd[0] ** 2
    V = -mm * gg * LL * ca.cos(q[0])
    return E.from_lagrangian("Pendulum", ["theta"], ["m", "L", "g"], [m, L, g], q, qd, t, p, T, V,
                             q0=[theta0], outputs={"x": LL * ca.sin(q[0]), "y": -LL * ca.cos(q[0])})


def chain(N, theta0=np.pi / 2):
    """N point masses on massless unit rods in series (absolute angles)."""
    q, qd, t, p = _syms(N, 3)
    m, l, g = p[0], p[1], p[2]
    T = V = 0
    x = y = vx = vy = 0
    for i in range(N):
        x = x + l * ca.sin(q[i])
        y = y - l * ca.cos(q[i])
        vx = vx + l * ca.cos(q[i]) * qd[i]
        vy = vy + l * ca.sin(q[i]) * qd[i]
        T = T + 0.5 * m * (vx ** 2 + vy ** 2)
        V = V + m * g * y
    return E.from_lagrangian(f"Chain{N}", [f"theta{i + 1}" for i in range(N)], ["m", "l", "g"], [1.0, 1.0, 9.81],
                             q, qd, t, p, T, V, q0=[theta0] + [0.0] * (N - 1),
                             outputs={"x_tip": x, "y_tip": y})


def singular_bead(extra_oscillator=False):
    """T = 1/2 (cos(q) q')^2: M = cos(q)^2 vanishes at q = pi/2.  From q = 0, q' = 1 the exact
    motion is sin q = t, reaching the singular configuration at t = 1.  With
    extra_oscillator a decoupled harmonic oscillator z is added (2 coordinates: the mass
    matrix is then solved by the numeric QR route)."""
    n = 2 if extra_oscillator else 1
    q, qd, t, p = _syms(n, 1)
    T = 0.5 * (ca.cos(q[0]) * qd[0]) ** 2
    V = 0
    if extra_oscillator:
        T = T + 0.5 * qd[1] ** 2
        V = 0.5 * p[0] * q[1] ** 2
    names = ["s", "z"][:n]
    return E.from_lagrangian("Bead", names, ["k"], [1.0], q, qd, t, p, T, V,
                             q0=[0.0] * n, qd0=[1.0] + ([0.5] if extra_oscillator else []))


def blowup():
    """T = q'^2/2, V = -q^4/4: q'' = q^3.  From q = 1, q' = 1/sqrt(2): q = 1/(1 - t/sqrt(2)),
    infinite at t = sqrt(2)."""
    q, qd, t, p = _syms(1, 0)
    return E.from_lagrangian("Blowup", ["u"], [], [], q, qd, t, p, 0.5 * qd[0] ** 2, -q[0] ** 4 / 4,
                             q0=[1.0], qd0=[1 / np.sqrt(2)])


def stiff_oscillator(c=1e4, k=1.0):
    """Two masses: a slow spring k and a very stiff damper c between q1 and q2 (overdamped mode
    with rate ~ 2c), a classic stiff ODE."""
    q, qd, t, p = _syms(2, 2)
    T = 0.5 * (qd[0] ** 2 + qd[1] ** 2)
    V = 0.5 * p[1] * q[0] ** 2
    D = 0.5 * p[0] * (qd[0] - qd[1]) ** 2
    return E.from_lagrangian("Stiff", ["a", "b"], ["c", "k"], [c, k], q, qd, t, p, T, V, D=D,
                             q0=[1.0, 0.0])


def forced_oscillator():
    """x'' + 2 zeta w x' + w^2 x = F cos(W t): damped, driven (time-dependent generalized force)."""
    q, qd, t, p = _syms(1, 4)
    w, zeta, F, W = p[0], p[1], p[2], p[3]
    T = 0.5 * qd[0] ** 2
    V = 0.5 * w ** 2 * q[0] ** 2
    D = zeta * w * qd[0] ** 2
    Q = F * ca.cos(W * t)
    return E.from_lagrangian("Forced", ["x"], ["w", "zeta", "F", "W"], [2.0, 0.1, 1.0, 1.5], q, qd, t, p, T, V,
                             D=D, Q=Q, q0=[1.0])
