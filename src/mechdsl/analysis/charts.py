"""Local charts of rotation joints for the analyses (equilibria, linearization).

A unit quaternion block q (4 coordinates, |q| = 1) has three degrees of freedom; the
equations of motion of a quaternion joint carry a fourth, artificial direction along q (the
norm), in which M is regularized and the forces are projected away.  Analyses therefore work
in the tangent space: about a reference q* the chart

    q(w) = q* (x) u(w),     u(w) = (1, w/2) / sqrt(1 + |w|^2/4)

(w: a rotation vector in child axes, so dq = 1/2 G(q*)' dw at w = 0) is smooth and regular
everywhere, has unit norm identically, and its Jacobian J(w) is orthogonal to q(w).  The
equations in w are therefore exact:  J' M J w'' = J'(bias(q(w), J w') - M dJ/dt w'),  because
J' q = 0 removes both the regularization term mu q q' of M and the component along q.  Other
coordinates z_i = q_i - q*_i.  The resulting EOM (``chart``) is an ordinary EOM in independent
coordinates, so the classification and the linearization of :mod:`.equilibrium` and
:mod:`.linearize` apply unchanged.

Euler angles are singular at gimbal lock (det of the joint's motion subspace = 0, the
``<joint>.gimbal`` monitor of the EOM).  There the model is derived again with those joints in
quaternions (``quaternion_model``) and analysed in the quaternion chart above: the switch of
charts away from the singularity.
"""
from __future__ import annotations

import dataclasses

import numpy as np

from ..diagnostics import Diagnostic, MechError
from ..mechanics import derive
from ..mechanics.rotations import euler_sequence
from ..model import ir
from ..model.exprs import walk


LOCK_TOL = 1e-6          # |det S| below this: gimbal lock


def quaternion_blocks(eom) -> list[tuple[str, list[int]]]:
    """(joint name, coordinate indices in order q0..q3) of every quaternion block of the EOM."""
    def build():
        import casadi as ca

        out = []
        for name, expr in eom.invariants.items():
            if not name.endswith(".quaternion_norm"):
                continue
            dep = [i for i, d in enumerate(ca.which_depends(ca.SX(expr), eom.q, 1, False)) if d]
            if len(dep) == 4:
                out.append((name[: -len(".quaternion_norm")], dep))
        return out

    return eom.workspace.memo("quaternion_blocks", build)


def normalize_blocks(q: np.ndarray, blocks, fallback: np.ndarray | None = None) -> np.ndarray | None:
    """q with every quaternion block scaled to unit norm and its sign made canonical (the first
    component above 1e-9 positive: q and -q are one rotation); None if a block is ~0 and no
    fallback is given."""
    q = np.array(q, float)
    for _, idx in blocks:
        b = q[idx]
        nb = float(np.linalg.norm(b))
        if not np.isfinite(nb) or nb < 1e-9:
            if fallback is None:
                return None
            b, nb = np.array(fallback[idx], float), float(np.linalg.norm(fallback[idx]))
            if nb < 1e-9:
                b, nb = np.array([1.0, 0.0, 0.0, 0.0]), 1.0
        b = b / nb
        for x in b:
            if abs(x) > 1e-9:
                if x < 0:
                    b = -b
                break
        q[idx] = b
    return q


def block_distance(a: np.ndarray, b: np.ndarray, idx) -> float:
    """Distance of two quaternion blocks as rotations (q and -q are the same)."""
    return float(min(np.max(np.abs(a[idx] - b[idx])), np.max(np.abs(a[idx] + b[idx]))))


def left_matrix(p) -> np.ndarray:
    """L(p) with p (x) u = L(p) u (Hamilton product, scalar first)."""
    p0, p1, p2, p3 = p
    return np.array([[p0, -p1, -p2, -p3], [p1, p0, -p3, p2], [p2, p3, p0, -p1], [p3, -p2, p1, p0]], float)


