"""Vector start values of spatial joints and point masses (issue 17): `r(start = {..})`, `v(start = {..})` on a
Free joint and `omega(start = {..}, frame = "body" | "world")` on Spherical and Free joints.

They are converted here, as IR expressions in the parameters, into the start values and speeds
of the joint's own coordinates:

- `r`, `v`: the translation coordinates x, y, z and their speeds (the Free joint translates
  first, along the parent joint frame's axes, so they are the child point's position and
  velocity relative to the parent point, in parent axes).
- `omega`: the angular velocity of the child relative to the parent, in child body axes
  (`frame = "body"`) or in the parent's axes (`frame = "world"`; only for a joint whose parent
  is the world), turned into the chart's rates at the start orientation: for an Euler
  sequence abc (R = R_a(phi) R_b(theta) R_c(psi)) w_body = E(q) qd with the columns
  R_c^T R_b^T e_a, R_c^T e_b, e_c, solved by Cramer's rule (a gimbal-locked start, det E = 0, is
  refused by the flattener: E222); for a quaternion
  qd = G(q)^T w_body / 2 (w_body = 2 G qd / |q|^2, G G^T = |q|^2 1).

With oriented joint frames (rpy / R on the joint or its points, issue 26) the vectors are turned
into the joint frames' axes first: r, v and omega "world" by P^T (the parent joint frame's
axes), omega "body" by C^T (the child joint frame's axes in the child body).
"""
from __future__ import annotations

import dataclasses
from typing import TYPE_CHECKING

import numpy as np

from ..model import exprs as X
from ..model import ir
from ..model import units as U
from . import components as K
from . import values as V
from .components import rodrigues
from .evaluate import fail
from .mods import Mod
from .values import Arr, CompRef, Scalar, Str

if TYPE_CHECKING:
    from ..diagnostics import Span
    from .entries import CompInst

VECTOR_STARTS = {"Spherical": ("omega",), "Free": ("r", "v", "omega"), "PointMass": ("r", "v")}   # the modifiers

C = X.const
E = ((C(1.0), C(0.0), C(0.0)), (C(0.0), C(1.0), C(0.0)), (C(0.0), C(0.0), C(1.0)))
AXES = {"x": 0, "y": 1, "z": 2}


def _dot(a, b) -> ir.Expr:
    return X.add(X.add(X.mul(a[0], b[0]), X.mul(a[1], b[1])), X.mul(a[2], b[2]))


def _cross(a, b):
    return (X.sub(X.mul(a[1], b[2]), X.mul(a[2], b[1])), X.sub(X.mul(a[2], b[0]), X.mul(a[0], b[2])),
            X.sub(X.mul(a[0], b[1]), X.mul(a[1], b[0])))


def _mat_t_vec(R, v):
    """R^T v."""
    return tuple(_dot(tuple(R[i][j] for i in range(3)), v) for j in range(3))


def _matmul(A, B):
    return tuple(tuple(_dot(A[i], tuple(B[k][j] for k in range(3))) for j in range(3)) for i in range(3))


def _det(a, b, c) -> ir.Expr:
    return _dot(a, _cross(b, c))


def euler_rates(seq: str, angles, w, frame: str):
    """((phi', theta', psi'), det) of the intrinsic sequence `seq` at `angles` for the angular
    velocity w (child axes for frame 'body', parent axes for 'world'); det = det E(q), |det| <= 1,
    vanishes at gimbal lock."""
    a, b, c = (AXES[ch] for ch in seq)
    Ra, Rb, Rc = (rodrigues(E[k], ang) for k, ang in zip((a, b, c), angles))
    if frame == "world":
        w = _mat_t_vec(_matmul(_matmul(Ra, Rb), Rc), w)
    cols = (_mat_t_vec(Rc, _mat_t_vec(Rb, E[a])), _mat_t_vec(Rc, E[b]), E[c])
    det = _det(*cols)
    out = []
    for k in range(3):
        cs = list(cols)
        cs[k] = w
        out.append(X.div(_det(*cs), det))
    return tuple(out), det


def quaternion_rates(q, w, frame: str):
    """q' = G(q)^T w_body / 2 for the quaternion q = (q0, q1, q2, q3)."""
    q0, q1, q2, q3 = q
    if frame == "world":
        w = _mat_t_vec(_quat_matrix(q), w)
    G = ((X.neg(q1), q0, q3, X.neg(q2)), (X.neg(q2), X.neg(q3), q0, q1), (X.neg(q3), q2, X.neg(q1), q0))
    half = C(0.5)
    return tuple(X.mul(half, _dot(tuple(G[i][j] for i in range(3)), w)) for j in range(4))


