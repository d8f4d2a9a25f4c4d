"""Classification of an equilibrium (analysis.equilibrium): kind (static, relative,
accelerated reference), stability from the Hessian of the (effective) potential transverse to the
symmetry directions, with the linearized eigenvalues as the second witness; in a chart for
quaternion joints and Euler angles at gimbal lock; continuous families of equilibria as neutral
directions."""
from __future__ import annotations

from types import SimpleNamespace

import numpy as np

from ..eom import multiplier_units
from ..model.units import coordinate_units, matrix_units
from .charts import chart, locked_joints, quaternion_blocks, quaternion_model
from .charts import tangent_basis as zbasis
from .constraints import constrained, tangent_basis
from .core import dense, null_space, parts, structure
from .equilibrium_record import Equilibrium
from .lm import levenberg_marquardt
from .matrices import complement, reduced_first_order, second_order, sym


def chart_of(eom, q, t, pv):
    """(EOM in the chart about q, its structure, chart reference point, basis Z with dq = Z dz
    in the coordinates of the chart's EOM, the EOM the chart belongs to, notes) for a model with
    quaternion joints or Euler angles at gimbal lock; None for a regular point of ordinary
    coordinates."""
    blocks = quaternion_blocks(eom)
    locked = locked_joints(eom, q, t, pv) if not constrained(eom) else []
    if not blocks and not locked:
        return None
    notes = []
    base, qb = eom, np.asarray(q, float)
    if locked:
        base, to_new = quaternion_model(eom, locked)
        qb = to_new(qb)
        blocks = quaternion_blocks(base)
        notes.append(f"the Euler angles of {', '.join(locked)} are at gimbal lock here: analysed in a "
                     "quaternion chart instead (rotation vectors <joint>.rx, .ry, .rz in child axes)")
    else:
        notes.append("quaternion joint(s): analysed in the tangent space of the unit quaternion(s) "
                     "(rotation vectors <joint>.rx, .ry, .rz in child axes)")
    ch = chart(base, qb)
    st0 = structure(base, pv)
    keep = [i for i in range(base.n) if not any(i in idx for _, idx in blocks)]
    N = st0.symmetry
    cols = [c for c in N.T if np.max(np.abs(np.delete(c, keep)), initial=0.0) <= 1e-12]
    Z = zbasis(qb, blocks, base.n)
    Nc = np.array([Z.T @ c for c in cols]).T if cols else np.zeros((ch.n, 0))
    per = [False] * ch.n
    ang = [False] * ch.n
    j = 0
    for i in range(base.n):
        if i in keep:
            per[j], ang[j] = st0.periodic[i], st0.angle_unit[i]
            j += 1
        elif any(i == idx[0] for _, idx in blocks):
            j += 3
    import dataclasses

    st = dataclasses.replace(st0, n=ch.n, periodic=tuple(per), angle_unit=tuple(ang), symmetry=Nc)
    return ch, st, qb, Z, base, notes


def classify_in_chart(eom, st, pv, qs, alpha, t, resid, notes, blocks, locked) -> Equilibrium:
    """Classification in the chart of :func:`chart_of`; continuous families of equilibria
    through the point (a top's rotation about the vertical) are neutral directions, like
    symmetry directions."""
    ch, stc, qb, Z, base, more = chart_of(eom, qs, t, pv)
    nz = ch.n
    k = stc.symmetry.shape[1]
    if locked and not k:
        # at gimbal lock dV/d(angles) = J' grad V vanishes where J loses rank: a point that is
        # no equilibrium in a regular chart is an artefact of the Euler angles
        _, bias = parts(ch).M_bias(np.zeros(nz), np.zeros(nz), t, pv)
        if np.max(np.abs(bias), initial=0.0) > 1e-8 * max(st.force_scale, 1e-300):
            return None
    a = np.zeros(k)
    if k and len(alpha) == st.symmetry.shape[1]:
        a = np.linalg.lstsq(stc.symmetry, Z.T @ (st.symmetry @ alpha) if base is eom else np.zeros(nz),
                            rcond=None)[0]
    stc, a, fam_notes = with_families(ch, stc, pv, np.zeros(nz), t, a)
    e = classify(ch, stc, pv, np.zeros(nz), a, t, resid, notes + more + fam_notes)
    e.coords, e.q, e.chart_coords = tuple(eom.coords), np.asarray(qs, float), tuple(ch.coords)
    e.tangent_basis = Z if base is eom else None
    e.acceleration = np.zeros(eom.n) if not k else (st.symmetry @ alpha)
    return e


