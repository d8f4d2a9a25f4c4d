"""Per-link steps of the recursive algorithms as cached CasADi Functions.

Building SX from Python costs ~25 us per operation (the SWIG layer), so a 50-link ABA written
op by op takes a good part of a second.  Each per-link step is therefore written once with
the spatial helpers on symbolic placeholders, wrapped in an SX Function, and *called* on the
actual SX arguments: the call expands the step in C++ (one Python call per link and pass),
and CasADi's element-level simplification (x*0 -> 0, x*1 -> x, constant folding) still prunes
everything the structural zeros of a joint axis or an inertia allow.
"""
from __future__ import annotations

from functools import lru_cache

import casadi as ca

from .spatial import Inertia, crf, crm, cross, force_to_parent, inv_small, motion_to_child, skew

_S = ca.SX.sym


def _fn(name, ins, outs):
    return ca.Function(name, [x for _, x in ins], outs, [n for n, _ in ins], [f"o{i}" for i in range(len(outs))])


@lru_cache(maxsize=None)
def kin_step(k: int, root: bool) -> ca.Function:
    """(E, r, R_parent, o_parent, w_parent, v_parent, Sw, Sv, nu, jw0, jv0) ->
    (R, o, w, v, jw, jv): world pose and link-coordinate velocity of a link."""
    E, r, Rl, ol, wl, vl = _S("E", 3, 3), _S("r", 3), _S("Rl", 3, 3), _S("ol", 3), _S("wl", 3), _S("vl", 3)
    Sw, Sv, nu, jw0, jv0 = _S("Sw", 3, k), _S("Sv", 3, k), _S("nu", k), _S("jw0", 3), _S("jv0", 3)
    jw, jv = ca.mtimes(Sw, nu) + jw0, ca.mtimes(Sv, nu) + jv0
    if root:
        R, o, w, v = Rl @ E, ol + Rl @ r, jw, jv
    else:
        wc, vc = motion_to_child(E, r, wl, vl)
        R, o, w, v = Rl @ E, ol + Rl @ r, wc + jw, vc + jv
    return _fn("kin_step", [("E", E), ("r", r), ("Rl", Rl), ("ol", ol), ("wl", wl), ("vl", vl),
                            ("Sw", Sw), ("Sv", Sv), ("nu", nu), ("jw0", jw0), ("jv0", jv0)],
               [R, o, w, v, jw, jv])


@lru_cache(maxsize=None)
def aba_p1() -> ca.Function:
    """(w, v, A, B, C, fn, ff, jw, jv, aJw, aJv) -> (pn, pf, cw, cv): bias force v x* I v - f_ext
    and bias acceleration c = a_J + v x v_J."""
    w, v, A, B, C = _S("w", 3), _S("v", 3), _S("A", 3, 3), _S("B", 3, 3), _S("C", 3, 3)
    fn, ff, jw, jv, aw, av = (_S(n, 3) for n in ("fn", "ff", "jw", "jv", "aw", "av"))
    I = Inertia(A, B, C)
    hw, hv = I.times(w, v)
    pn, pf = crf(w, v, hw, hv)
    cw, cv = crm(w, v, jw, jv)
    return _fn("aba_p1", [("w", w), ("v", v), ("A", A), ("B", B), ("C", C), ("fn", fn), ("ff", ff),
                          ("jw", jw), ("jv", jv), ("aw", aw), ("av", av)],
               [pn - fn, pf - ff, cw + aw, cv + av])


