"""The CasADi Functions compiled into an FMU, under the names the C runtime calls.

    mech_ode    (t, x, u, p) -> xdot, lam     the formulated ODE: minimal coordinates, or the
                                              index-1 ODE of a constrained model (lam: every
                                              constraint's multiplier, EOM sign convention)
    mech_out    (t, x, u, p, lam) -> y        the model's outputs, in declaration order
    mech_jvp    (t, x, u, p, dx, du) -> dxdot, dy
                                              directional derivative of (xdot, y) along (dx, du)
                                              (CasADi forward mode; lam follows the states)
    mech_start  (p) -> q0, qd0                start values (expressions in the parameters)
    mech_params (free) -> p                   dependent parameters from the free ones
    mech_dyn    (t, q, qd, u, p) -> M, bias   M q'' = bias (models with constraints or contacts)
    mech_cons   (t, q, qd, p) -> c, A, ct, gamma
                                              every constraint row: the model's constraints,
                                              one gap per contact, three rows per fixation;
                                              A = dc/dq, ct = dc/dt, c'' = A q'' + gamma
    mech_gap    (t, q, p) -> g                the contacts' gaps (event location)
    mech_e      (p) -> e                      the contacts' coefficients of restitution
    mech_fric   (t, q, qd, p) -> W            sliding friction of closed contacts: column j the
                                              generalized force per unit normal force of the
                                              j-th contact with friction

Every output is dense.  ``Plan`` collects them with the sizes the runtime needs.
"""
from __future__ import annotations

from dataclasses import dataclass, field

from ..diagnostics import Diagnostic, MechError


@dataclass
class Plan:
    """What one FMU holds: the Functions and the model's sizes."""
    functions: list
    n: int
    nu: int
    np: int
    m: int                  # model constraints (all rows, redundant ones included)
    k: int                  # contacts
    nfix: int               # fixations
    nrows: int              # rows of mech_cons
    nout: int
    base_rows: tuple = ()   # the constraints mech_ode holds (an independent subset)
    fix_times: tuple = ()
    gaps: list = field(default_factory=list)
    fixations: list = field(default_factory=list)
    fric_col: tuple = ()    # per contact: column of mech_fric (its sliding friction), -1 without


def _sx_or_mx(f):
    import casadi as ca

    return ca.SX if f.is_a("SXFunction") else ca.MX


def _dense(f, name, names_in, names_out):
    """``f`` renamed, with dense outputs; SX Functions stay SX (flat, no call node)."""
    import casadi as ca

    Sym = _sx_or_mx(f)
    ins = [Sym.sym(names_in[i], f.sparsity_in(i)) for i in range(f.n_in())]
    outs = [ca.densify(o) for o in f.call(ins)]
    return ca.Function(name, ins, outs, list(names_in), list(names_out))


