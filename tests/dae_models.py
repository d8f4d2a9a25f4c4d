"""Constrained test models built directly as EOMs (CasADi SX) for the DAE tests.

Each builder returns an :class:`mechdsl.eom.EOM` made with ``eom.from_lagrangian`` from
T, V, Q and the constraint residuals g written out by hand, so the tests exercise the DAE
layer independently of the front end and the mechanics derivation.
"""
from __future__ import annotations

import json
from pathlib import Path

import casadi as ca
import numpy as np

from mechdsl.eom import from_lagrangian

REFERENCES = Path("/work/shared/references")


def _syms(coords, params):
    q = ca.SX.sym("q", len(coords))
    qd = ca.SX.sym("qd", len(coords))
    t = ca.SX.sym("t")
    p = ca.SX.sym("p", len(params))
    P = {name: p[i] for i, name in enumerate(params)}
    return q, qd, t, p, P


# --------------------------------------------------------------------------- Andrews


def andrews_data():
    return json.loads((REFERENCES / "andrews_squeezer.json").read_text())


ANDREWS_COORDS = ("beta", "Theta", "gamma", "Phi", "delta", "Omega", "epsilon")


def andrews_mass_forces(q, qd, P):
    """M(q) and the velocity/spring/motor forces f(q, qd) exactly as printed in the reference."""
    b, th, ga, ph, de, om, ep = (q[i] for i in range(7))
    bd, thd, gad, phd, ded, omd, epd = (qd[i] for i in range(7))
    m1, m2, m3, m4, m5, m6, m7 = (P[f"m{i}"] for i in range(1, 8))
    I1, I2, I3, I4, I5, I6, I7 = (P[f"i{i}"] for i in range(1, 8))
    ra, rr, da, sa, sb, e, ea, zt, ta, tb = (P[k] for k in ("ra", "rr", "da", "sa", "sb", "e", "ea", "zt", "ta", "tb"))
    zf, fa, u, ua, ub = (P[k] for k in ("zf", "fa", "u", "ua", "ub"))
    M = ca.SX.zeros(7, 7)
    M[0, 0] = m1 * ra**2 + m2 * (rr**2 - 2 * da * rr * ca.cos(th) + da**2) + I1 + I2
    M[1, 0] = M[0, 1] = m2 * (da**2 - da * rr * ca.cos(th)) + I2
    M[1, 1] = m2 * da**2 + I2
    M[2, 2] = m3 * (sa**2 + sb**2) + I3
    M[3, 3] = m4 * (e - ea) ** 2 + I4
    M[4, 3] = M[3, 4] = m4 * ((e - ea) ** 2 + zt * (e - ea) * ca.sin(ph)) + I4
    M[4, 4] = m4 * (zt**2 + 2 * zt * (e - ea) * ca.sin(ph) + (e - ea) ** 2) + m5 * (ta**2 + tb**2) + I4 + I5
    M[5, 5] = m6 * (zf - fa) ** 2 + I6
    M[6, 5] = M[5, 6] = m6 * ((zf - fa) ** 2 - u * (zf - fa) * ca.sin(om)) + I6
    M[6, 6] = m6 * ((zf - fa) ** 2 - 2 * u * (zf - fa) * ca.sin(om) + u**2) + m7 * (ua**2 + ub**2) + I6 + I7
    xd = P["sd"] * ca.cos(ga) + P["sc"] * ca.sin(ga) + P["xb"]
    yd = P["sd"] * ca.sin(ga) - P["sc"] * ca.cos(ga) + P["yb"]
    L = ca.sqrt((xd - P["xc"]) ** 2 + (yd - P["yc"]) ** 2)
    F = -P["c0"] * (L - P["l0"]) / L
    fx, fy = F * (xd - P["xc"]), F * (yd - P["yc"])
    sc, sd = P["sc"], P["sd"]
    f = ca.vertcat(
        P["mom"] - m2 * da * rr * thd * (thd + 2 * bd) * ca.sin(th),
        m2 * da * rr * bd**2 * ca.sin(th),
        fx * (sc * ca.cos(ga) - sd * ca.sin(ga)) + fy * (sd * ca.cos(ga) + sc * ca.sin(ga)),
        m4 * zt * (e - ea) * ded**2 * ca.cos(ph),
        -m4 * zt * (e - ea) * phd * (phd + 2 * ded) * ca.cos(ph),
        -m6 * u * (zf - fa) * epd**2 * ca.cos(om),
        m6 * u * (zf - fa) * omd * (omd + 2 * epd) * ca.cos(om),
    )
    return M, f, (xd, yd, L)


def andrews_constraints(q, P):
    b, th, ga, ph, de, om, ep = (q[i] for i in range(7))
    rr, d, ss, e, zt, zf, u = (P[k] for k in ("rr", "d", "ss", "e", "zt", "zf", "u"))
    xa, ya, xb, yb = P["xa"], P["ya"], P["xb"], P["yb"]
    cx = rr * ca.cos(b) - d * ca.cos(b + th)
    cy = rr * ca.sin(b) - d * ca.sin(b + th)
    return ca.vertcat(
        cx - ss * ca.sin(ga) - xb,
        cy + ss * ca.cos(ga) - yb,
        cx - e * ca.sin(ph + de) - zt * ca.cos(de) - xa,
        cy + e * ca.cos(ph + de) - zt * ca.sin(de) - ya,
        cx - zf * ca.cos(om + ep) - u * ca.sin(ep) - xa,
        cy - zf * ca.sin(om + ep) + u * ca.cos(ep) - ya,
    )