@lru_cache(maxsize=None)
def aba_p2(k: int) -> ca.Function:
    """(A, B, C, pn, pf, cw, cv, Sw, Sv, tau, E, r) -> (A', B', C', pn', pf', Uw, Uv, Di, u):
    articulated inertia and bias force handed to the parent (already in parent coordinates)."""
    A, B, C = _S("A", 3, 3), _S("B", 3, 3), _S("C", 3, 3)
    pn, pf, cw, cv = _S("pn", 3), _S("pf", 3), _S("cw", 3), _S("cv", 3)
    Sw, Sv, tau, E, r = _S("Sw", 3, k), _S("Sv", 3, k), _S("tau", k), _S("E", 3, 3), _S("r", 3)
    I = Inertia(A, B, C)
    if k:
        Uw = A @ Sw + B @ Sv
        Uv = B.T @ Sw + C @ Sv
        D = Sw.T @ Uw + Sv.T @ Uv
        Di = inv_small(D)
        u = tau - (Sw.T @ pn + Sv.T @ pf)
        UDw, UDv = Uw @ Di, Uv @ Di
        Ia = Inertia(A - UDw @ Uw.T, B - UDw @ Uv.T, C - UDv @ Uv.T)
        iw, iv = Ia.times(cw, cv)
        Du = Di @ u
        pan, paf = pn + iw + Uw @ Du, pf + iv + Uv @ Du
    else:
        Uw, Uv, Di, u = ca.SX(3, 0), ca.SX(3, 0), ca.SX(0, 0), ca.SX(0, 1)
        Ia = I
        iw, iv = I.times(cw, cv)
        pan, paf = pn + iw, pf + iv
    Ip = Ia.to_parent(E, r)
    ppn, ppf = force_to_parent(E, r, pan, paf)
    return _fn("aba_p2", [("A", A), ("B", B), ("C", C), ("pn", pn), ("pf", pf), ("cw", cw), ("cv", cv),
                          ("Sw", Sw), ("Sv", Sv), ("tau", tau), ("E", E), ("r", r)],
               [Ip.A, Ip.B, Ip.C, ppn, ppf, Uw, Uv, Di, u])


@lru_cache(maxsize=None)
def aba_p3(k: int, root: bool) -> ca.Function:
    """(E, r, aw_parent, av_parent, cw, cv, Uw, Uv, Di, u, Sw, Sv) -> (nu', aw, av)."""
    E, r, awl, avl, cw, cv = _S("E", 3, 3), _S("r", 3), _S("awl", 3), _S("avl", 3), _S("cw", 3), _S("cv", 3)
    Uw, Uv, Di, u, Sw, Sv = _S("Uw", 3, k), _S("Uv", 3, k), _S("Di", k, k), _S("u", k), _S("Sw", 3, k), _S("Sv", 3, k)
    if root:
        aw, av = cw, cv
    else:
        aw, av = motion_to_child(E, r, awl, avl)
        aw, av = aw + cw, av + cv
    nud = Di @ (u - (Uw.T @ aw + Uv.T @ av)) if k else ca.SX(0, 1)
    aw, av = aw + Sw @ nud, av + Sv @ nud
    return _fn("aba_p3", [("E", E), ("r", r), ("awl", awl), ("avl", avl), ("cw", cw), ("cv", cv),
                          ("Uw", Uw), ("Uv", Uv), ("Di", Di), ("u", u), ("Sw", Sw), ("Sv", Sv)],
               [nud, aw, av])


@lru_cache(maxsize=None)
def rnea_fwd(k: int, root: bool) -> ca.Function:
    """(E, r, aw_parent, av_parent, cw, cv, Sw, Sv, nud, A, B, C, w, v, fn, ff) -> (aw, av, n, f):
    link acceleration and the net force I a + v x* I v - f_ext."""
    E, r, awl, avl, cw, cv = _S("E", 3, 3), _S("r", 3), _S("awl", 3), _S("avl", 3), _S("cw", 3), _S("cv", 3)
    Sw, Sv, nud = _S("Sw", 3, k), _S("Sv", 3, k), _S("nud", k)
    A, B, C, w, v, fn, ff = _S("A", 3, 3), _S("B", 3, 3), _S("C", 3, 3), _S("w", 3), _S("v", 3), _S("fn", 3), _S("ff", 3)
    if root:
        aw, av = cw, cv
    else:
        aw, av = motion_to_child(E, r, awl, avl)
        aw, av = aw + cw, av + cv
    aw, av = aw + Sw @ nud, av + Sv @ nud
    I = Inertia(A, B, C)
    iaw, iav = I.times(aw, av)
    hw, hv = I.times(w, v)
    xn, xf = crf(w, v, hw, hv)
    return _fn("rnea_fwd", [("E", E), ("r", r), ("awl", awl), ("avl", avl), ("cw", cw), ("cv", cv),
                            ("Sw", Sw), ("Sv", Sv), ("nud", nud), ("A", A), ("B", B), ("C", C),
                            ("w", w), ("v", v), ("fn", fn), ("ff", ff)],
               [aw, av, iaw + xn - fn, iav + xf - ff])


@lru_cache(maxsize=None)
def rnea_bwd(k: int) -> ca.Function:
    """(E, r, n, f, Sw, Sv) -> (S^T f, n_parent, f_parent)."""
    E, r, n, f, Sw, Sv = _S("E", 3, 3), _S("r", 3), _S("n", 3), _S("f", 3), _S("Sw", 3, k), _S("Sv", 3, k)
    tau = Sw.T @ n + Sv.T @ f
    pn, pf = force_to_parent(E, r, n, f)
    return _fn("rnea_bwd", [("E", E), ("r", r), ("n", n), ("f", f), ("Sw", Sw), ("Sv", Sv)], [tau, pn, pf])


