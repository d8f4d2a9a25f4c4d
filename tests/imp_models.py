"""Hand-built equations of motion (eom.from_lagrangian, CasADi SX) for the impact tests.

Each builder returns an EOM whose ``point_position`` knows the model's named points, so
contacts can be given as ``ir.Contact`` objects exactly as the front end produces them.
"""
from __future__ import annotations

import casadi as ca
import numpy as np

from mechdsl.model import ir
from mechdsl.eom import from_lagrangian

C = ir.Const


def _sym(n, np_):
    return ca.SX.sym("q", n), ca.SX.sym("qd", n), ca.SX.sym("t"), ca.SX.sym("p", np_)


def ball(h0=1.0, e=0.8, g=9.81, m=1.0, r=0.0):
    """A point mass falling along y (1 dof) onto the floor y = 0 (contact 'floor' on point 'ball')."""
    q, qd, t, p = _sym(1, 3)
    pts = {"ball": ca.vertcat(0, q[0], 0), "world": ca.SX.zeros(3)}
    eom = from_lagrangian("Ball", ["y"], ["m", "g", "e"], [m, g, e], q, qd, t, p,
                          T=0.5 * p[0] * qd[0] ** 2, V=p[0] * p[1] * q[0], q0=[h0], qd0=[0.0],
                          point_position=lambda n: pts[n])
    floor = ir.Contact("floor", "plane", (("point", "ball"), ("radius", C(r)), ("surface", "plane"),
                                          ("normal", (C(0), C(1), C(0))), ("offset", C(0)), ("e", ir.Param("e"))))
    return eom, floor


def pendulum(L=1.0, g=9.81, m=1.0, theta0=-1.0, omega0=0.0):
    """Planar pendulum, angle theta from the downward vertical; the bob is the point 'bob'."""
    q, qd, t, p = _sym(1, 3)
    bob = ca.vertcat(p[1] * ca.sin(q[0]), -p[1] * ca.cos(q[0]), 0)
    pts = {"bob": bob, "world": ca.SX.zeros(3)}
    eom = from_lagrangian("Pendulum", ["theta"], ["m", "L", "g"], [m, L, g], q, qd, t, p,
                          T=0.5 * p[0] * p[1] ** 2 * qd[0] ** 2, V=-p[0] * p[2] * p[1] * ca.cos(q[0]),
                          q0=[theta0], qd0=[omega0], point_position=lambda n: pts[n])
    return eom


def wall(x_wall, e):
    """A wall x <= x_wall for the point 'bob' (normal -x, offset -x_wall)."""
    return ir.Contact("wall", "plane", (("point", "bob"), ("surface", "plane"), ("normal", (C(-1), C(0), C(0))),
                                        ("offset", C(-x_wall)), ("e", C(e))))


def cartesian_pendulum(L=1.0, g=9.81, m=1.0, theta0=-1.0):
    """The pendulum in Cartesian coordinates (x, y) with the constraint x^2 + y^2 = L^2 (a DAE)."""
    q, qd, t, p = _sym(2, 3)
    pts = {"bob": ca.vertcat(q[0], q[1], 0), "world": ca.SX.zeros(3)}
    eom = from_lagrangian("CartesianPendulum", ["x", "y"], ["m", "L", "g"], [m, L, g], q, qd, t, p,
                          T=0.5 * p[0] * ca.sumsqr(qd), V=p[0] * p[2] * q[1],
                          g=q[0] ** 2 + q[1] ** 2 - p[1] ** 2,
                          q0=[L * np.sin(theta0), -L * np.cos(theta0)], qd0=[0.0, 0.0],
                          point_position=lambda n: pts[n])
    return eom


def cradle(N=3, L=1.0, r=0.05, g=9.81, m=0.1, theta0=-0.3, e=1.0):
    """Newton's cradle: N pendulums of length L hung 2r apart, balls of radius r touching at rest.

    Ball 1 is released from theta0; contacts 'c1'..'c{N-1}' between neighbours (surface 'point').
    """
    q, qd, t, p = _sym(N, 4)
    mm, LL, gg, rr = p[0], p[1], p[2], p[3]
    pts = {"world": ca.SX.zeros(3)}
    T = 0
    V = 0
    for i in range(N):
        x = 2 * rr * i + LL * ca.sin(q[i])
        y = -LL * ca.cos(q[i])
        pts[f"b{i + 1}"] = ca.vertcat(x, y, 0)
        T += 0.5 * mm * LL ** 2 * qd[i] ** 2
        V += mm * gg * y
    q0 = [theta0] + [0.0] * (N - 1)
    eom = from_lagrangian(f"Cradle{N}", [f"th{i + 1}" for i in range(N)], ["m", "L", "g", "r"], [m, L, g, r],
                          q, qd, t, p, T=T, V=V, q0=q0, qd0=[0.0] * N, point_position=lambda n: pts[n])
    contacts = [ir.Contact(f"c{i + 1}", "point", (("point", f"b{i + 1}"), ("radius", ir.Param("r")),
                                                  ("surface", "point"), ("center", f"b{i + 2}"),
                                                  ("surface_radius", ir.Param("r")), ("e", C(e))))
                for i in range(N - 1)]
    return eom, contacts