def andrews_eom():
    """Andrews' squeezer from T = 1/2 qd^T M qd, the spring potential and the motor torque."""
    data = andrews_data()
    params = tuple(data["params"])
    values = [data["params"][k] for k in params]
    q, qd, t, p, P = _syms(ANDREWS_COORDS, params)
    M, _, (xd, yd, L) = andrews_mass_forces(q, qd, P)
    T = 0.5 * ca.dot(qd, ca.mtimes(M, qd))
    V = 0.5 * P["c0"] * (L - P["l0"]) ** 2
    Q = ca.vertcat(P["mom"], ca.SX.zeros(6))
    g = andrews_constraints(q, P)
    y0 = [float(v) for v in data["y0"]]
    return from_lagrangian("Andrews", ANDREWS_COORDS, params, values, q, qd, t, p, T, V, Q=Q, g=g,
                           q0=y0[:7], qd0=y0[7:14], constraint_names=[f"g{i}" for i in range(1, 7)])


# --------------------------------------------------------------------------- Cartesian pendulum


def pendulum_eom(gravity=1.0, x0=(1.0, 0.0), v0=(0.0, 1.0), length=1.0, mass=1.0):
    """Unit point mass in the plane, distance constraint (x^2 + y^2 - L^2)/2 = 0 to the origin."""
    coords = ("x", "y")
    params = ("m", "g", "L")
    q, qd, t, p, P = _syms(coords, params)
    T = 0.5 * P["m"] * ca.dot(qd, qd)
    V = P["m"] * P["g"] * q[1]
    g = 0.5 * (q[0] ** 2 + q[1] ** 2 - P["L"] ** 2)
    return from_lagrangian("PendulumCartesian", coords, params, [mass, gravity, length], q, qd, t, p, T, V,
                           g=g, q0=list(x0), qd0=list(v0), constraint_names=["rod"],
                           outputs={"x": q[0], "y": q[1]})


# --------------------------------------------------------------------------- dumbbell


def dumbbell_dae(m1=1.0, m2=2.0, length=1.5, gravity=9.81, state=None):
    """Two point masses in the plane joined by a massless rigid rod (distance constraint)."""
    coords = ("x1", "y1", "x2", "y2")
    params = ("m1", "m2", "L", "g")
    q, qd, t, p, P = _syms(coords, params)
    T = 0.5 * P["m1"] * (qd[0] ** 2 + qd[1] ** 2) + 0.5 * P["m2"] * (qd[2] ** 2 + qd[3] ** 2)
    V = P["g"] * (P["m1"] * q[1] + P["m2"] * q[3])
    g = (q[2] - q[0]) ** 2 + (q[3] - q[1]) ** 2 - P["L"] ** 2
    q0, qd0 = state
    return from_lagrangian("DumbbellDAE", coords, params, [m1, m2, length, gravity], q, qd, t, p, T, V,
                           g=g, q0=q0, qd0=qd0, constraint_names=["rod"])


def dumbbell_minimal(m1=1.0, m2=2.0, length=1.5, gravity=9.81, state=None):
    """The same dumbbell in minimal coordinates (x1, y1, phi): mass 2 at x1 + L cos phi, y1 + L sin phi."""
    coords = ("x1", "y1", "phi")
    params = ("m1", "m2", "L", "g")
    q, qd, t, p, P = _syms(coords, params)
    x2 = q[0] + P["L"] * ca.cos(q[2])
    y2 = q[1] + P["L"] * ca.sin(q[2])
    v2 = ca.jtimes(ca.vertcat(x2, y2), q, qd)
    T = 0.5 * P["m1"] * (qd[0] ** 2 + qd[1] ** 2) + 0.5 * P["m2"] * ca.dot(v2, v2)
    V = P["g"] * (P["m1"] * q[1] + P["m2"] * y2)
    q0, qd0 = state
    return from_lagrangian("DumbbellMinimal", coords, params, [m1, m2, length, gravity], q, qd, t, p, T, V,
                           q0=q0, qd0=qd0, outputs={"x2": x2, "y2": y2})


def pendulum_exact(t, g=9.81, L=1.0, theta0=np.pi / 2):
    """Exact large-amplitude pendulum released from rest at theta0 (from the downward vertical):
    sin(theta/2) = k cd(w t | k^2), k = sin(theta0/2), w = sqrt(g/L).  Returns (x, y)."""
    from scipy.special import ellipj

    k = np.sin(theta0 / 2)
    sn, cn, dn, _ = ellipj(np.sqrt(g / L) * np.asarray(t, float), k * k)
    theta = 2 * np.arcsin(k * cn / dn)
    return L * np.sin(theta), -L * np.cos(theta)