def tangent_basis(q: np.ndarray, blocks, n: int) -> np.ndarray:
    """Z (n x (n - 4b + 3b)) with dq = Z dz: unit columns for ordinary coordinates, 1/2 G(q)'
    (rotation vector in child axes) for each quaternion block."""
    quat = {i for _, idx in blocks for i in idx}
    cols = []
    first = {idx[0]: idx for _, idx in blocks}
    for i in range(n):
        if i in first:
            L = left_matrix(q[first[i]])
            for k in range(1, 4):
                c = np.zeros(n)
                c[first[i]] = 0.5 * L[:, k]
                cols.append(c)
        elif i not in quat:
            c = np.zeros(n)
            c[i] = 1.0
            cols.append(c)
    return np.array(cols).T if cols else np.zeros((n, 0))


def chart_names(eom, blocks) -> tuple[str, ...]:
    quat = {i for _, idx in blocks for i in idx}
    first = {idx[0]: j for j, idx in blocks}
    out = []
    for i, c in enumerate(eom.coords):
        if i in first:
            out += [f"{first[i]}.rx", f"{first[i]}.ry", f"{first[i]}.rz"]
        elif i not in quat:
            out.append(c)
    return tuple(out)


def chart(eom, qstar: np.ndarray):
    """The EOM in the chart about ``qstar`` (module docstring); its coordinates are
    ``chart_names``, z = 0 at qstar.  Cached per reference point."""
    qstar = np.asarray(qstar, float)
    return eom.workspace.memo(("chart", qstar.tobytes()), lambda: _chart(eom, qstar))


def _chart(eom, qstar):
    import casadi as ca

    blocks = quaternion_blocks(eom)
    n = eom.n
    names = chart_names(eom, blocks)
    nz = len(names)
    z = ca.SX.sym("z", nz)
    zd = ca.SX.sym("zd", nz)
    quat = {i for _, idx in blocks for i in idx}
    first = {idx[0]: idx for _, idx in blocks}
    qz = [None] * n
    j = 0
    for i in range(n):
        if i in first:
            w = z[j:j + 3]
            u = ca.vertcat(1, w / 2) / ca.sqrt(1 + ca.dot(w, w) / 4)
            qb = ca.mtimes(ca.DM(left_matrix(qstar[first[i]])), u)
            for a, k in enumerate(first[i]):
                qz[k] = qb[a]
            j += 3
        elif i not in quat:
            qz[i] = qstar[i] + z[j]
            j += 1
    qz = ca.vertcat(*qz)
    J = ca.jacobian(qz, z)
    qdz = ca.mtimes(J, zd)
    Jdot_zd = ca.mtimes(ca.jacobian(qdz, z), zd)

    def sub(x):
        return ca.substitute(ca.substitute(ca.SX(x), eom.qd, qdz), eom.q, qz)

    M = sub(eom.M)
    Mr = ca.mtimes([J.T, M, J])
    bias = ca.mtimes(J.T, sub(eom.bias) - ca.mtimes(M, Jdot_zd))
    Q = ca.mtimes(J.T, sub(eom.Q))
    zeros = np.zeros(nz)
    return eom.replace(coords=names, q=z, qd=zd, T=sub(eom.T), V=sub(eom.V), D=sub(eom.D), Q=Q,
                       M=0.5 * (Mr + Mr.T), bias=bias, qdd=None, g=None, constraint_names=(),
                       outputs={}, q0=ca.SX(zeros), qd0=ca.SX(zeros), fixed_q=(True,) * nz,
                       fixed_qd=(True,) * nz, route="lagrange", singularity_monitors={}, invariants={},
                       lam=None, reactions={}, point_position=None, point_velocity=None)


def chart_speeds(qstar, qd, blocks, n) -> np.ndarray:
    """Chart speeds z' at z = 0 of the coordinate speeds qd (least squares on the blocks:
    the component along q, which a unit quaternion cannot have, is dropped)."""
    Z = tangent_basis(qstar, blocks, n)
    return np.linalg.lstsq(Z, np.asarray(qd, float), rcond=None)[0]


# --------------------------------------------------------------------------- gimbal lock