def with_families(eom, st, pv, q, t, alpha):
    """(structure, alpha, notes) with the directions along a continuous family of equilibria
    through q added to the symmetry directions (neutral)."""
    import dataclasses

    fam = _family_directions(eom, st, pv, t, alpha, q)
    if not fam.shape[1]:
        return st, alpha, []
    Nold = st.symmetry
    k = Nold.shape[1]
    Nall = np.linalg.qr(np.hstack([Nold, fam]))[0] if k else fam
    a = np.linalg.lstsq(Nall, Nold @ alpha, rcond=None)[0] if k else np.zeros(Nall.shape[1])
    return (dataclasses.replace(st, symmetry=Nall), a,
            [f"{fam.shape[1]} direction(s) along a continuous family of equilibria through this point: neutral"])


def _family_directions(ch, st, pv, t, alpha, q=None) -> np.ndarray:
    """Orthonormal directions v of zero stiffness (transverse to the symmetry directions) along
    which the point q (default 0: a chart's centre) continues as a curve of equilibria: from
    q + s v (s = 0.2) Levenberg-Marquardt with the gauge v'(z - q) = s converges to an
    equilibrium.  Not for accelerated references."""
    import casadi as ca

    n = ch.n
    q = np.zeros(n) if q is None else np.asarray(q, float)
    N = st.symmetry
    M, C, K, _, _ = second_order(ch, q, np.zeros(n), t, pv, acc=np.zeros(n))
    # an accelerated reference motion (round-off in alpha is not one: as classify decides)
    if N.size and np.linalg.norm(M @ (N @ np.asarray(alpha, float))) > 1e-8 * max(st.force_scale, 1e-300):
        return np.zeros((n, 0))
    P = complement(N)
    Kr = sym(P.T @ K @ P)
    if not Kr.size:
        return np.zeros((n, 0))
    w, V = np.linalg.eigh(Kr)
    kscale = max(np.max(np.abs(K), initial=0.0), st.stiffness_scale, 1e-300)
    null = [P @ V[:, i] for i in range(len(w)) if abs(w[i]) <= 1e-9 * kscale]
    if not null:
        return np.zeros((n, 0))
    scale = max(st.force_scale, 1e-300)
    z = ca.SX.sym("z", n)
    rest = ca.substitute(ca.substitute(ch.bias, ch.qd, ca.SX.zeros(n)), ch.t, ca.SX(float(t)))
    f = ca.Function("fam", [z, ch.p], [ca.substitute(rest, ch.q, z)])
    keep = []
    for v in null:
        s = 0.2
        vv = ca.DM(v)
        r = ca.vertcat(ca.substitute(rest, ch.q, z) / scale, ca.mtimes(vv.T, z - ca.DM(q)) - s)
        F = ca.Function("famr", [z, ch.p], [r])
        JF = ca.Function("famj", [z, ch.p], [ca.jacobian(r, z)])
        try:
            x = levenberg_marquardt(lambda x: dense(F(x, pv)).ravel(), lambda x: dense(JF(x, pv)), q + s * v)
        except (ValueError, np.linalg.LinAlgError, FloatingPointError):
            x = None
        if x is None:
            continue
        res = dense(f(x, pv)).ravel()
        if np.all(np.isfinite(res)) and np.max(np.abs(res), initial=0.0) <= 1e-8 * scale \
                and abs(float(v @ (x - q)) - s) <= 1e-6:
            keep.append(v)
    if not keep:
        return np.zeros((n, 0))
    Q = np.linalg.qr(np.array(keep).T)[0]
    return Q