@lru_cache(maxsize=None)
def inertia_up() -> ca.Function:
    """(E, r, A, B, C) -> the inertia in parent coordinates."""
    E, r, A, B, C = _S("E", 3, 3), _S("r", 3), _S("A", 3, 3), _S("B", 3, 3), _S("C", 3, 3)
    Ip = Inertia(A, B, C).to_parent(E, r)
    return _fn("inertia_up", [("E", E), ("r", r), ("A", A), ("B", B), ("C", C)], [Ip.A, Ip.B, Ip.C])


@lru_cache(maxsize=None)
def crba_col(k: int) -> ca.Function:
    """(A, B, C, Sw, Sv) -> (Fw, Fv, S^T F): composite-inertia forces of a joint's columns."""
    A, B, C, Sw, Sv = _S("A", 3, 3), _S("B", 3, 3), _S("C", 3, 3), _S("Sw", 3, k), _S("Sv", 3, k)
    Fw, Fv = A @ Sw + B @ Sv, B.T @ Sw + C @ Sv
    return _fn("crba_col", [("A", A), ("B", B), ("C", C), ("Sw", Sw), ("Sv", Sv)], [Fw, Fv, Sw.T @ Fw + Sv.T @ Fv])


@lru_cache(maxsize=None)
def force_up(k: int) -> ca.Function:
    """(E, r, Fw, Fv) -> (Fw, Fv) in parent coordinates, for k force columns."""
    E, r, Fw, Fv = _S("E", 3, 3), _S("r", 3), _S("Fw", 3, k), _S("Fv", 3, k)
    Fv2 = E @ Fv
    Fw2 = E @ Fw + skew(r) @ Fv2
    return _fn("force_up", [("E", E), ("r", r), ("Fw", Fw), ("Fv", Fv)], [Fw2, Fv2])


@lru_cache(maxsize=None)
def project(k: int, kf: int) -> ca.Function:
    """(Sw, Sv, Fw, Fv) -> S^T F (k x kf)."""
    Sw, Sv, Fw, Fv = _S("Sw", 3, k), _S("Sv", 3, k), _S("Fw", 3, kf), _S("Fv", 3, kf)
    return _fn("project", [("Sw", Sw), ("Sv", Sv), ("Fw", Fw), ("Fv", Fv)], [Sw.T @ Fw + Sv.T @ Fv])


@lru_cache(maxsize=None)
def kinetic() -> ca.Function:
    """(A, B, C, w, v) -> 1/2 (w, v) . I (w, v)."""
    A, B, C, w, v = _S("A", 3, 3), _S("B", 3, 3), _S("C", 3, 3), _S("w", 3), _S("v", 3)
    hw, hv = Inertia(A, B, C).times(w, v)
    return _fn("kinetic", [("A", A), ("B", B), ("C", C), ("w", w), ("v", v)], [0.5 * (ca.dot(w, hw) + ca.dot(v, hv))])


@lru_cache(maxsize=None)
def point_pos() -> ca.Function:
    R, o, r = _S("R", 3, 3), _S("o", 3), _S("r", 3)
    return _fn("point_pos", [("R", R), ("o", o), ("r", r)], [o + R @ r])


@lru_cache(maxsize=None)
def point_vel() -> ca.Function:
    R, w, v, r = _S("R", 3, 3), _S("w", 3), _S("v", 3), _S("r", 3)
    return _fn("point_vel", [("R", R), ("w", w), ("v", v), ("r", r)], [R @ (v + cross(w, r))])


@lru_cache(maxsize=None)
def point_force() -> ca.Function:
    """(R, r, F_world) -> (n, f) in link coordinates about the link origin."""
    R, r, F = _S("R", 3, 3), _S("r", 3), _S("F", 3)
    f = R.T @ F
    return _fn("point_force", [("R", R), ("r", r), ("F", F)], [cross(r, f), f])


@lru_cache(maxsize=None)
def rigid_inertia() -> ca.Function:
    """(m, c, Ic) -> (A, B, C) of a rigid body (Ic about the centre of mass c)."""
    m, c, Ic = _S("m"), _S("c", 3), _S("Ic", 3, 3)
    I = Inertia.rigid(m, c, Ic)
    return _fn("rigid_inertia", [("m", m), ("c", c), ("Ic", Ic)], [I.A, I.B, I.C])
