"""The linear model of a constrained model on its constraint manifold, in independent coordinates.

About a rest state q* (an equilibrium, or a configuration at rest with acceleration a*) of

    M(q) q'' = bias(q, q') - G(q)^T lambda,    g(q) = 0,

write the configurations near q* as q(z) = q* + Z z + M^-1 G^T w(z) with Z a basis of null(G)
at q* and w(z) = O(|z|^2) fixed by g(q(z)) = 0.  Projecting the equations onto T(z) = dq/dz
removes the multipliers (T^T G^T = 0), and at rest

    M_r = Z^T M Z,   C_r = Z^T C Z,   K_r = Z^T (K + sum_l lambda_l d2g_l/dq2) Z,   B_r = Z^T B

with M, C, K the matrices of the unconstrained linearization (``matrices.second_order``, K
including d(M a*)/dq) and lambda the multipliers at q*.  The sum is the geometric stiffness
of the constraint forces: the curvature of the manifold (the second-order part of q(z)) enters
through it.  At an equilibrium this holds for any parametrization; about a rest state with
a* != 0 the normal correction along M^-1 G^T (the mass-orthogonal one the DAE projection uses)
is what makes the term Z^T M (d2q/dz2) a* vanish.

Z is deterministic: the independent coordinates of a pivoted QR of the mass-scaled G
(``constraints.independent_basis``: dz are changes of those coordinates, Z[dep] = -G_dep^-1
G_indep), or an orthonormal basis of null(G) when that one is ill-conditioned.  States in
motion are refused: there the linear model on the manifold is time-varying.
"""
from __future__ import annotations

import re

import numpy as np

from ..dae.init import initialize
from ..diagnostics import Diagnostic, MechError, UsageError, did_you_mean
from ..eom import multiplier_units
from .constraints import independent_basis, project, rest_multipliers
from .core import parts, structure
from .equilibrium import nearest_equilibrium
from .equilibrium_classify import singular_mass
from .equilibrium_record import Equilibrium
from .linear_model import Linearization, declared_inputs, input_columns
from .matrices import first_order, second_order, singular_mass_error
from ..model.names import split_state


def _refuse_motion(eom, where: str):
    raise MechError(Diagnostic(
        "E901", f"a constrained model is linearized about a state at rest; {where}",
        help="linearize about an equilibrium (--at equilibrium, the default) or a configuration at rest "
             "(--at NAME=VALUE,...); a motion's linear model on the constraint manifold is time-varying"))


def rest_state(eom, con, at, q0, pv, t):
    """q* for a state given as 'start' or a dict (named coordinates held, the others moved onto
    the constraints); motion is refused."""
    n = eom.n
    if isinstance(at, dict):
        q = q0.copy()
        fixed = [False] * n
        for name, v in at.items():
            key, speed = split_state(name)
            if key not in eom.coords:
                hint = did_you_mean(key, eom.coords)
                raise UsageError(f"unknown coordinate {key!r}" + (f"; {hint}" if hint else ""))
            if speed:
                if float(v) != 0.0:
                    _refuse_motion(eom, f"the state given has der({key}) = {float(v):g}")
                continue
            q[eom.coords.index(key)] = float(v)
            fixed[eom.coords.index(key)] = True
        qp = _continued(eom, q0, q, fixed, t, pv)
        if qp is None:
            raise MechError(Diagnostic(
                "E901", f"the state {', '.join(f'{k} = {v:g}' for k, v in at.items())} cannot be brought "
                        f"onto the constraints of '{eom.name}' ({', '.join(eom.constraint_names)})",
                help="give values the mechanism can assemble in, or fewer of them"))
        return qp, t
    if isinstance(at, str):
        s = at.strip()
        if s == "start":
            rep = initialize(eom, t=t, p=pv)
            if np.max(np.abs(rep.qd), initial=0.0) > 0:
                _refuse_motion(eom, f"'{eom.name}' is in motion at its start values")
            return rep.q, t
        if re.fullmatch(r"t\s*=\s*(.+)", s):
            _refuse_motion(eom, f"'{s}' asks for a state of the motion of '{eom.name}'")
    raise UsageError(f"cannot linearize at {at!r}: use 'equilibrium', 'start', a dict of coordinate values "
                     "or an Equilibrium")


def _continued(eom, q_from, q_to, fixed, t, pv, step: float = 0.25):
    """Project q_to (the ``fixed`` coordinates held) by continuation from q_from on the
    manifold: the held values move in steps of at most ``step``, each projection warm-started
    from the last, so the result stays on the assembly branch of q_from."""
    d = np.where(fixed, np.asarray(q_to, float) - q_from, 0.0)
    k = max(1, int(np.ceil(np.max(np.abs(d), initial=0.0) / step)))
    q = np.asarray(q_from, float).copy()
    for j in range(1, k + 1):
        trial = q.copy()
        trial[np.asarray(fixed)] = (q_from + d * j / k)[np.asarray(fixed)]
        q = project(eom, trial, t, pv, fixed=fixed)
        if q is None:
            return project(eom, q_to, t, pv, fixed=fixed)
    return q