def _quat_matrix(q):
    q0, q1, q2, q3 = q
    sq = lambda a: X.mul(a, a)  # noqa: E731
    two = lambda a, b: X.mul(C(2.0), X.mul(a, b))  # noqa: E731
    n2 = X.add(X.add(sq(q0), sq(q1)), X.add(sq(q2), sq(q3)))
    R = ((X.sub(X.add(sq(q0), sq(q1)), X.add(sq(q2), sq(q3))), X.sub(two(q1, q2), two(q0, q3)), X.add(two(q1, q3), two(q0, q2))),
         (X.add(two(q1, q2), two(q0, q3)), X.sub(X.add(sq(q0), sq(q2)), X.add(sq(q1), sq(q3))), X.sub(two(q2, q3), two(q0, q1))),
         (X.sub(two(q1, q3), two(q0, q2)), X.add(two(q2, q3), two(q0, q1)), X.sub(X.add(sq(q0), sq(q3)), X.add(sq(q1), sq(q2)))))
    return tuple(tuple(X.div(x, n2) for x in row) for row in R)


class VectorStarts:
    """The flattener's part (a mixin of :class:`~mechdsl.semantic.flatten.Flattener`): read the
    vector modifiers, check them and rewrite the coordinates' start values and speeds."""

    def _vector_starts(self, inst: CompInst, jvars: list[ir.JointVar], param: str) -> None:
        """`r(start = ..)`, `v(start = ..)`, `omega(start = .., frame = ..)` of a spatial joint:
        the start values and speeds of its own coordinates."""
        given = [(k, inst.entry.mod.sub[k]) for k in VECTOR_STARTS.get(inst.cls.name, ()) if k in inst.entry.mod.sub]
        if not given:
            return
        index = {c.name: i for i, c in enumerate(inst.coords)}
        own = {jv.role: jv.coordinate for jv in jvars if jv.coordinate == f"{inst.name}.{jv.role}"
               and jv.coordinate in index}
        roles = [jv.role for jv in jvars]
        for key, m in given:
            allowed = {"start", "frame"} if key == "omega" else {"start"}
            self._check_attrs(m, allowed)
            if m.value is not None or "start" not in m.sub:
                fail("E220", f"'{key}' of '{inst.name}' needs a start vector: {key}(start = {{..}})", m.span,
                     f"e.g. {key}(start = {{0, 0, 1}})")
            targets = [r for r in roles if (r in ("x", "y", "z")) == (key != "omega")]
            if key == "omega" and param == "euler":
                targets = [r for r in roles if r in ("phi", "theta", "psi")]
            missing = [r for r in targets if r not in own]
            if not targets or missing:
                fail("E220", f"'{key}' of '{inst.name}' sets the start of the joint's own coordinates, but "
                             + (f"'{missing[0]}' is bound to an expression" if missing else "the joint has none here"),
                     m.span, "give the start values on the coordinates the joint is bound to, or remove the binding"
                     if missing else "a Free joint with a point-mass child has no rotation coordinates")
            attr = "speed" if key in ("v", "omega") else "start"
            for r in targets:
                rm = inst.entry.mod.sub.get(r)
                if rm is not None and attr in rm.sub:
                    fail("E211", f"the {attr} of '{inst.name}.{r}' is set twice: by {r}({attr} = ..) and by {key}(..)",
                         rm.sub[attr].span, "remove one of them")
            vec = self._start_vector(inst, key, m, (3,))
            if key != "omega":
                new = dict(zip(targets, self._in_joint_axes(inst, vec, "parent")))
            else:
                frame = "body"
                if "frame" in m.sub:
                    fv = self.eval(m.sub["frame"].value)
                    frame = fv.value if isinstance(fv, Str) else None
                    if frame not in ("body", "world"):
                        fail("E217", (f"'{frame}' is not a valid frame of omega" if frame is not None else
                                      f"the frame of omega must be a string, got {V.describe_shape(fv)}"),
                             m.sub["frame"].value.span,
                             'frame = "body" (child body axes) or "world"')
                if frame == "world" and self._point_name_of(inst, "parent") != "world":
                    fail("E221", f"omega(frame = \"world\") of '{inst.name}' needs a joint whose parent is the world",
                         m.sub["frame"].span, 'give the angular velocity relative to the parent in the child\'s axes: '
                                              'frame = "body"')
                vec = self._in_joint_axes(inst, vec, "parent" if frame == "world" else "child")
                starts = [inst.coords[index[own[r]]].start for r in targets]
                if param == "euler":
                    seq = self.field_value(inst, "sequence").value  # type: ignore[union-attr]
                    rates, det = euler_rates(seq.strip().lower(), starts, vec, frame)
                    self._check_not_gimbal_locked(inst, seq, det, m.span)
                else:
                    rates = quaternion_rates(starts, vec, frame)
                new = dict(zip(targets, rates))
            for r, expr in new.items():
                i = index[own[r]]
                inst.coords[i] = dataclasses.replace(inst.coords[i], **{attr: expr})

    def _in_joint_axes(self, inst: CompInst, vec, side: str):
        """A vector given in the parent's (or child body's) axes, in the axes of the parent (child)
        joint frame, when that frame is oriented (rpy / R on the joint or its points)."""
        from .assemble import joint_axes
        from .orientation import transpose_times

        axes = joint_axes(self, inst)[0 if side == "parent" else 1]
        return tuple(vec) if axes is None else transpose_times(axes, tuple(vec))

    def _check_not_gimbal_locked(self, inst: CompInst, seq: str, det: ir.Expr, span: Span) -> None:
        """omega at a gimbal-locked start orientation has no Euler rates (or huge cancelling
        ones): refused with the parameter values of the file (E222)."""
        try:
            with np.errstate(all="ignore"):
                d = X.evaluate(det, dict(self.param_values))
        except (KeyError, ValueError, ZeroDivisionError, OverflowError):   # not known yet: the start check's job
            return
        if abs(d) < 1e-8:
            fail("E222", f"the start orientation of '{inst.name}' is at the gimbal lock of the Euler sequence "
                         f"'{seq}' (det = {d:.3g}): an angular velocity has no angle rates there", span,
                 'start away from the lock, or use parametrization = "quaternion"')

    def _start_vector(self, inst: CompInst, key: str, m: Mod, sizes: tuple[int, ...]) -> tuple[ir.Expr, ...]:
        """The expressions of `key(start = {..})`: a vector of one of `sizes`, in parameters."""
        sv = self.eval(m.sub["start"].value)
        want = {"r": U.LENGTH, "v": U.VELOCITY, "omega": U.dim(s=-1)}[key]
        if not isinstance(sv, Arr) or len(V.shape_of(sv)) != 1 or V.shape_of(sv)[0] not in sizes:
            fail("E301", f"the start of '{key}' of '{inst.name}' must be a vector of "
                         f"{' or '.join(map(str, sizes))}, got {V.describe_shape(sv)}",
                 m.sub["start"].value.span, f"write {key}(start = {{x, y, z}})")
        bad = next((it for it in sv.items if not isinstance(it, Scalar)), None)
        if bad is not None:
            fail("E301", f"the start of '{key}' of '{inst.name}' must be numbers, got {V.describe_shape(bad)}",
                 m.sub["start"].value.span, f"write {key}(start = {{x, y, z}})")
        for s in V.flatten(sv):
            self.check_dim(s, want, f"the start of '{key}' of '{inst.name}'", m.sub["start"].value.span)
            if X.depends_on_state(s.expr) or X.depends_on_time(s.expr):
                fail("E306", "the start value may only depend on parameters", m.sub["start"].value.span,
                     "start values are numbers or expressions in parameters")
        return tuple(s.expr for s in V.flatten(sv))

    def _cartesian_point_mass(self, inst: CompInst, span) -> ir.Joint | None:
        """A PointMass with `r(start = ..)` / `v(start = ..)` has Cartesian coordinates named after
        it (`bob.x`, `bob.y`[, `bob.z`]): a translation from the world, no rotation.  Two-vector
        starts give the plane motion in world x, y."""
        given = {k: inst.entry.mod.sub[k] for k in ("r", "v") if k in inst.entry.mod.sub}
        if not given:
            return None
        vecs = {}
        for key, m in given.items():
            self._check_attrs(m, {"start"})
            if m.value is not None or "start" not in m.sub:
                fail("E220", f"'{key}' of '{inst.name}' needs a start vector: {key}(start = {{..}})", m.span,
                     f"e.g. {key}(start = {{0, 0, 0}}) (a vector of 2 keeps the mass in the x, y plane)")
            vecs[key] = self._start_vector(inst, key, m, (2, 3))
        n = {len(v) for v in vecs.values()}
        if len(n) > 1:
            fail("E301", f"r and v of '{inst.name}' must have the same size", span, "give both with 2 or both with 3 entries")
        n = n.pop()
        zero = X.const(0.0)
        jvars = []
        for role in "xyz"[n:]:
            if role in inst.entry.mod.sub:
                fail("E204", f"'{inst.name}' moves in the x, y plane (r and v have 2 entries): it has no '{role}'",
                     inst.entry.mod.sub[role].name_span, "give r(start = {x, y, z}) for motion in space")
        for i, role in enumerate("xyz"[:n]):     # x(start = ..) (a scene, --set bob.x.start) wins over r's entry
            defaults = {attr: vecs[key][i] for key, attr in (("r", "start"), ("v", "speed")) if key in vecs}
            c = self._own_coordinate(inst, role, "m", f"{inst.name}.cartesian", defaults)
            inst.coords.append(c)
            jvars.append(ir.JointVar(role, ir.Coord(c.name), c.name))
        z_axis = (zero, zero, X.const(1.0))
        kind, plane = ("free", None) if n == 3 else ("planar", K.plane_axes(z_axis))
        return ir.Joint(f"{inst.name}.cartesian", kind, "world", inst.name, "world", inst.name, z_axis, tuple(jvars),
                        plane, None, None, (("parametrization", "euler"), ("sequence", "zyx")), False, span)

    def _point_name_of(self, inst: CompInst, fname: str) -> str:
        v = self.field_value(inst, fname)
        return self.body_of_point(v.name) if isinstance(v, CompRef) else ""
