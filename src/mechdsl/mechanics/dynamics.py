"""Recursive dynamics in CasADi SX over the link tree (Featherstone, body coordinates).

- ``aba``: articulated-body algorithm, forward dynamics nu' = f(q, qd, t, p), O(N), explicit
  (the only divisions are by the 1x1 or 3x3 articulated joint inertias D, inverted in closed
  form).  Prescribed joint motion enters as a known joint acceleration a_J.
- ``rnea``: recursive Newton-Euler inverse dynamics; with zero free accelerations it gives
  the bias C(q, qd, t) of M nu' + C = tau; with the forward dynamics it gives the joint forces
  (reactions).
- ``crba``: composite-rigid-body algorithm, the joint-space mass matrix M (exact, symmetric).

External forces are spatial forces per link (link coordinates about the link origin).  The
per-link steps are the cached Functions of ``templates``.
"""
from __future__ import annotations

import casadi as ca

from ..diagnostics import Diagnostic, MechError
from . import templates as tpl
from .kinematics import Kinematics
from .tree import Tree, z3


def _sub(vec, idx):
    return ca.vertcat(*[vec[k] for k in idx]) if idx else ca.SX(0, 1)


def _fext(fext, i):
    return fext.get(i, (z3(), z3()))


def _p1(tree: Tree, kin: Kinematics, fext: dict):
    """Per link: bias force p = v x* I v - f_ext and bias acceleration c = a_J + v x v_J."""
    out = []
    for lk in tree.links:
        i = lk.index
        I = lk.I
        fn, ff = _fext(fext, i)
        out.append(tpl.aba_p1()(kin.w[i], kin.v[i], I.A, I.B, I.C, fn, ff, kin.vJw[i], kin.vJv[i],
                                lk.known_aw, lk.known_av))
    return out


def _no_mass_hint(tree: Tree, joint) -> str:
    from ..eom.preflight import point_rotation_hint

    hint = point_rotation_hint(tree.model, joint)
    return hint or "a joint variable needs inertia beyond it (or prescribe its motion)"


def aba(tree: Tree, kin: Kinematics, fext: dict, tau) -> tuple[ca.SX, list]:
    """Forward dynamics: returns (nu', link accelerations [(aw, av)])."""
    links = tree.links
    n = len(links)
    p1 = _p1(tree, kin, fext)
    IA = [(lk.I.A, lk.I.B, lk.I.C) for lk in links]
    pA = [(x[0], x[1]) for x in p1]
    c = [(x[2], x[3]) for x in p1]
    saved = [None] * n
    for lk in reversed(links):
        i = lk.index
        A, B, C = IA[i]
        out = tpl.aba_p2(lk.k)(A, B, C, pA[i][0], pA[i][1], c[i][0], c[i][1], lk.S_w, lk.S_v,
                               _sub(tau, lk.dofs), lk.E, lk.r)
        Ap, Bp, Cp, pn, pf, Uw, Uv, Di, u = out
        if lk.k == 1 and Di.is_constant() and not Di.is_regular():
            raise MechError(Diagnostic("E730", f"joint '{lk.joint.name}' moves no mass", lk.joint.span,
                                       _no_mass_hint(tree, lk.joint)))
        saved[i] = (Uw, Uv, Di, u)
        lam = lk.parent
        if lam >= 0:
            a0, b0, c0 = IA[lam]
            IA[lam] = (a0 + Ap, b0 + Bp, c0 + Cp)
            pA[lam] = (pA[lam][0] + pn, pA[lam][1] + pf)
    nud = [None] * len(tree.dofs)
    acc: list[tuple] = [None] * n
    for lk in links:
        i, lam = lk.index, lk.parent
        root = lam < 0
        awl, avl = (z3(), z3()) if root else acc[lam]
        Uw, Uv, Di, u = saved[i]
        nd, aw, av = tpl.aba_p3(lk.k, root)(lk.E, lk.r, awl, avl, c[i][0], c[i][1], Uw, Uv, Di, u, lk.S_w, lk.S_v)
        for col, k in enumerate(lk.dofs):
            nud[k] = nd[col]
        acc[i] = (aw, av)
    return (ca.vertcat(*nud) if nud else ca.SX(0, 1)), acc


