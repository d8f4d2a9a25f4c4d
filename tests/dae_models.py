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

REFERENCES = Path(__file__).resolve().parent / "references"   # copies of ../shared/references


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


DUMBBELL = dict(m1=1.0, m2=2.0, L=1.5, g=9.81, k=30.0)
DUMBBELL_START = dict(x1=0.5, y1=0.0, phi=0.4, vx1=0.0, vy1=1.0, w=2.0)


def dumbbell_dae():
    """Two point masses in the plane joined by a massless rigid rod (distance constraint);
    mass 1 is tied to the origin by a spring (k), gravity along -y."""
    d, s0 = DUMBBELL, DUMBBELL_START
    coords = ("x1", "y1", "x2", "y2")
    params = ("m1", "m2", "L", "g", "k")
    q, qd, t, p, P = _syms(coords, params)
    T = 0.5 * P["m1"] * (qd[0] ** 2 + qd[1] ** 2) + 0.5 * P["m2"] * (qd[2] ** 2 + qd[3] ** 2)
    V = P["g"] * (P["m1"] * q[1] + P["m2"] * q[3]) + 0.5 * P["k"] * (q[0] ** 2 + q[1] ** 2)
    g = (q[2] - q[0]) ** 2 + (q[3] - q[1]) ** 2 - P["L"] ** 2
    L, ph, w = d["L"], s0["phi"], s0["w"]
    q0 = [s0["x1"], s0["y1"], s0["x1"] + L * np.cos(ph), s0["y1"] + L * np.sin(ph)]
    qd0 = [s0["vx1"], s0["vy1"], s0["vx1"] - L * w * np.sin(ph), s0["vy1"] + L * w * np.cos(ph)]
    return from_lagrangian("DumbbellDAE", coords, params, [d[k] for k in params], q, qd, t, p, T, V,
                           g=g, q0=q0, qd0=qd0, constraint_names=["rod"])


def dumbbell_minimal():
    """The same dumbbell in minimal coordinates (x1, y1, phi): mass 2 at x1 + L cos phi, y1 + L sin phi."""
    d, s0 = DUMBBELL, DUMBBELL_START
    coords = ("x1", "y1", "phi")
    params = ("m1", "m2", "L", "g", "k")
    q, qd, t, p, P = _syms(coords, params)
    x2 = q[0] + P["L"] * ca.cos(q[2])
    y2 = q[1] + P["L"] * ca.sin(q[2])
    v2 = ca.jtimes(ca.vertcat(x2, y2), q, qd)
    T = 0.5 * P["m1"] * (qd[0] ** 2 + qd[1] ** 2) + 0.5 * P["m2"] * ca.dot(v2, v2)
    V = P["g"] * (P["m1"] * q[1] + P["m2"] * y2) + 0.5 * P["k"] * (q[0] ** 2 + q[1] ** 2)
    return from_lagrangian("DumbbellMinimal", coords, params, [d[k] for k in params], q, qd, t, p, T, V,
                           q0=[s0["x1"], s0["y1"], s0["phi"]], qd0=[s0["vx1"], s0["vy1"], s0["w"]],
                           outputs={"x2": x2, "y2": y2})


def pendulum_exact(t, g=9.81, L=1.0, theta0=np.pi / 2):
    """Exact large-amplitude pendulum released from rest at theta0 (from the downward vertical):
    sin(theta/2) = k cd(w t | k^2), k = sin(theta0/2), w = sqrt(g/L).  Returns (x, y)."""
    from scipy.special import ellipj

    k = np.sin(theta0 / 2)
    sn, cn, dn, _ = ellipj(np.sqrt(g / L) * np.asarray(t, float), k * k)
    theta = 2 * np.arcsin(k * cn / dn)
    return L * np.sin(theta), -L * np.cos(theta)


# --------------------------------------------------------------------------- planar linkages


def _rot2(a):
    return ca.vertcat(ca.cos(a), ca.sin(a))


