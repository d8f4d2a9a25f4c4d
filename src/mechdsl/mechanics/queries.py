"""Resolution of the IR's kinematic leaves (PointPos, PointVel, BodyRot, BodyOmega,
EnergyRef, ReactionRef, PointAcc, BodyAlpha) to SX, for exprs.CasadiEnv(query=...)."""
from __future__ import annotations

from typing import Callable

from ..model import exprs, ir
from ..diagnostics import Diagnostic, MechError
from .kinematics import Kinematics


class Query:
    def __init__(self, model: ir.Model, kin: Kinematics):
        self.model = model
        self.kin = kin
        self.energies: dict[str, object] | None = None       # set once T, V, D are known
        self.reaction: Callable[[ir.ReactionRef], object] | None = None
        self.constraint_load: Callable[[ir.ConstraintLoad], object] | None = None
        self.acceleration: Callable[[object], object] | None = None   # SX (q, qd, t) -> its d/dt
        self._bodies = {b.name for b in model.bodies} | {"world"}

    def _point(self, name):
        if name not in self.kin.tree._points:
            raise MechError(Diagnostic("E707", f"unknown point '{name}'"))
        return name

    def _body(self, name):
        if name not in self._bodies:
            raise MechError(Diagnostic("E715", f"unknown body '{name}'"))
        return name

    def __call__(self, n: ir.Expr):
        k = self.kin
        if isinstance(n, ir.PointPos):
            return k.point_pos(self._point(n.point))[n.i]
        if isinstance(n, ir.PointVel):
            return k.point_vel(self._point(n.point))[n.i]
        if isinstance(n, ir.BodyRot):
            return k.body_rot(self._body(n.body))[n.i, n.j]
        if isinstance(n, ir.BodyOmega):
            if n.frame == "body":
                return k.body_omega_body(self._body(n.body))[n.i]
            return k.body_omega(self._body(n.body))[n.i]
        if isinstance(n, (ir.PointAcc, ir.BodyAlpha)):
            if self.acceleration is None:
                raise MechError(Diagnostic("E725", f"the acceleration {exprs.to_text(n)} used inside a force or term",
                                           help="accelerations may appear in outputs only"))
            if isinstance(n, ir.PointAcc):
                return self.acceleration(("a", n.point), lambda: k.point_vel(self._point(n.point)))[n.i]
            return self.acceleration(("alpha", n.body), lambda: k.body_omega(self._body(n.body)))[n.i]
        if isinstance(n, ir.EnergyRef):
            if self.energies is None:
                raise MechError(Diagnostic("E723", f"{n.kind} energy used inside a force or energy term",
                                           help="energies may appear in outputs only"))
            if n.kind not in self.energies:
                raise MechError(Diagnostic("E724", f"unknown energy '{n.kind}'"))
            return self.energies[n.kind]
        if isinstance(n, ir.ReactionRef):
            if self.reaction is None:
                raise MechError(Diagnostic("E725", f"reaction of joint '{n.joint}' used inside a force or term",
                                           help="reactions may appear in outputs only"))
            return self.reaction(n)
        if isinstance(n, ir.ConstraintLoad):
            if self.constraint_load is None:
                raise MechError(Diagnostic("E725", f"constraint_{n.what}({n.constraint}, {n.body}) used inside a "
                                                   "force or term", help="constraint forces may appear in outputs only"))
            return self.constraint_load(n)
        raise MechError(Diagnostic("E726", f"cannot evaluate {type(n).__name__} here"))