def rnea(tree: Tree, kin: Kinematics, fext: dict, nud=None) -> tuple[ca.SX, list]:
    """Inverse dynamics: returns (S^T f per speed, joint forces [(n, f)] per link).

    ``nud`` None: free accelerations zero (then the first result is the bias C)."""
    links = tree.links
    n = len(links)
    acc: list[tuple] = [None] * n
    f: list[tuple] = [None] * n
    p1 = _p1(tree, kin, {})          # only the bias accelerations c are used from here
    for lk in links:
        i, lam = lk.index, lk.parent
        root = lam < 0
        awl, avl = (z3(), z3()) if root else acc[lam]
        nd = _sub(nud, lk.dofs) if nud is not None else ca.SX.zeros(lk.k, 1)
        I = lk.I
        fn, ff = _fext(fext, i)
        aw, av, fi_n, fi_f = tpl.rnea_fwd(lk.k, root)(lk.E, lk.r, awl, avl, p1[i][2], p1[i][3], lk.S_w, lk.S_v,
                                                      nd, I.A, I.B, I.C, kin.w[i], kin.v[i], fn, ff)
        acc[i] = (aw, av)
        f[i] = (fi_n, fi_f)
    tau = [None] * len(tree.dofs)
    for lk in reversed(links):
        i, lam = lk.index, lk.parent
        t, pn, pf = tpl.rnea_bwd(lk.k)(lk.E, lk.r, f[i][0], f[i][1], lk.S_w, lk.S_v)
        for col, k in enumerate(lk.dofs):
            tau[k] = t[col]
        if lam >= 0:
            f[lam] = (f[lam][0] + pn, f[lam][1] + pf)
    return (ca.vertcat(*tau) if tau else ca.SX(0, 1)), f


def crba(tree: Tree) -> ca.SX:
    """Joint-space mass matrix by composite rigid bodies (symmetric by construction).

    One sweep from the leaves: a link's composite inertia times its motion subspace gives the
    force columns of its own speeds; the columns of its whole subtree travel to the parent
    together (one 3 x K transform per link, so O(N) Python calls), and the link's block row
    of M is S_i^T times those columns."""
    links = tree.links
    nv = len(tree.dofs)
    Ic = [(lk.I.A, lk.I.B, lk.I.C) for lk in links]
    for lk in reversed(links):
        if lk.parent >= 0:
            Ap, Bp, Cp = tpl.inertia_up()(lk.E, lk.r, *Ic[lk.index])
            a, b, c = Ic[lk.parent]
            Ic[lk.parent] = (a + Ap, b + Bp, c + Cp)
    M = ca.SX(nv, nv)
    sub: list = [None] * len(links)           # (Fw, Fv, columns) of the subtree, link coordinates
    children = tree.children()
    for lk in reversed(links):
        i = lk.index
        Fw, Fv, cols = [], [], []
        if lk.dofs:
            fw, fv, _ = tpl.crba_col(lk.k)(*Ic[i], lk.S_w, lk.S_v)
            Fw.append(fw)
            Fv.append(fv)
            cols += lk.dofs
        for c in children[i]:
            if sub[c] is not None:
                Fw.append(sub[c][0])
                Fv.append(sub[c][1])
                cols += sub[c][2]
                sub[c] = None
        if not cols:
            continue
        Fw, Fv = ca.horzcat(*Fw), ca.horzcat(*Fv)
        if lk.dofs:
            blk = ca.mtimes(lk.S_w.T, Fw) + ca.mtimes(lk.S_v.T, Fv)
            M[lk.dofs, cols] = blk
            M[cols, lk.dofs] = blk.T
        if lk.parent >= 0:
            Fv2 = ca.mtimes(lk.E, Fv)
            Fw2 = ca.mtimes(lk.E, Fw)
            if not all(lk.r[j].is_zero() for j in range(3)):
                Fw2 = Fw2 + ca.mtimes(ca.SX(ca.skew(lk.r)), Fv2)
            sub[i] = (Fw2, Fv2, cols)
    return M


def joint_reactions(tree: Tree, kin: Kinematics, fext: dict, nud) -> dict[str, tuple]:
    """Force and torque exerted by the parent on the child across every tree joint, in the
    child joint frame (about the child point): {joint name: (torque (3,), force (3,))}."""
    _, f = rnea(tree, kin, fext, nud)
    out = {}
    for lk in tree.links:
        if lk.body is not None:
            n, fo = f[lk.index]
            if lk.post is not None:      # body axes -> the child joint frame's axes
                n, fo = ca.mtimes(lk.post.T, n), ca.mtimes(lk.post.T, fo)
            out[lk.joint.name] = (n, fo)
    return out
