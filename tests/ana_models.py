"""Hand-built EOMs (CasADi SX, through eom.from_lagrangian) for the analysis tests.

Kinematics are written from positions (and rotation matrices for the top), so the analyses
see the same kind of SX a component model produces (trig identities not simplified).
"""
import math

import casadi as ca

from mechdsl import eom as E


def _sym(n, np_):
    return ca.SX.sym("q", n), ca.SX.sym("qd", n), ca.SX.sym("t"), ca.SX.sym("p", np_)


def _vel(r, q, qd, t):
    return ca.jacobian(r, q) @ qd + ca.jacobian(r, t)


def double_pendulum(m=1.0, l=1.0, g=9.81, q0=(0.1, 0.1), qd0=(0.0, 0.0)):
    """Two equal point masses on equal massless rods; angles from the downward vertical (absolute)."""
    q, qd, t, p = _sym(2, 3)
    mm, ll, gg = p[0], p[1], p[2]
    r1 = ca.vertcat(ll * ca.sin(q[0]), -ll * ca.cos(q[0]))
    r2 = r1 + ca.vertcat(ll * ca.sin(q[1]), -ll * ca.cos(q[1]))
    v1, v2 = _vel(r1, q, qd, t), _vel(r2, q, qd, t)
    T = 0.5 * mm * (ca.dot(v1, v1) + ca.dot(v2, v2))
    V = mm * gg * (r1[1] + r2[1])
    return E.from_lagrangian("DoublePendulum", ["th1", "th2"], ["m", "l", "g"], [m, l, g], q, qd, t, p, T, V,
                             q0=list(q0), qd0=list(qd0))


def pendulum(m=1.0, L=1.0, g=9.81, c=0.0, F=0.0, A=0.0, w=0.0, q0=0.5, qd0=0.0):
    """Point-mass pendulum; damping c (Rayleigh), constant horizontal force F at the bob,
    and a forcing torque A sin(w t)."""
    q, qd, t, p = _sym(1, 7)
    mm, LL, gg, cc, FF, AA, ww = (p[i] for i in range(7))
    r = ca.vertcat(LL * ca.sin(q[0]), -LL * ca.cos(q[0]))
    v = _vel(r, q, qd, t)
    T = 0.5 * mm * ca.dot(v, v)
    V = mm * gg * r[1]
    D = 0.5 * cc * qd[0] ** 2
    Q = ca.jacobian(r, q).T @ ca.vertcat(FF, 0) + AA * ca.sin(ww * t)
    return E.from_lagrangian("Pendulum", ["theta"], ["m", "L", "g", "c", "F", "A", "w"],
                             [m, L, g, c, F, A, w], q, qd, t, p, T, V, D=D, Q=Q, q0=[q0], qd0=[qd0])


def hoop(m=1.0, R=1.0, g=9.81, w=5.0, q0=0.3):
    """Bead on a hoop spinning at rate w about its vertical diameter (prescribed rotation)."""
    q, qd, t, p = _sym(1, 4)
    mm, RR, gg, ww = (p[i] for i in range(4))
    r = ca.vertcat(RR * ca.sin(q[0]) * ca.cos(ww * t), -RR * ca.cos(q[0]), RR * ca.sin(q[0]) * ca.sin(ww * t))
    v = _vel(r, q, qd, t)
    return E.from_lagrangian("Hoop", ["theta"], ["m", "R", "g", "w"], [m, R, g, w], q, qd, t, p,
                             0.5 * mm * ca.dot(v, v), mm * gg * r[1], q0=[q0])


def two_masses(m=2.0, k=50.0, l0=1.0, F=3.0, c=0.0):
    """Two masses on a line joined by a spring (and damper c); constant force F on mass 2."""
    q, qd, t, p = _sym(2, 5)
    mm, kk, ll, FF, cc = (p[i] for i in range(5))
    T = 0.5 * mm * ca.dot(qd, qd)
    V = 0.5 * kk * (q[1] - q[0] - ll) ** 2
    D = 0.5 * cc * (qd[1] - qd[0]) ** 2
    return E.from_lagrangian("TwoMasses", ["x1", "x2"], ["m", "k", "l0", "F", "c"], [m, k, l0, F, c],
                             q, qd, t, p, T, V, D=D, Q=ca.vertcat(0, FF), q0=[0.0, l0])


def cart_pole(M=1.0, m=0.1, l=1.0, g=9.81, uniform=False, q0=(0.0, 0.1)):
    """Cart (x) with a pole hinged on it, theta from the upward vertical.

    uniform=False: point mass m at distance l on a massless rod; True: uniform rod of length l.
    The force on the cart is the parameter F (generalized force on x).
    """
    q, qd, t, p = _sym(2, 5)
    MM, mm, ll, gg, FF = (p[i] for i in range(5))
    x, th = q[0], q[1]
    rc = ca.vertcat(x, 0)
    if uniform:
        rg = ca.vertcat(x - ll / 2 * ca.sin(th), ll / 2 * ca.cos(th))
        vg = _vel(rg, q, qd, t)
        T = 0.5 * MM * qd[0] ** 2 + 0.5 * mm * ca.dot(vg, vg) + 0.5 * (mm * ll ** 2 / 12) * qd[1] ** 2
        V = mm * gg * rg[1]
    else:
        rb = ca.vertcat(x - ll * ca.sin(th), ll * ca.cos(th))
        vb = _vel(rb, q, qd, t)
        T = 0.5 * MM * qd[0] ** 2 + 0.5 * mm * ca.dot(vb, vb)
        V = mm * gg * rb[1]
    del rc
    return E.from_lagrangian("CartPole", ["x", "theta"], ["M", "m", "l", "g", "F"], [M, m, l, g, 0.0],
                             q, qd, t, p, T, V, Q=ca.vertcat(FF, 0), q0=list(q0))