def _rod_energy(m, L, c, phi, q, qd):
    """Kinetic energy of a uniform planar rod: centre c (SX 2-vector in q), angle phi."""
    vc = ca.jtimes(c, q, qd)
    w = ca.jtimes(phi, q, qd)
    return 0.5 * m * ca.dot(vc, vc) + 0.5 * (m * L**2 / 12) * w**2


def four_bar_eom(lengths=(1.0, 1.0, 1.0, 1.0), masses=(1.0, 1.0, 1.0), gravity=9.81, q0=None, qd0=None,
                 fixed_q=None, fixed_qd=None, name="FourBar"):
    """Planar four-bar in joint angles (th1 crank, th2 coupler, th3 rocker; world angles).

    Ground pivots A = (0, 0) and D = (d, 0); crank A->B (a), coupler B->C (b), rocker D->C (c).
    The loop is cut at the joint C between coupler (parent) and rocker (child); its two
    constraints g = R3^T (C_coupler - C_rocker) are named "jC.force[0]", "jC.force[1]", so
    their multipliers are the force of the joint on the rocker in the rocker's frame."""
    a, b, c, d = lengths
    coords = ("th1", "th2", "th3")
    params = ("m1", "m2", "m3", "g")
    q, qd, t, p, P = _syms(coords, params)
    th1, th2, th3 = q[0], q[1], q[2]
    B = a * _rot2(th1)
    C1 = B + b * _rot2(th2)
    C3 = ca.vertcat(d, 0) + c * _rot2(th3)
    T = (_rod_energy(P["m1"], a, 0.5 * B, th1, q, qd) + _rod_energy(P["m2"], b, 0.5 * (B + C1), th2, q, qd)
         + _rod_energy(P["m3"], c, 0.5 * (ca.vertcat(d, 0) + C3), th3, q, qd))
    V = P["g"] * (P["m1"] * 0.5 * B[1] + P["m2"] * 0.5 * (B[1] + C1[1]) + P["m3"] * 0.5 * C3[1])
    R3T = ca.horzcat(ca.vertcat(ca.cos(th3), -ca.sin(th3)), ca.vertcat(ca.sin(th3), ca.cos(th3)))
    g = ca.mtimes(R3T, C1 - C3)
    e = from_lagrangian(name, coords, params, [*masses, gravity], q, qd, t, p, T, V, g=g, q0=q0, qd0=qd0,
                        constraint_names=["jC.force[0]", "jC.force[1]"],
                        outputs={"xB": B[0], "yB": B[1], "xC": C3[0], "yC": C3[1], "energy": T + V})
    if fixed_q is not None:
        e = e.replace(fixed_q=tuple(fixed_q))
    if fixed_qd is not None:
        e = e.replace(fixed_qd=tuple(fixed_qd))
    return e


def crank_rocker_eom():
    """A Grashof crank-rocker (ground 1, crank 0.4, coupler 1.0, rocker 0.8) under gravity with
    the crank turning; th2, th3 and their speeds are computed by consistent initialization."""
    return four_bar_eom(lengths=(0.4, 1.0, 0.8, 1.0), masses=(0.5, 1.0, 0.8), q0=[1.0, 0.3, 1.4],
                        qd0=[6.0, 0.0, 0.0], fixed_q=(True, False, False), fixed_qd=(True, False, False),
                        name="CrankRocker")


def parallelogram_eom():
    """IFToMM A02 with N = 1: unit rods, cranks vertical, coupler at y = 1, crank tip moving
    at 1 m/s in +x; it falls to the flat, singular configuration (all bars on the x axis)."""
    return four_bar_eom(q0=[np.pi / 2, 0.0, np.pi / 2], qd0=[-1.0, 0.0, -1.0], name="Parallelogram")