def locked_joints(eom, q, t, pv) -> list[str]:
    """Euler-angle joints at (or within LOCK_TOL of) gimbal lock at q."""
    import casadi as ca

    out = []
    for name, expr in eom.singularity_monitors.items():
        if not name.endswith(".gimbal"):
            continue
        f = eom.workspace.memo(("monitor", name), lambda e=expr: ca.Function("m", [eom.q, eom.t, eom.p], [ca.SX(e)]))
        v = float(f(q, t, pv))
        if np.isfinite(v) and abs(v) < LOCK_TOL:
            out.append(name[: -len(".gimbal")])
    return out


def _lock_error(joint, why):
    return MechError(Diagnostic("E908", f"the Euler angles of joint '{joint}' are at gimbal lock here and "
                                        f"the model cannot be analysed in another chart: {why}",
                                help="use parametrization = \"quaternion\" for this joint (no singularity), "
                                     "or another Euler sequence whose singularity is elsewhere"))


def quaternion_model(eom, joints: list[str]):
    """The EOM of the same model with the Euler-angle joints ``joints`` in quaternions, and a
    function mapping coordinate vectors of ``eom`` to coordinate vectors of the new one
    (derived once per EOM and set of joints)."""
    return eom.workspace.memo(("quaternion_model", tuple(joints)), lambda: _quaternion_model(eom, list(joints)))


def _quaternion_model(eom, joints: list[str]):
    model = eom.model
    if model is None:
        raise _lock_error(joints[0], "the equations do not come from a component model")
    angle_of: dict[str, tuple[str, str]] = {}        # coordinate -> (joint, role)
    new_joints = []
    coord_new: dict[str, list[ir.Coordinate]] = {}
    for j in model.joints:
        if j.name not in joints:
            new_joints.append(j)
            continue
        roles = {v.role: v for v in j.variables}
        rot = [roles.get(r) for r in ("phi", "theta", "psi")]
        if any(v is None or v.coordinate is None for v in rot):
            raise _lock_error(j.name, "its angles are not all plain coordinates")
        names = [f"{j.name}.q{k}" for k in range(4)]
        for v in rot:
            angle_of[v.coordinate] = (j.name, v.role)
        coord_new[rot[0].coordinate] = [ir.Coordinate(name=nm, start=ir.ONE if k == 0 else ir.ZERO, owner=j.name)
                                        for k, nm in enumerate(names)]
        keep = tuple(v for v in j.variables if v.role not in ("phi", "theta", "psi"))
        qv = tuple(ir.JointVar(role=f"q{k}", motion=ir.Coord(nm), coordinate=nm) for k, nm in enumerate(names))
        opts = tuple((k, v) for k, v in j.options if k not in ("parametrization", "sequence"))
        new_joints.append(dataclasses.replace(j, variables=keep + qv,
                                              options=opts + (("parametrization", "quaternion"),)))
    used = _coords_used_outside_joints(model)
    clash = sorted(set(angle_of) & used)
    if clash:
        raise _lock_error(angle_of[clash[0]][0], f"coordinate '{clash[0]}' is used in equations, forces or "
                                                 "constraints of its own")
    coords = []
    for c in model.coordinates:
        if c.name in coord_new:
            coords += coord_new[c.name]
        elif c.name not in angle_of:
            coords.append(c)
    new = dataclasses.replace(model, coordinates=tuple(coords), joints=tuple(new_joints), outputs=())
    try:
        qe = derive(new)
    except MechError as e:
        raise _lock_error(joints[0], e.diagnostics[0].message) from None
    seqs = {j.name: j.option("sequence", "zyx") for j in model.joints if j.name in joints}
    old_index = {c: i for i, c in enumerate(eom.coords)}

    def to_new(q):
        out = np.zeros(qe.n)
        for i, c in enumerate(qe.coords):
            if c in old_index:
                out[i] = q[old_index[c]]
        for jn in joints:
            ang = {role: q[old_index[c]] for c, (jj, role) in angle_of.items() if jj == jn}
            quat = euler_to_quaternion(seqs[jn], ang["phi"], ang["theta"], ang["psi"])
            for k in range(4):
                out[qe.coords.index(f"{jn}.q{k}")] = quat[k]
        return out

    return qe, to_new