def build(model, funcs) -> Plan:
    """The Functions of ``model`` (an api.Model) from ``funcs``, the problem's Functions
    (``Model.casadi()``, export/problem.py): ``mech_ode`` is its ``ode`` with its
    ``multipliers``, ``mech_dyn`` its ``mass_matrix`` and ``bias``, ``mech_start`` and
    ``mech_params`` its ``start`` and ``parameters``; the outputs are the model's output
    expressions reading the multipliers as an input (the problem's ``outputs`` solve them again
    inside; the runtime has them from ``mech_ode``, or from the contact accelerations)."""
    import casadi as ca

    from . import problem

    eom = model.eom
    n, nu, npar, m = eom.n, eom.nu, int(eom.p.numel()), eom.m
    ode, base_rows = problem.ode(model, funcs)
    q, qd, t, p, u = eom.q, eom.qd, eom.t, eom.p, eom.u_sym
    x = ca.vertcat(q, qd)
    lam = eom.lam if eom.lam is not None else ca.SX(0, 1)
    if lam.numel() != m and m:
        lam = ca.SX.sym("lam", m)
    names = list(eom.outputs)
    y = ca.vertcat(*[ca.SX(eom.outputs[k]) for k in names]) if names else ca.SX(0, 1)
    try:
        out = ca.Function("mech_out", [t, x, u, p, lam], [ca.densify(y)], ["t", "x", "u", "p", "lam"], ["y"])
    except RuntimeError as e:
        raise MechError(Diagnostic("E890", f"cannot export the outputs of '{eom.name}': "
                                   f"{str(e).strip().splitlines()[-1]}",
                                   help="an output must depend only on coordinates, speeds, time, "
                                        "inputs, parameters and constraint multipliers")) from None
    jvp = _jvp(ode, out, n, nu, npar, m)
    start = _dense(funcs["start"], "mech_start", ["p"], ["q0", "qd0"])
    params = _dense(funcs["parameters"], "mech_params", ["free"], ["p"])
    gaps, fixes = problem.contacts(eom) if model.model.contacts else ([], [])
    fns = [ode, out, jvp, start, params]
    k, nfix = len(gaps), len(fixes)
    rows = []
    if m:
        rows.append(ca.reshape(ca.SX(eom.g), -1, 1))
    rows += [ca.SX(g.gap) for g in gaps]
    rows += [ca.reshape(problem.point_position(eom, f.point), 3, 1) for f in fixes]
    nrows = m + k + 3 * nfix
    if nrows:
        c = ca.vertcat(*rows)
        A = ca.jacobian(c, q)
        ct = ca.jacobian(c, t)
        cdot = ca.mtimes(A, qd) + ct
        gamma = ca.mtimes(ca.jacobian(cdot, q), qd) + ca.jacobian(cdot, t)
        fns.append(problem.dynamics(model, funcs))
        fns.append(ca.Function("mech_cons", [t, q, qd, p], [ca.densify(c), ca.densify(A), ca.densify(ct),
                                                               ca.densify(gamma)],
                                 ["t", "q", "qd", "p"], ["c", "A", "ct", "gamma"]))
    fric_col = [-1] * k
    fric = [i for i, gi in enumerate(gaps) if getattr(gi, "friction", None) is not None]
    if fric:
        for j, i in enumerate(fric):
            fric_col[i] = j
        W = ca.horzcat(*[ca.reshape(ca.SX(gaps[i].friction), n, 1) for i in fric])
        fns.append(ca.Function("mech_fric", [t, q, qd, p], [ca.densify(W)], ["t", "q", "qd", "p"], ["W"]))
    if k:
        g = ca.vertcat(*[ca.SX(gi.gap) for gi in gaps])
        e = ca.vertcat(*[ca.SX(gi.e) for gi in gaps])
        fns.append(ca.Function("mech_gap", [t, q, p], [ca.densify(g)], ["t", "q", "p"], ["g"]))
        fns.append(ca.Function("mech_e", [p], [ca.densify(e)], ["p"], ["e"]))
    return Plan(functions=fns, n=n, nu=nu, np=npar, m=m, k=k, nfix=nfix, nrows=nrows, nout=len(names),
                base_rows=tuple(base_rows), fix_times=tuple(float(f.time) for f in fixes), gaps=gaps,
                fixations=fixes, fric_col=tuple(fric_col))


def _jvp(ode, out, n, nu, npar, m):
    """mech_jvp: the forward derivative of (xdot, y) with lam = lam(t, x, u, p) of mech_ode."""
    import casadi as ca

    Sym = ca.SX if ode.is_a("SXFunction") else ca.MX
    t, x, u, p = Sym.sym("t"), Sym.sym("x", 2 * n), Sym.sym("u", nu), Sym.sym("p", npar)
    dx, du = Sym.sym("dx", 2 * n), Sym.sym("du", nu)
    xdot, lam = ode(t, x, u, p)
    y = out(t, x, u, p, lam)
    z = ca.vertcat(x, u)
    dz = ca.vertcat(dx, du)
    if Sym is ca.SX:
        d = ca.jtimes(ca.vertcat(xdot, y), z, dz)
        return ca.Function("mech_jvp", [t, x, u, p, dx, du], [ca.densify(d[:2 * n]), ca.densify(d[2 * n:])],
                           ["t", "x", "u", "p", "dx", "du"], ["dxdot", "dy"])
    F = ca.Function("F", [t, x, u, p], [xdot, y])
    fwd = F.forward(1)
    res = fwd(t, x, u, p, xdot, y, 0, dx, du, Sym.zeros(npar, 1))
    return ca.Function("mech_jvp", [t, x, u, p, dx, du], [ca.densify(res[0]), ca.densify(res[1])],
                       ["t", "x", "u", "p", "dx", "du"], ["dxdot", "dy"])