def parallelogram_singular_time(g=9.81):
    """Time for the parallelogram above to reach theta = 0 (from energy: (5/6) w^2 + 2 g sin(theta))."""
    from scipy.integrate import quad

    E = 5 / 6 * 1.0 + 2 * g
    speed = lambda th: np.sqrt((E - 2 * g * np.sin(th)) * 6 / 5)  # noqa: E731
    return quad(lambda th: 1 / speed(th), 0, np.pi / 2, epsabs=1e-14, epsrel=1e-14)[0]


def slider_crank_eom(r=0.3, l=1.0, masses=(1.0, 2.0, 0.5), gravity=9.81, torque=5.0, q0=None, qd0=None):
    """Crank (th1, length r, pivot at the origin), connecting rod (th2, length l), slider (s on y = 0).

    The loop is cut at the pin B between the rod (parent) and the slider (child, not rotating):
    g = (A + l e(th2)) - (s, 0), named "jB.force[0]", "jB.force[1]" (force on the slider, world axes).
    A constant torque drives the crank."""
    coords = ("th1", "th2", "s")
    params = ("m1", "m2", "m3", "g", "tau")
    q, qd, t, p, P = _syms(coords, params)
    A = r * _rot2(q[0])
    B = A + l * _rot2(q[1])
    T = (_rod_energy(P["m1"], r, 0.5 * A, q[0], q, qd) + _rod_energy(P["m2"], l, 0.5 * (A + B), q[1], q, qd)
         + 0.5 * P["m3"] * qd[2] ** 2)
    V = P["g"] * (P["m1"] * 0.5 * A[1] + P["m2"] * 0.5 * (A[1] + B[1]))
    Q = ca.vertcat(P["tau"], 0, 0)
    g = B - ca.vertcat(q[2], 0)
    if q0 is None:
        th1 = 1.0
        th2 = -np.arcsin(r * np.sin(th1) / l)
        q0 = [th1, th2, r * np.cos(th1) + l * np.cos(th2)]
        qd0 = [2.0, 0.0, 0.0]
    e = from_lagrangian("SliderCrank", coords, params, [*masses, gravity, torque], q, qd, t, p, T, V, Q=Q, g=g,
                        q0=q0, qd0=qd0, constraint_names=["jB.force[0]", "jB.force[1]"],
                        outputs={"xA": A[0], "yA": A[1]})
    e = e.replace(fixed_qd=(True, False, False))
    return e


# --------------------------------------------------------------------------- Bricard (IFToMM A04)

BRICARD_POINTS = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [1, 1, 1], [0, 1, 1], [0, 0, 1]], float)
BRICARD_AXES = np.array([[0, 1, 0], [0, 0, 1], [1, 0, 0], [0, 1, 0], [0, 0, 1], [1, 0, 0]], float)


def _rodrigues(axis, angle):
    k = ca.DM(axis)
    K = ca.vertcat(ca.horzcat(0, -k[2], k[1]), ca.horzcat(k[2], 0, -k[0]), ca.horzcat(-k[1], k[0], 0))
    return ca.DM.eye(3) + ca.sin(angle) * K + (1 - ca.cos(angle)) * ca.mtimes(K, K)