def kepler(mu=1.0, m=1.0, e=0.6, a=1.0):
    """A planet around a fixed centre (plane, Cartesian), started at perihelion of an orbit
    of eccentricity e and semi-major axis a; period 2 pi sqrt(a^3/mu)."""
    q, qd, t, p = _sym(2, 2)
    r = ca.sqrt(q[0] ** 2 + q[1] ** 2)
    T = 0.5 * p[1] * ca.dot(qd, qd)
    V = -p[0] * p[1] / r
    rp = a * (1 - e)
    vp = math.sqrt(mu * (1 + e) / (a * (1 - e)))
    return E.from_lagrangian("Kepler", ["x", "y"], ["mu", "m"], [mu, m], q, qd, t, p, T, V,
                             q0=[rp, 0.0], qd0=[0.0, vp])


def two_body(m1=1.0, m2=0.5, G=1.0, e=0.6, a=1.0):
    """Two free bodies in a plane under mutual gravitation (a free planetary system); the
    relative orbit has eccentricity e, semi-major axis a; centre of mass at rest at 0."""
    q, qd, t, p = _sym(4, 3)
    M1, M2, GG = p[0], p[1], p[2]
    r = ca.sqrt((q[2] - q[0]) ** 2 + (q[3] - q[1]) ** 2)
    T = 0.5 * M1 * (qd[0] ** 2 + qd[1] ** 2) + 0.5 * M2 * (qd[2] ** 2 + qd[3] ** 2)
    V = -GG * M1 * M2 / r
    mu = G * (m1 + m2)
    rp = a * (1 - e)
    vp = math.sqrt(mu * (1 + e) / (a * (1 - e)))
    f1, f2 = m2 / (m1 + m2), m1 / (m1 + m2)
    return E.from_lagrangian("TwoBody", ["x1", "y1", "x2", "y2"], ["m1", "m2", "G"], [m1, m2, G], q, qd, t, p,
                             T, V, q0=[-f1 * rp, 0, f2 * rp, 0], qd0=[0, -f1 * vp, 0, f2 * vp])


def _rot(axis, a):
    c, s = ca.cos(a), ca.sin(a)
    if axis == "z":
        return ca.vertcat(ca.horzcat(c, -s, 0), ca.horzcat(s, c, 0), ca.horzcat(0, 0, 1))
    return ca.vertcat(ca.horzcat(1, 0, 0), ca.horzcat(0, c, -s), ca.horzcat(0, s, c))


def heavy_top(m=1.0, l=0.5, g=9.81, I1=0.3, I3=0.2, q0=(0.0, 0.6, 0.0), qd0=(1.0, 0.0, 20.0)):
    """Heavy symmetric top, fixed tip, z-x-z Euler angles (phi precession, theta nutation, psi
    spin); the angular velocity comes from R'R_dot of the rotation matrix, so T is not
    simplified (phi and psi cancel only through sin^2 + cos^2 = 1)."""
    q, qd, t, p = _sym(3, 5)
    mm, ll, gg, A, C = (p[i] for i in range(5))
    R = _rot("z", q[0]) @ _rot("x", q[1]) @ _rot("z", q[2])
    Rd = ca.reshape(ca.jacobian(ca.vec(R), q) @ qd, 3, 3)
    W = R.T @ Rd
    w = ca.vertcat(W[2, 1], W[0, 2], W[1, 0])
    T = 0.5 * ca.dot(w, ca.diag(ca.vertcat(A, A, C)) @ w)
    V = mm * gg * (R @ ca.vertcat(0, 0, ll))[2]
    return E.from_lagrangian("HeavyTop", ["phi", "theta", "psi"], ["m", "l", "g", "I1", "I3"],
                             [m, l, g, I1, I3], q, qd, t, p, T, V, q0=list(q0), qd0=list(qd0))


def rotating_saddle(m=1.0, k=1.0, W=2.0):
    """A particle in a frame rotating at W about z, in the saddle potential k/2 (x^2 - y^2)
    fixed in that frame (coordinates in the rotating frame): gyroscopic terms T1."""
    q, qd, t, p = _sym(2, 3)
    mm, kk, ww = p[0], p[1], p[2]
    vx = qd[0] - ww * q[1]
    vy = qd[1] + ww * q[0]
    T = 0.5 * mm * (vx ** 2 + vy ** 2)
    V = 0.5 * kk * (q[0] ** 2 - q[1] ** 2)
    return E.from_lagrangian("RotatingSaddle", ["x", "y"], ["m", "k", "W"], [m, k, W], q, qd, t, p, T, V,
                             q0=[0.01, 0.0])


def quartic(m=1.0, a=1.0):
    """x'' = -4 a x^3: zero Hessian at the origin (stable, but not by Lagrange-Dirichlet's test)."""
    q, qd, t, p = _sym(1, 2)
    return E.from_lagrangian("Quartic", ["x"], ["m", "a"], [m, a], q, qd, t, p, 0.5 * p[0] * qd[0] ** 2,
                             p[1] * q[0] ** 4, q0=[0.3])


def simulate_symplectic(eom, t_end, method="stormer-verlet", **kw):
    """A fixed-step run in canonical variables through the one simulation layer (the settings'
    ``fixed_step`` group: dt, newton_tol, max_newton)."""
    from mechdsl.simulate import simulate

    return simulate(eom, t_end, method=method, **kw)