def linearize_constrained(eom, con, at, inputs, pv, t, guesses):
    """The reduced linear model (see the module docstring) as a :class:`Linearization`."""
    n = eom.n
    q0 = con.q_start
    notes = list(con.notes)
    eq = None
    if isinstance(at, Equilibrium):
        eq = at
    elif isinstance(at, str) and at.strip() == "equilibrium":
        eq = nearest_equilibrium(eom, guesses, t, pv, q0, notes,
                                 "linearize about a configuration at rest (--at NAME=VALUE)")
    pt = parts(eom)
    if eq is not None:
        if eq.multipliers is None:
            raise UsageError("this Equilibrium belongs to a model without constraints")
        q, t = np.asarray(eq.q, float), eq.t
        lam = np.asarray(eq.multipliers, float)[list(con.active)]
        acc = np.asarray(eq.acceleration, float)
        kind = "accelerated-reference" if eq.kind == "accelerated-reference" else "equilibrium"
    else:
        q, t = rest_state(eom, con, at, q0, pv, t)
        M, bias = pt.M_bias(q, np.zeros(n), t, pv)
        acc, lam = rest_multipliers(con, q, 0.5 * (M + M.T), bias)

        if np.max(np.abs(M @ acc), initial=0.0) <= 1e-8 * max(structure(eom, pv).force_scale, 1e-300):
            kind, acc = "equilibrium", np.zeros(n)
        else:
            kind = "state"
            notes.append("not an equilibrium: the linear model describes deviations from the motion "
                         "starting at rest in this configuration (frozen time, reference acceleration "
                         "included in K)")
    M, C, K, _, acc = second_order(eom, q, np.zeros(n), t, pv, acc=acc)
    Kfull = K + con.geometric_stiffness(q, lam)
    G = con.G_active(q)
    Z, indep = independent_basis(eom, M, G)
    if indep or Z.shape[1] == 0:
        names = tuple(eom.coords[i] for i in indep)
    else:
        names = tuple(f"z{j + 1}" for j in range(Z.shape[1]))
        notes.append("no well-conditioned set of independent coordinates here: z are the coordinates "
                     "along an orthonormal basis of the tangent space")
    Mr, Cr, Kr = Z.T @ M @ Z, Z.T @ C @ Z, Z.T @ Kfull @ Z
    k = Z.shape[1]

    if k and singular_mass(Mr):
        w, V = np.linalg.eigh(0.5 * (Mr + Mr.T))
        raise singular_mass_error(eom, Z @ V[:, 0], "on the constraint manifold at the linearization point")
    A = first_order(Mr, Cr, Kr) if k else np.zeros((0, 0))
    if inputs is None:
        inputs = declared_inputs(eom)
    _check_inputs(eom, inputs)
    in_names, Bq = input_columns(eom, inputs, q, np.zeros(n), t, pv)
    Bqr = Z.T @ Bq
    B = np.vstack([np.zeros((k, Bqr.shape[1])), np.linalg.solve(Mr, Bqr)]) if k else np.zeros((0, Bqr.shape[1]))
    return Linearization(coords=tuple(eom.coords), M=Mr, C=Cr, K=Kr, A=A, B=B, Bq=Bqr, inputs=in_names,
                         q=np.asarray(q, float), qd=np.zeros(n), t=float(t), acceleration=np.asarray(acc, float),
                         kind=kind, p=pv, equilibrium=eq, notes=notes, eom=eom, basis=Z, reduced_coords=names,
                         multipliers=con.full_multipliers(lam), constraint_names=tuple(eom.constraint_names),
                         multiplier_units=multiplier_units(eom),
                         active_constraints=tuple(eom.constraint_names[i] for i in con.active),
                         stiffness=Kfull)


def _check_inputs(eom, inputs) -> None:
    """Parameters that move the constraints are not inputs of the linear model on the manifold."""
    import casadi as ca

    if not inputs:
        return
    names = [s for s in re.split(r"[,\s]+", inputs) if s] if isinstance(inputs, str) else list(inputs)
    for name in names:
        if name in eom.params and ca.depends_on(eom.g, eom.p[eom.params.index(name)]):
            raise UsageError(f"input {name!r} changes the constraints of {eom.name}: inputs of a constrained "
                             "model must be forces (parameters outside the constraints, or force(coordinate))")
