"""Recursive kinematics over the tree: world poses of every link, link velocities in link
coordinates, and the point/body queries that outputs and forces use."""
from __future__ import annotations

import casadi as ca

from . import templates as tpl
from .tree import Tree, z3

EYE = ca.SX.eye(3)


class Kinematics:
    def __init__(self, tree: Tree):
        self.tree = tree
        n = len(tree.links)
        self.R: list[ca.SX] = [None] * n          # link axes -> world axes
        self.o: list[ca.SX] = [None] * n          # link origin, world coordinates
        self.w: list[ca.SX] = [None] * n          # angular velocity, link coordinates
        self.v: list[ca.SX] = [None] * n          # velocity of the link origin, link coordinates
        self.vJw: list[ca.SX] = [None] * n        # joint velocity (free + prescribed), link coordinates
        self.vJv: list[ca.SX] = [None] * n
        self._memo: dict = {}
        nu = [d.nu for d in tree.dofs]
        for lk in tree.links:
            i, lam = lk.index, lk.parent
            nul = ca.vertcat(*[nu[k] for k in lk.dofs]) if lk.dofs else ca.SX(0, 1)
            root = lam < 0
            Rl, ol, wl, vl = (EYE, z3(), z3(), z3()) if root else (self.R[lam], self.o[lam], self.w[lam], self.v[lam])
            out = tpl.kin_step(lk.k, root)(lk.E, lk.r, Rl, ol, wl, vl, lk.S_w, lk.S_v, nul,
                                           lk.known_vw, lk.known_vv)
            self.R[i], self.o[i], self.w[i], self.v[i], self.vJw[i], self.vJv[i] = out

    # -- link-level ------------------------------------------------------------------
    def link_rot(self, i: int) -> ca.SX:
        return EYE if i < 0 else self.R[i]

    def link_pos(self, i: int, r) -> ca.SX:
        return r if i < 0 else tpl.point_pos()(self.R[i], self.o[i], r)

    def link_vel(self, i: int, r) -> ca.SX:
        if i < 0:
            return z3()
        return tpl.point_vel()(self.R[i], self.w[i], self.v[i], r)

    # -- named queries (memoized, so every use shares one SX subgraph) ----------------
    def point_pos(self, name: str) -> ca.SX:
        key = ("pos", name)
        if key not in self._memo:
            i, r = self.tree.point_in_link(name)
            self._memo[key] = self.link_pos(i, r)
        return self._memo[key]

    def point_vel(self, name: str) -> ca.SX:
        key = ("vel", name)
        if key not in self._memo:
            i, r = self.tree.point_in_link(name)
            self._memo[key] = self.link_vel(i, r)
        return self._memo[key]

    def body_rot(self, body: str) -> ca.SX:
        return self.link_rot(self.tree.body_link[body])

    def body_omega(self, body: str) -> ca.SX:
        key = ("omega", body)
        if key not in self._memo:
            i = self.tree.body_link[body]
            self._memo[key] = z3() if i < 0 else ca.mtimes(self.R[i], self.w[i])
        return self._memo[key]

    def body_omega_body(self, body: str) -> ca.SX:
        """Angular velocity in body axes (a link's axes are its body's axes)."""
        i = self.tree.body_link[body]
        return z3() if i < 0 else self.w[i]

    def com_link(self, body) -> tuple[int, ca.SX]:
        """(link, centre of mass in link coordinates) of an ir.Body."""
        return self.tree.body_link[body.name], self.tree.vec(body.com) - self.tree.body_offset[body.name]