def classify(eom, st, pv, q, alpha, t, resid, notes, con=None, lam=None) -> Equilibrium:
    """Kind and stability.  Constrained models: K is the Hessian of V + lambda'g (the geometric
    stiffness of the constraint forces added) and everything is decided on the tangent space
    of the constraints (coordinates dq = Z dz, Z an orthonormal basis of null(G))."""
    n = eom.n
    N = st.symmetry
    k = N.shape[1]
    L = _reduced(eom, st, pv, q, alpha, t, con, lam)
    M, K, Kabs, Z, acc = L.M, L.K, L.Kabs, L.Z, L.acc
    Mt, Ct, Kt, Nt, R, P, Kr = L.Mt, L.Ct, L.Kt, L.Nt, L.R, L.P, L.Kr
    inert = L.inert
    if inert:
        notes = notes + [f"{inert} direction(s) carry neither inertia nor force here (the spin of a point "
                         "mass about its own axis): left out"]
    accel = bool(k) and np.linalg.norm(M @ acc) > 1e-8 * max(st.force_scale, 1e-300)
    if accel:
        kind = "accelerated-reference"
    elif st.scleronomic:
        kind = "static"
    else:
        kind = "relative"
    Ksym = sym(Kr)
    heig, vecs = np.linalg.eigh(Ksym) if Kr.size else (np.zeros(0), np.zeros((0, 0)))
    kscale = max(np.max(np.abs(K), initial=0.0), st.stiffness_scale, 1e-300)
    if con is not None:      # the geometric stiffness is of the order force scale x curvature
        kscale = max(kscale, st.force_scale * con.curvature_scale(q))
    circulatory = np.max(np.abs(Kt - Kt.T), initial=0.0) > 1e-7 * kscale
    massless = singular_mass(Mt)
    A = reduced_first_order(Mt, Ct, Kt, Nt) if not massless else np.zeros((0, 0))
    ev = np.linalg.eigvals(A) if A.size else np.zeros(0, complex)
    ev = ev[np.lexsort((ev.imag, ev.real))]
    lscale = max(1.0, np.max(np.abs(ev), initial=0.0))
    # each eigenvalue against the terms along its own direction u (full coordinates): |u|'|K||u|,
    # so that 5.96 beside a spring of 1e12 N/m is resolved (issue 23: a global 1e-9 x max|K| called
    # it zero); a floor at round-off of the largest terms anywhere
    B = (Z if Z is not None else np.eye(n)) @ (R if R is not None else np.eye(Kt.shape[0] + inert)) @ P
    U = np.abs(B @ vecs) if vecs.size else np.zeros((n, 0))
    etol = 1e-9 * np.einsum("ij,ik,kj->j", U, Kabs, U) + 1e-13 * kscale if heig.size else np.zeros(0)
    Csym = sym(Ct)
    gyro = np.max(np.abs(Ct - Ct.T), initial=0.0) > 1e-9 * max(np.max(np.abs(Ct), initial=0.0), 1e-300)
    damping_ok = np.min(np.linalg.eigvalsh(Csym), initial=0.0) >= -1e-9 * max(np.max(np.abs(Ct), initial=0.0), 1e-300)
    # the Hessian's eigenvalues have K's unit when every coordinate has the same unit
    hu = _unit_suffix(matrix_units(coordinate_units(eom)).get("K", ""))
    potential = "V - T0" if st.has_T0 else "V"
    if con is not None:
        potential += " + lambda'g on the constraint manifold"
    singular = con is not None and Z.shape[1] != n - con.ma
    if singular:
        notes = notes + ["singular configuration: the active constraints lose rank here, so the "
                         "multipliers are not unique"]

    growth = float(np.max(ev.real, initial=-np.inf)) if ev.size else -np.inf
    stable, reason = _stability(st, ev, growth, lscale, heig, etol, potential, hu, massless=massless,
                                singular=singular, circulatory=circulatory, damping_ok=damping_ok, symmetric=bool(k),
                                no_dof=con is not None and Z.shape[1] == 0)
    if gyro and stable is not None:
        notes = notes + ["gyroscopic terms present (T1 != 0)"]
    if accel:
        notes = notes + ["uniformly accelerated reference motion q(t) = q* + a t^2/2 with acceleration a = "
                         + ", ".join(f"{c}: {v:.6g}" + _unit_suffix(u and u + "/s2")
                                     for c, v, u in zip(eom.coords, acc, coordinate_units(eom)) if abs(v) > 0)]
    extra = {}
    if con is not None:
        extra = dict(multipliers=con.full_multipliers(lam), constraint_names=tuple(eom.constraint_names),
                     multiplier_units=multiplier_units(eom),
                     active_constraints=tuple(eom.constraint_names[i] for i in con.active), tangent_basis=Z)
    return Equilibrium(coords=tuple(eom.coords), q=np.asarray(q, float), stable=stable,
                       hessian_eigenvalues=heig, kind=kind, residual=resid, reason=reason, hessian=K,
                       acceleration=acc if k else np.zeros(n), linear_eigenvalues=ev,
                       symmetry_directions=N if k else None, t=float(t), notes=list(notes), **extra)