def bricard_eom(gravity=9.81, speed=1.0):
    """Orthogonal Bricard linkage: five 1 m, 1 kg rods along the cube path P1..P6, six revolute
    joints (axes perpendicular to both adjacent rods), the ground link P6-P1.

    Coordinates: the five joint angles from J1 along the chain; the loop is cut at J6
    (rod 5 to ground): its end must be at P6 (3 equations) and its J6 axis must stay along
    x (2 equations).  5 coordinates, 5 constraints, but the linkage moves: rank 4, 1 dof.
    Start: the cube configuration, J1 turning at `speed` rad/s (the other speeds free)."""
    coords = tuple(f"th{i}" for i in range(1, 6))
    params = ("g",)
    q, qd, t, p, P = _syms(coords, params)
    R = ca.SX.eye(3)
    o = ca.SX.zeros(3, 1)          # translation of the accumulated rigid motion x -> R x + o
    T = 0
    V = 0
    for k in range(5):
        Pk = BRICARD_POINTS[k]
        Rk = _rodrigues(BRICARD_AXES[k], q[k])
        # compose: x -> R (Rk (x - Pk) + Pk) + o
        o = ca.mtimes(R, ca.DM(Pk) - ca.mtimes(Rk, ca.DM(Pk))) + o
        R = ca.mtimes(R, Rk)
        a0, b0 = BRICARD_POINTS[k], BRICARD_POINTS[k + 1]
        c = ca.mtimes(R, ca.DM(0.5 * (a0 + b0))) + o
        vc = ca.jtimes(c, q, qd)
        Rd = ca.jtimes(R, q, qd)
        W = ca.mtimes(Rd, R.T)
        w = ca.vertcat(W[2, 1], W[0, 2], W[1, 0])
        u = ca.mtimes(R, ca.DM(b0 - a0))
        Iw = (1.0 / 12) * (w - u * ca.dot(u, w))
        T = T + 0.5 * ca.dot(vc, vc) + 0.5 * ca.dot(w, Iw)
        V = V + P["g"] * c[1]
    end = ca.mtimes(R, ca.DM(BRICARD_POINTS[5])) + o
    axis6 = ca.mtimes(R, ca.DM(BRICARD_AXES[5]))
    g = ca.vertcat(end - ca.DM(BRICARD_POINTS[5]), axis6[1], axis6[2])
    e = from_lagrangian("Bricard", coords, params, [gravity], q, qd, t, p, T, V, g=g,
                        q0=[0.0] * 5, qd0=[speed, 0, 0, 0, 0],
                        constraint_names=["j6.x", "j6.y", "j6.z", "j6.axis_y", "j6.axis_z"],
                        outputs={"energy": T + V})
    e = e.replace(fixed_qd=(True, False, False, False, False))
    return e


# --------------------------------------------------------------------------- rheonomic pendulum


def rheonomic_pendulum_eom(gravity=9.81, amp=0.2, freq=2.0, theta0=0.8):
    """Point mass on a rod of prescribed length L(t) = 1 + amp sin(freq t): g = (x^2 + y^2 - L^2)/2."""
    coords = ("x", "y")
    params = ("g", "amp", "freq")
    q, qd, t, p, P = _syms(coords, params)
    L = 1 + P["amp"] * ca.sin(P["freq"] * t)
    T = 0.5 * ca.dot(qd, qd)
    V = P["g"] * q[1]
    g = 0.5 * (q[0] ** 2 + q[1] ** 2 - L**2)
    # start on the rod: L(0) = 1, dL/dt(0) = amp*freq (radial speed), at rest tangentially
    x0, y0 = np.sin(theta0), -np.cos(theta0)
    e = from_lagrangian("RheonomicPendulum", coords, params, [gravity, amp, freq], q, qd, t, p, T, V, g=g,
                        q0=[x0, y0], qd0=[0.0, 0.0], constraint_names=["rod"], outputs={"x": q[0], "y": q[1]})
    e = e.replace(fixed_qd=(False, False))
    return e


def rheonomic_pendulum_reference(t_out, gravity=9.81, amp=0.2, freq=2.0, theta0=0.8):
    """Minimal-coordinate solution: r = L(t) prescribed, d/dt(r^2 th') = -g r sin th."""
    from scipy.integrate import solve_ivp

    def rhs(t, y):
        th, w = y
        r = 1 + amp * np.sin(freq * t)
        rd = amp * freq * np.cos(freq * t)
        return [w, (-gravity * np.sin(th) - 2 * rd * w) / r]

    sol = solve_ivp(rhs, (0, t_out[-1]), [theta0, 0.0], method="DOP853", rtol=1e-13, atol=1e-13, t_eval=t_out)
    r = 1 + amp * np.sin(freq * sol.t)
    return r * np.sin(sol.y[0]), -r * np.cos(sol.y[0])