def particle_sphere(R=1.0, g=9.81, m=1.0, theta0=0.1, inside=False, speed0=0.0):
    """A particle (x, y) on the sphere of radius R about the origin, at angle theta0 from the top
    (outside) or from the bottom (inside), moving along the surface with speed speed0."""
    q, qd, t, p = _sym(2, 3)
    pts = {"particle": ca.vertcat(q[0], q[1], 0), "world": ca.SX.zeros(3)}
    s, c = np.sin(theta0), np.cos(theta0)
    if inside:
        q0, v0 = [R * s, -R * c], [speed0 * c, speed0 * s]
    else:
        q0, v0 = [R * s, R * c], [speed0 * c, -speed0 * s]
    eom = from_lagrangian("ParticleSphere", ["x", "y"], ["m", "R", "g"], [m, R, g], q, qd, t, p,
                          T=0.5 * p[0] * ca.sumsqr(qd), V=p[0] * p[2] * q[1], q0=q0, qd0=v0,
                          point_position=lambda n: pts[n])
    sphere = ir.Contact("sphere", "sphere", (("point", "particle"), ("surface", "sphere"), ("center", "world"),
                                             ("surface_radius", ir.Param("R")), ("inside", C(1.0 if inside else 0.0)),
                                             ("e", C(0.0))))
    return eom, sphere


def planar_rod(L=1.0, m=1.0, g=9.81, phi0=0.5, y0=1.0, vx0=0.0, vy0=0.0, w0=0.0):
    """A uniform rod in the plane: centre (x, y), angle phi from the x axis; ends 'a' (at -L/2 along
    the rod) and 'b' (at +L/2).  I = m L^2 / 12."""
    q, qd, t, p = _sym(3, 3)
    mm, LL, gg = p[0], p[1], p[2]
    x, y, ph = q[0], q[1], q[2]
    d = ca.vertcat(ca.cos(ph), ca.sin(ph), 0) * LL / 2
    c = ca.vertcat(x, y, 0)
    pts = {"a": c - d, "b": c + d, "rod": c, "world": ca.SX.zeros(3)}
    T = 0.5 * mm * (qd[0] ** 2 + qd[1] ** 2) + 0.5 * (mm * LL ** 2 / 12) * qd[2] ** 2
    eom = from_lagrangian("Rod", ["x", "y", "phi"], ["m", "L", "g"], [m, L, g], q, qd, t, p,
                          T=T, V=mm * gg * y, q0=[0.0, y0, phi0], qd0=[vx0, vy0, w0],
                          point_position=lambda n: pts[n])
    return eom


def floor_at(point, e, name=None):
    return ir.Contact(name or f"floor_{point}", "plane",
                      (("point", point), ("surface", "plane"), ("normal", (C(0), C(1), C(0))), ("offset", C(0)),
                       ("e", C(e))))


def ball_closed_form(h0, e, g, n):
    """Impact times t_k and impact speeds v_k (k = 1..n) of a ball dropped from rest at h0."""
    v = np.sqrt(2 * g * h0)
    times, speeds = [np.sqrt(2 * h0 / g)], [v]
    for _ in range(n - 1):
        v *= e
        times.append(times[-1] + 2 * v / g)
        speeds.append(v)
    return np.array(times), np.array(speeds)


def ball_height(t, h0, e, g, n_max=200):
    """Closed-form height of the bouncing ball at times t (before it comes to rest)."""
    times, speeds = ball_closed_form(h0, e, g, n_max)
    out = []
    for tt in np.atleast_1d(t):
        if tt <= times[0]:
            out.append(h0 - 0.5 * g * tt ** 2)
            continue
        k = np.searchsorted(times, tt) - 1
        s = tt - times[k]
        v = e * speeds[k]
        out.append(v * s - 0.5 * g * s ** 2)
    return np.array(out)


def stack(r=0.1, h=1.0, g=9.81, m=1.0, e=1.0):
    """Two balls on a vertical line: the lower one rests on the floor, the upper one is dropped
    onto it from height h (centre distance 2r + h)."""
    q, qd, t, p = _sym(2, 3)
    pts = {"b1": ca.vertcat(0, q[0], 0), "b2": ca.vertcat(0, q[1], 0), "world": ca.SX.zeros(3)}
    eom = from_lagrangian("Stack", ["y1", "y2"], ["m", "g", "r"], [m, g, r], q, qd, t, p,
                          T=0.5 * p[0] * ca.sumsqr(qd), V=p[0] * p[1] * (q[0] + q[1]),
                          q0=[r, 3 * r + h], qd0=[0.0, 0.0], point_position=lambda n: pts[n])
    floor = ir.Contact("floor", "plane", (("point", "b1"), ("radius", ir.Param("r")), ("surface", "plane"),
                                          ("normal", (C(0), C(1), C(0))), ("e", C(e))))
    touch = ir.Contact("touch", "point", (("point", "b2"), ("radius", ir.Param("r")), ("surface", "point"),
                                          ("center", "b1"), ("surface_radius", ir.Param("r")), ("e", C(e))))
    return eom, [floor, touch]


def pendulum_swing_time(th_a, th_b, amp, L, g):
    """Time for a pendulum of amplitude amp to swing from th_a to th_b (monotonic part, |th| <= amp)."""
    from scipy.special import ellipkinc

    k = np.sin(amp / 2)
    phi = lambda th: np.arcsin(np.clip(np.sin(th / 2) / k, -1, 1))  # noqa: E731
    return np.sqrt(L / g) * abs(ellipkinc(phi(th_b), k * k) - ellipkinc(phi(th_a), k * k))


def pendulum_wall_impacts(n, L, g, th0, thw, e):
    """Closed form of a pendulum released at rest from th0 < thw against a wall at thw:
    the first n impact times and the angular speeds just before them."""
    amp = abs(th0)
    t = pendulum_swing_time(th0, thw, amp, L, g)
    times, omegas = [], []
    for _ in range(n):
        w = np.sqrt(2 * g / L * (np.cos(thw) - np.cos(amp)))
        times.append(t)
        omegas.append(w)
        amp = np.arccos(np.cos(thw) - L * (e * w) ** 2 / (2 * g))   # rebound with e w: new amplitude
        t += 2 * pendulum_swing_time(thw, -amp, amp, L, g)
    return np.array(times), np.array(omegas)