def _reduced(eom, st, pv, q, alpha, t, con, lam) -> SimpleNamespace:
    """The linearization about ``q`` (M, C, K; K with the constraint forces' geometric
    stiffness, Kabs the sizes of its terms; acc the reference acceleration along the symmetry
    directions) and its reduction: onto the constraints' tangent space (Z; Mt, Ct, Kt, Nt), the
    active directions (R), without inert ones (``inert`` of them), and the complement P of the
    symmetry directions (Kr = P'Kt P)."""
    n = eom.n
    N = st.symmetry
    k = N.shape[1]
    acc = N @ alpha if k else np.zeros(n)
    M, C, K, _, _ = second_order(eom, q, np.zeros(n), t, pv, acc=acc)
    if k and np.linalg.norm(M @ acc) <= 1e-8 * max(st.force_scale, 1e-300) and np.any(acc):
        # no force along N: alpha is arbitrary where N carries no inertia; the reference is at rest
        acc = np.zeros(n)
        M, C, K, _, _ = second_order(eom, q, np.zeros(n), t, pv, acc=acc)
    Z = None
    Kabs = np.abs(K)             # the sizes of the terms K adds up: what an eigenvalue is resolved against
    if con is not None:
        Kg = con.geometric_stiffness(q, lam)
        Kabs = Kabs + np.abs(Kg)
        K = K + Kg
        Z = tangent_basis(con.G_active(q))
        Mt, Ct, Kt, Nt = Z.T @ M @ Z, Z.T @ C @ Z, Z.T @ K @ Z, Z.T @ N
    else:
        Mt, Ct, Kt, Nt = M, C, K, N
    R = active_basis(Mt, Ct, Kt)
    Mt, Ct, Kt, Nt, inert = drop_inert(Mt, Ct, Kt, Nt)
    P = complement(Nt)
    return SimpleNamespace(M=M, C=C, K=K, Kabs=Kabs, Z=Z, acc=acc, Mt=Mt, Ct=Ct, Kt=Kt, Nt=Nt, R=R, inert=inert,
                           P=P, Kr=P.T @ Kt @ P)