def _coords_used_outside_joints(model) -> set[str]:
    used: set[str] = set()

    def scan(obj):
        if isinstance(obj, ir.Expr):
            for e in walk(obj):
                if isinstance(e, ir.Coord):
                    used.add(e.name)
        elif isinstance(obj, (tuple, list)):
            for x in obj:
                scan(x)
        elif dataclasses.is_dataclass(obj) and not isinstance(obj, type):
            for f in dataclasses.fields(obj):
                scan(getattr(obj, f.name))

    scan(model.forces)
    scan(model.terms)
    scan(model.constraints)
    scan(model.contacts)
    scan(model.loops)
    scan(tuple(v.motion for j in model.joints for v in j.variables if v.coordinate is None))
    return used


def _axis_rot(k: int, a: float) -> np.ndarray:
    c, s = np.cos(a), np.sin(a)
    i, j = (k + 1) % 3, (k + 2) % 3
    R = np.eye(3)
    R[i, i] = R[j, j] = c
    R[i, j], R[j, i] = -s, s
    return R


def euler_to_quaternion(seq: str, phi: float, theta: float, psi: float) -> np.ndarray:
    """Unit quaternion of the intrinsic Euler rotation R_a(phi) R_b(theta) R_c(psi)."""
    a, b, c = euler_sequence(seq)
    return matrix_to_quaternion(_axis_rot(a, phi) @ _axis_rot(b, theta) @ _axis_rot(c, psi))


def matrix_to_quaternion(R: np.ndarray) -> np.ndarray:
    """Unit quaternion (scalar first) of a rotation matrix (Shepperd's method)."""
    tr = np.trace(R)
    k = int(np.argmax([tr, R[0, 0], R[1, 1], R[2, 2]]))
    if k == 0:
        s = 2.0 * np.sqrt(1.0 + tr)
        q = [s / 4, (R[2, 1] - R[1, 2]) / s, (R[0, 2] - R[2, 0]) / s, (R[1, 0] - R[0, 1]) / s]
    elif k == 1:
        s = 2.0 * np.sqrt(1.0 + 2 * R[0, 0] - tr)
        q = [(R[2, 1] - R[1, 2]) / s, s / 4, (R[0, 1] + R[1, 0]) / s, (R[0, 2] + R[2, 0]) / s]
    elif k == 2:
        s = 2.0 * np.sqrt(1.0 + 2 * R[1, 1] - tr)
        q = [(R[0, 2] - R[2, 0]) / s, (R[0, 1] + R[1, 0]) / s, s / 4, (R[1, 2] + R[2, 1]) / s]
    else:
        s = 2.0 * np.sqrt(1.0 + 2 * R[2, 2] - tr)
        q = [(R[1, 0] - R[0, 1]) / s, (R[0, 2] + R[2, 0]) / s, (R[1, 2] + R[2, 1]) / s, s / 4]
    q = np.array(q)
    return q / np.linalg.norm(q)


# --------------------------------------------------------------------------- Euler twins


def euler_blocks(eom) -> list[tuple[list[int], bool, str]]:
    """([i_phi, i_theta, i_psi], proper, joint name) of every Euler-angle joint whose three
    angles are coordinates; proper: a sequence like z-x-z (first axis = last axis)."""
    def build():
        model = eom.model
        out = []
        if model is None:
            return out
        for j in model.joints:
            if j.kind not in ("spherical", "free") or j.option("parametrization", "euler").lower() != "euler":
                continue
            roles = {v.role: v.coordinate for v in j.variables}
            idx = [roles.get(r) for r in ("phi", "theta", "psi")]
            if any(c is None or c not in eom.coords for c in idx):
                continue
            try:
                a, _, c = euler_sequence(j.option("sequence", "zyx"))
            except ValueError:
                continue
            out.append(([eom.coords.index(c) for c in idx], a == c, j.name))
        return out

    return eom.workspace.memo("euler_blocks", build)


def euler_twin(q: np.ndarray, block) -> np.ndarray:
    """The other Euler angles of the same rotation: (phi + pi, pi - theta, psi + pi) for
    Tait-Bryan sequences, (phi + pi, -theta, psi + pi) for proper Euler sequences."""
    (i, j, k), proper = block[0], block[1]
    out = np.array(q, float)
    out[i] += np.pi
    out[j] = -out[j] if proper else np.pi - out[j]
    out[k] += np.pi
    return out