def _stability(st, ev, growth, lscale, heig, etol, potential, hu, *, massless, singular, circulatory, damping_ok,
               symmetric, no_dof):
    """(stable: True / False / None when not decided, the reason) from the linearization's
    eigenvalues ``ev`` (largest real part ``growth``) and the reduced Hessian's ``heig``, each
    resolved against ``etol``, in the order the theorems apply: time dependence, a singular
    mass matrix or constraint Jacobian, a growing mode (Lyapunov), circulatory forces,
    Lagrange-Dirichlet, gyroscopic stabilization, nothing to decide, zero eigenvalues."""
    if not st.autonomous:
        stable, reason = None, "explicitly time-dependent equations: stability is not decided here"
    elif massless:
        stable, reason = None, (f"the mass matrix is singular here ({massless}) while forces act in that "
                                "direction: the equations of motion do not determine the motion, stability "
                                "is not decided")
    elif singular:
        stable, reason = None, "singular configuration of the constraints: stability is not decided here"
    elif growth > 1e-6 * lscale:
        i = int(np.argmax(ev.real))
        neg = heig[heig < -etol]
        why = (f"Hessian of {potential} has negative eigenvalue(s) {_fmt_list(neg)}{hu}; " if neg.size else "")
        stable, reason = False, (why + f"linearization has eigenvalue {_fmt_c(ev[i])} 1/s with positive "
                                       "real part (Lyapunov's indirect method)")
    elif circulatory:
        stable, reason = None, ("non-conservative positional (circulatory) forces: the stiffness is not "
                                "symmetric, Lagrange-Dirichlet does not apply; linear model has no growing mode")
    elif heig.size and np.all(heig > etol) and damping_ok:
        stable, reason = True, (f"Lagrange-Dirichlet: Hessian of {potential} positive definite "
                                f"(eigenvalues {_fmt_list(heig)}{hu})")
        if symmetric:
            reason += "; neutral along the symmetry directions"
    elif heig.size and np.any(heig < -etol):
        stable, reason = None, (f"Hessian of {potential} has negative eigenvalue(s) "
                                f"{_fmt_list(heig[heig < -etol])}{hu} but gyroscopic terms keep the linear "
                                "model bounded (gyroscopic stabilization): nonlinear stability undetermined")
    elif heig.size == 0 and no_dof:
        stable, reason = None, "no degree of freedom: the constraints fix the configuration"
    elif heig.size == 0:
        stable, reason = None, "no coordinate transverse to the symmetry directions: nothing to decide"
    elif np.any(np.abs(heig) <= etol):
        stable, reason = None, (f"zero eigenvalue(s) of the Hessian of {potential} "
                                f"({_fmt_list(heig[np.abs(heig) <= etol])}{hu}): higher-order terms decide")
    else:
        stable, reason = None, (f"Hessian of {potential} positive definite (eigenvalues {_fmt_list(heig)}) but "
                                "the damping matrix is not positive semidefinite (a force that feeds energy in "
                                "at some speeds): Lagrange-Dirichlet does not apply, and the linear model has no "
                                "growing mode; stability is not decided")
    return stable, reason


def drop_inert(M, C, K, N):
    """Leave out the directions that carry neither inertia nor force (M v = 0, K v = K'v = 0,
    C v = C'v = 0: a point mass spinning about its own axis); (M, C, K, N, count) in an
    orthonormal basis of the rest."""
    R = active_basis(M, C, K)
    if R is None:
        return M, C, K, N, 0
    Nr = R.T @ N
    if Nr.size:
        U, sv, _ = np.linalg.svd(Nr, full_matrices=False)
        Nr = U[:, sv > 1e-8]
    return R.T @ M @ R, R.T @ C @ R, R.T @ K @ R, Nr, M.shape[0] - R.shape[1]


def active_basis(M, C, K):
    """Orthonormal basis of the complement of the directions without inertia or force (None
    when there are none); columns that are coordinate axes are kept exactly."""
    n = M.shape[0]
    if n == 0:
        return None

    scale = max(np.max(np.abs(M), initial=0.0), 1e-300)
    ks = max(np.max(np.abs(K), initial=0.0), np.max(np.abs(C), initial=0.0), 1e-300)
    J = np.vstack([M / scale, K / ks, K.T / ks, C / ks, C.T / ks])
    inert = null_space(J, rel=1e-10)
    if inert.shape[1] == 0:
        return None
    R = complement(inert)
    R[np.abs(R) <= 1e-12] = 0.0
    return R


def singular_mass(M) -> str:
    """'' when M is invertible, else a description of its null direction."""
    if M.size == 0:
        return ""
    w, V = np.linalg.eigh(sym(M))
    if w[0] > 1e-12 * max(abs(w[-1]), 1e-300):
        return ""
    return f"smallest eigenvalue {w[0]:.3g} of {w[-1]:.3g}"


def _unit_suffix(unit: str) -> str:
    return f" {unit}" if unit else ""


def _fmt_list(v) -> str:
    return "[" + ", ".join(f"{x:.6g}" for x in v) + "]"


def _fmt_c(z: complex) -> str:
    return f"{z.real:.6g}" if abs(z.imag) < 1e-12 * max(1.0, abs(z)) else f"{z.real:.6g}{z.imag:+.6g}i"

