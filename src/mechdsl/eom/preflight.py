"""The start check: the numbers of a derived model at its start state, before any step.

``preflight(eom, p, x0, t)`` returns the problems (Diagnostics, empty when the model can
start); ``check_start`` raises them.  ``mech check`` runs it on every model and scene, and
``simulation.simulate`` (the entry of every run) before it formulates, so that `--set`,
`with_params`, `p` and `x0` values are judged too: what ``check`` accepts, ``simulate`` can
start (docs/simulate.md, "The start check").

In order (the first group that finds something ends the check):

  E740  a parameter value that is not finite, or subnormal (below 2.2e-308)  (at the parameter)
  E508-E512  the component values (semantic/physical.py)  (at the component)
  E747  a negative parameter that is a mass or an inertia: its unit is kg or kg.m2 and the
        kinetic energy is linear in it with a positive semidefinite coefficient (at the parameter)
  E741  a start value that is not finite                  (at the coordinate's joint)
  E748  a start angle too large for double precision (|q| eps > 1e-6 rad, e.g. tan(pi/2))
  E826  a constraint residual or gradient that is not finite at the start (dae/init.py)
  E821/E822  consistent initialization (dae/init.py)      (constrained models)
  E749  a loop whose positions double precision cannot resolve to the drift bound (lengths 1e16)
  E755  a mechanism with closed loops smaller than 100 times the drift bound (lengths 1e-12)
  E742  the mass matrix is not finite at the start
  E743  the mass matrix is singular (or not positive definite) at the start, on the motions
        the constraints allow: a coordinate moves no inertia (a point mass on a Spherical
        joint, a rod of length 0), or a negative mass in the equation layer
  E746  the energy is not finite at the start (overflow: a product of huge values)
  E745  a spring or damper whose ends coincide at the start (its direction is undefined)
  E744  the accelerations are not finite at the start for another reason
  E756  a contact gap that is not finite at the start          (at the contact)
  E861  a start that penetrates a contact by more than the contact tolerance   (at the contact)
  E758  a model with contacts smaller than 100 times the contact tolerance's floor, 1e-7 m (lengths 1e-12)
  E757  an output that is not finite at the start                (at the output)

Cost: one evaluation of the Functions the simulation builds anyway (the forward dynamics,
energy, the constraint Jacobian); the mass matrix of the recursive route (CRBA, O(N^2)) is
built only to explain non-finite accelerations.
"""
from __future__ import annotations

import math

import numpy as np

from ..diagnostics import Diagnostic, MechError, Span
from ..model.names import split_state

SINGULAR_RCOND = 1e-12      # scaled mass matrix: smallest / largest eigenvalue below this is singular
ANGLE_RESOLUTION = 1e-6    # rad: a start angle known less precisely than this is refused (|q| > 4.5e9)
COINCIDE_REL = 1e-12        # spring/damper ends closer than this times the model's size coincide
PROBES = 3                 # seeded positions besides the start at which E747 judges dT/dp
LOOP_SIZE_FACTOR = 100     # a closed loop must measure this many times the constraint drift bound (E755)
CONTACT_FLOOR = 1e-9       # m: the contact tolerance's floor, max(1e-9, 100 atol, 2 offset) (impacts/contact_run.py)
CONTACT_SIZE_FACTOR = 100  # a model with contacts must measure this many times that floor (E758); a loose
                           # tolerance is the user's choice (the cradle, 0.45 m, at atol 1e-3 still runs)
DRIFT_BOUND = 1e-9          # the DAE's default drift bound, max(10 atol, 1e-10) for atol = 1e-10

_HINT_POINT_ROTATION = ("a point mass on a {kind} joint has no inertia about the rod: use Revolute joints, "
                        "or give the body a Sphere/Body inertia")


PASSED_KEPT = 64      # starts that passed, kept per EOM: a repeated run is not checked again


def check_start(eom, p=None, x0=None, t: float = 0.0, drift_bound: float = DRIFT_BOUND) -> None:
    """Raise a MechError with the start problems of ``eom`` (see the module docstring).  A start
    that passed (same parameters, start values, time and drift bound) passes again without
    being evaluated: the check is a pure function of them (0.7 ms of a 3 ms run)."""
    key = _start_key(p, x0, t, drift_bound)
    passed = eom.workspace.memo("preflight_passed", dict) if key is not None else None
    if passed is not None and key in passed:
        return
    problems = preflight(eom, p, x0, t, drift_bound)
    if problems:
        raise MechError(problems)
    if passed is not None:
        if len(passed) >= PASSED_KEPT:
            passed.pop(next(iter(passed)), None)
        passed[key] = True


def _start_key(p, x0, t, drift_bound):
    """A hashable key of the check's inputs, or None when they have no plain numeric form."""
    def norm(v):
        if v is None:
            return None
        if isinstance(v, dict):
            return tuple(sorted((str(k), float(x)) for k, x in v.items()))
        a = np.asarray(v, float)
        return (a.shape, a.tobytes())
    try:
        return (norm(p), norm(x0), float(t), float(drift_bound))
    except (TypeError, ValueError):
        return None


def preflight(eom, p=None, x0=None, t: float = 0.0, drift_bound: float = DRIFT_BOUND) -> list[Diagnostic]:
    """The problems of ``eom`` at its start state with parameters ``p`` (vector or overrides)
    and start overrides ``x0`` (as ``simulate`` takes them); empty when it can start.
    drift_bound: the constraint drift the DAE simulation will hold (E749)."""
    from . import parameter_vector

    pv = parameter_vector(eom, p)
    model = eom.model
    tiny = np.finfo(float).tiny
    bad = [i for i in range(pv.size) if not math.isfinite(pv[i]) or 0.0 < abs(pv[i]) < tiny]
    if bad:
        return [Diagnostic("E740", f"the value of parameter '{eom.params[i]}' is "
                           + (f"not finite ({pv[i]:g})" if not math.isfinite(pv[i]) else
                              f"too small to compute with ({pv[i]:g}: below {tiny:.3g}, double precision "
                              "keeps only a few of its digits)"),
                           _param_span(model, eom.params[i]),
                           "check its formula for overflow and division by zero, or the value given "
                           "with --set / with_params; use 0 for nothing, or other units") for i in bad]
    own = None if model is None else np.array([q.value for q in model.real_parameters], float)
    if model is not None and not (own.shape == pv.shape and np.array_equal(own, pv)):
        # the model's own values were judged when it was analyzed (or by with_params)
        from ..semantic.physical import errors, parameter_env, value_problems

        env = parameter_env(model)
        env.update(zip(eom.params, map(float, pv)))
        found = errors(value_problems(model, env))
        if found:
            return found
    found = _negative_masses(eom, pv)
    if found:
        return found
    if eom.n == 0:
        return []
    if not isinstance(drift_bound, (int, float)) or not drift_bound > 0:
        drift_bound = DRIFT_BOUND          # a bad option is refused by the simulator itself
    with np.errstate(all="ignore"):
        return _numbers(eom, pv, x0, float(t), drift_bound)


def _numbers(eom, pv, x0, t, drift_bound) -> list[Diagnostic]:
    q0, qd0 = eom.start(pv)
    x_model = np.r_[q0, qd0]
    given = _overridden(eom, x0)            # values x0 replaces are the caller's (UsageError if bad)
    bad = [i for i in range(2 * eom.n) if i not in given and not math.isfinite(x_model[i])]
    if bad:
        return [_start_problem(eom, i, x_model[i]) for i in bad]
    found = _huge_angles(eom, q0, given)
    if found:
        return found
    if eom.m:
        from ..dae.init import initialize
        from .start import fixed_start

        q, qd, fq, fqd = fixed_start(eom, x0, pv)
        g_problem = _constraint_problem(eom, q, t, pv)
        if g_problem:
            return g_problem
        try:
            init = initialize(eom, q, qd, t, pv, fixed_q=fq, fixed_qd=fqd)
        except MechError as e:
            return e.diagnostics
        q, qd = init.q, init.qd
        found = _loop_scale(eom, q, t, pv, drift_bound)
        if found:
            return found
    else:
        from .start import start_vector

        x = start_vector(eom, x0, pv)
        q, qd = x[:eom.n], x[eom.n:]
    return _dynamics_problems(eom, q, qd, t, pv, drift_bound)


def _dynamics_problems(eom, q, qd, t, pv, drift_bound: float = DRIFT_BOUND) -> list[Diagnostic]:
    from .codegen import casadi_functions

    x = np.r_[q, qd]
    fs = casadi_functions(eom, names=("energy", "mass_matrix", "bias"))
    if eom.m:
        M = _mass(fs, t, x, pv, eom.n)
        rhs = _value(fs["bias"], t, x, _u(eom), pv)
        G = _jacobian(eom, q, t, pv)
    else:
        M = None if eom.qdd is not None else _mass(fs, t, x, pv, eom.n)
        try:
            rhs = _value(casadi_functions(eom, names=("ode", "ode_jacobian"))["ode"], t, x, _u(eom), pv)   # simulate's own
        except RuntimeError:          # CasADi's QR refuses a singular M ("Evaluation failed"): M says why below
            rhs = np.full(2 * eom.n, np.nan)
        G = None
    ok_rhs = bool(np.all(np.isfinite(rhs)))
    if M is None and not ok_rhs:      # the recursive route: explain it with the mass matrix
        M = _mass(fs, t, x, pv, eom.n)
    if M is not None:
        found = _mass_problems(eom, M, G)
        if found:
            return found
    T, V, _ = (float(v) for v in fs["energy"](t, x, _u(eom), pv))
    if not (math.isfinite(T) and math.isfinite(V)):
        return [Diagnostic("E746", f"the energy at the start is not finite (kinetic {T:g}, potential {V:g})",
                           _model_span(eom),
                           "a product of huge values overflows: check the parameters for values near 1e308, "
                           "or choose units that keep the numbers moderate")]
    if not ok_rhs:
        return _force_problems(eom, q, t, pv, rhs)
    return _gap_problems(eom, q, t, pv, drift_bound) or _output_problems(eom, q, qd, t, pv)


def _gap_problems(eom, q, t, pv, drift_bound: float = DRIFT_BOUND) -> list[Diagnostic]:
    """E756: a contact whose gap is not finite at the start can never be located (the
    newtons_cradle with r = 1e308: inf gaps in the results of a run that 'succeeded').
    E758: a model with contacts smaller than CONTACT_SIZE_FACTOR times the contact tolerance's floor (the
    contact analogue of E755): pendulum_wall with L = 1e-12 m started with its contact closed
    and failed at t = 0 on a step budget of 8.7e7 steps; its size: the largest of the gaps
    and the spread of its points at the start.
    E861: a start that penetrates a contact by more than the contact tolerance (the contact back
    end's default gap_tol, max(1e-9, 100 atol) = max(1e-9, 10 x the drift bound)), which the run
    would refuse: `mech check` says so too (issue 23)."""
    if eom.model is None or not eom.model.contacts:
        return []
    import casadi as ca

    from ..impacts.gaps import contact_gaps

    def build():
        gaps = contact_gaps(eom)[0]
        return gaps, ca.Function("start_gaps", [eom.q, eom.t, eom.p],
                                 [ca.vertcat(*[ca.SX(g.gap) for g in gaps])] if gaps else [ca.SX(0, 1)])

    gaps, fn = eom.workspace.memo("preflight_gaps", build)
    if not gaps:
        return []
    values = _value(fn, q, t, pv)
    for g, v in zip(gaps, values):
        if not math.isfinite(v):
            return [Diagnostic("E756", f"the gap of contact '{g.name}' is not finite at the start ({v:g})",
                               g.span or _model_span(eom),
                               "its sizes and positions overflow with these parameter values: keep them moderate")]
    touch = max(1e-9, 10.0 * drift_bound)
    found = [Diagnostic("E861", f"the start state penetrates contact '{g.name}' (gap {v:.6g} m)",
                        g.span or _model_span(eom), "change the start values so that every gap is >= 0")
             for g, v in zip(gaps, values) if v < -touch]
    if found:
        return found
    size = max(_points_size(eom, q, t, pv), float(np.max(np.abs(values))))
    if 0.0 < size < CONTACT_SIZE_FACTOR * CONTACT_FLOOR:
        g = gaps[0]
        return [Diagnostic("E758", f"the model measures only {size:.3g} m across: contacts are located to "
                                   f"{CONTACT_FLOOR:g} m at best (the contact tolerance, max(1e-9, 100 atol)), more "
                                   f"than 1/{CONTACT_SIZE_FACTOR:g} of its size, so its motion is lost in the "
                                   f"tolerance (contact '{g.name}' would start closed)", g.span or _model_span(eom),
                           "choose units that make the lengths moderate (um or mm instead of m), "
                           "or check the lengths for a mistake")]
    return []


def _points_size(eom, q, t, pv) -> float:
    """The model's size at the start: twice the largest distance of its points (the world's
    origin, bodies, declared points) from their centroid; 0 when it has no positions."""
    model = eom.model
    if model is None or eom.point_position is None or not model.points:
        return 0.0
    import casadi as ca

    names = [pt.name for pt in model.points]
    try:
        fn = eom.workspace.memo("preflight_points", lambda: ca.Function(
            "points", [eom.q, eom.t, eom.p], [ca.horzcat(*[ca.vec(eom.point_position(n)) for n in names])]))
    except Exception:  # noqa: BLE001 - a point without a position: nothing to judge here
        return 0.0
    xyz = np.asarray(fn(q, t, pv), float).reshape(3, -1, order="F")
    if xyz.shape[1] < 2 or not np.all(np.isfinite(xyz)):
        return 0.0
    return 2 * float(np.max(np.linalg.norm(xyz - xyz.mean(axis=1, keepdims=True), axis=0)))


def _output_problems(eom, q, qd, t, pv) -> list[Diagnostic]:
    """E757: an output that is not finite at the start (R = 0 in cos_th = y/R): every run
    would fail at once on it (a run never writes inf or nan)."""
    import casadi as ca

    lam = getattr(eom, "lam", None)

    def build():
        names = [k for k, v in eom.outputs.items()
                 if lam is None or not ca.depends_on(ca.vec(ca.SX(v)), ca.SX(lam))]   # reactions need lambda
        exprs = [ca.vec(ca.SX(eom.outputs[k])) for k in names]
        sizes = [int(e.numel()) for e in exprs]
        u = eom.u if getattr(eom, "u", None) is not None else ca.SX(0, 1)      # outputs may use inputs
        return names, sizes, ca.Function("start_outputs", [eom.q, eom.qd, eom.t, u, eom.p],
                                         [ca.vertcat(*exprs)] if exprs else [ca.SX(0, 1)])

    names, sizes, fn = eom.workspace.memo("preflight_outputs", build)
    if not names:
        return []
    vals = _value(fn, q, qd, t, _u(eom), pv)
    row = 0
    for name, k in zip(names, sizes):
        v = vals[row:row + k]
        row += k
        if not np.all(np.isfinite(v)):
            bad = float(v[~np.isfinite(v)][0])
            span = next((o.span for o in (eom.model.outputs if eom.model is not None else ()) if o.name == name),
                        None)
            return [Diagnostic("E757", f"output '{name}' is not finite at the start ({bad:g})",
                               span or _model_span(eom),
                               "its expression divides by zero or leaves its domain (a square root or logarithm "
                               "of a negative number) at the start values: check it and the parameters")]
    return []


# ----------------------------------------------------------------------------- the parts


def _mass_problems(eom, M, G) -> list[Diagnostic]:
    """E742 (not finite) or E743 (singular on the speeds the constraints allow, judged after
    scaling each coordinate by its own inertia, so that units do not matter)."""
    bad_rows = [i for i in range(eom.n) if not np.all(np.isfinite(M[i]))]
    if bad_rows:
        names = ", ".join(eom.coords[i] for i in bad_rows)
        return [Diagnostic("E742", f"the mass matrix is not finite at the start (in the equation of {names})",
                           _coord_span(eom, eom.coords[bad_rows[0]]),
                           "check the masses, lengths and inertias of the bodies these coordinates move "
                           "for overflow and division by zero")]
    Ms = 0.5 * M + 0.5 * M.T             # (no overflow near 1e308)
    d = np.sqrt(np.abs(np.diag(Ms)))
    scale = float(np.max(d)) if d.size else 0.0
    if scale == 0.0:
        return [_singular(eom, np.ones(eom.n), G is not None)]
    dinv = 1.0 / np.where(d > 1e-150 * scale, d, scale)     # a coordinate with no inertia keeps a 0
    Z = np.eye(eom.n)
    if G is not None and G.size:
        Gs = G * dinv[None, :]
        _, sv, vt = np.linalg.svd(Gs, full_matrices=Gs.shape[0] < Gs.shape[1])   # V in full, U not
        rank = int(np.sum(sv > 1e-10 * max(float(sv[0]), 1e-300))) if sv.size else 0
        Z = vt[rank:].T                      # the (scaled) speeds the constraints allow
        if Z.shape[1] == 0:
            return []
    A = Z.T @ (dinv[:, None] * Ms * dinv[None, :]) @ Z
    ev, vecs = np.linalg.eigh(0.5 * (A + A.T))
    top = max(float(np.max(np.abs(ev))), 1.0)    # the scaled matrix has a unit diagonal: its scale is 1
    if ev[0] < -SINGULAR_RCOND * top:
        return [_singular(eom, Z @ vecs[:, 0], Z.shape[1] < eom.n, negative=True)]
    if ev[0] <= SINGULAR_RCOND * top:
        return [_singular(eom, Z @ vecs[:, 0], Z.shape[1] < eom.n)]
    return []


def _singular(eom, v, constrained: bool, negative: bool = False) -> Diagnostic:
    """E743 for the null direction v (or one of negative kinetic energy), named by its
    coordinates and joints."""
    v = np.abs(np.asarray(v, float))
    top = float(np.max(v)) if v.size else 0.0
    idx = [i for i in range(eom.n) if v[i] > 1e-6 * top] or list(range(eom.n))
    coords = [eom.coords[i] for i in idx]
    joint = _owner_joint(eom, coords[0])
    model = eom.model
    hint = ("every coordinate needs inertia beyond it: give the bodies it moves a mass and (for rotations) "
            "an extent, or prescribe its motion") if joint is not None else (
        "the kinetic energy must grow with every speed at the start: check the masses it uses (not 0) "
        "and that it is quadratic in der(...) (1/2 m der(q)^2, not der(q)^4)")
    if joint is not None and model is not None:
        hint = point_rotation_hint(model, joint) or hint
    where = f" (joint '{joint.name}')" if joint is not None else ""
    allowed = " on the motions the constraints allow" if constrained else ""
    if negative:
        return Diagnostic("E743", f"the mass matrix is not positive definite at the start{allowed}: a motion of "
                                  f"{', '.join(coords)}{where} has a negative kinetic energy",
                          joint.span if joint is not None else _coord_span(eom, coords[0]),
                          "masses and moments of inertia are positive: check the signs of the masses in the "
                          "kinetic energy and of the parameters they use")
    return Diagnostic("E743", f"the mass matrix is singular at the start{allowed}: "
                              f"{', '.join(coords)}{where} move{'s' if len(coords) == 1 else ''} no inertia",
                      joint.span if joint is not None else _coord_span(eom, coords[0]), hint)


def point_rotation_hint(model, joint) -> str | None:
    """The hint for rotations of a point mass (no inertia about any axis through it), else None."""
    child = _body(model, joint.child_body)
    if joint.kind in ("spherical", "free") and child is not None and child.kind == "point":
        return _HINT_POINT_ROTATION.format(kind=joint.kind.capitalize())
    return None


def _force_problems(eom, q, t, pv, rhs) -> list[Diagnostic]:
    found = _coincident_ends(eom, q, t, pv)
    if found:
        return found
    n = eom.n
    rows = [i % n for i in range(rhs.size) if not math.isfinite(rhs[i])]
    rows = list(dict.fromkeys(rows)) or list(range(n))
    names = ", ".join(eom.coords[i] for i in rows)
    return [Diagnostic("E744", f"the accelerations are not finite at the start (in the equation of {names})",
                       _coord_span(eom, eom.coords[rows[0]]),
                       "a force law or a term is not defined at the start state (a division by zero, a "
                       "square root of a negative number, an overflow); check the forces on these coordinates")]


def _coincident_ends(eom, q, t, pv) -> list[Diagnostic]:
    from ..model import ir

    model = eom.model
    if model is None or eom.point_position is None:
        return []
    import casadi as ca

    out = []
    for f in model.forces:
        if not isinstance(f, ir.SpringDamper):
            continue
        try:
            fn = ca.Function("ends", [eom.q, eom.t, eom.p],
                             [ca.vertcat(eom.point_position(f.a), eom.point_position(f.b))])
        except Exception:  # noqa: BLE001 - cannot judge this one: the generic message follows
            continue
        ab = np.array(fn(q, t, pv), float).ravel()
        size = max(1.0, float(np.max(np.abs(ab))))
        if np.all(np.isfinite(ab)) and np.linalg.norm(ab[3:] - ab[:3]) <= COINCIDE_REL * size:
            out.append(Diagnostic("E745", f"the ends of {f.kind} '{f.name}' coincide at the start ('{f.a}' and "
                                          f"'{f.b}'): its direction, and so its force, is undefined", f.span,
                                  "start the bodies apart (set a start value), or attach the ends to other points"))
    return out


def _loop_scale(eom, q, t, pv, drift_bound) -> list[Diagnostic]:
    """The size of the loops against the constraint drift the run holds (drift_bound).

    E749: loop closures compare positions; when double precision resolves the positions of
    the loop's points only to more than the drift bound, no projection can hold them.
    E755: a mechanism smaller than LOOP_SIZE_FACTOR times the drift bound (max(10 atol, 1e-10)):
    its geometry is lost in the tolerance.  nfourbar with rods of 1e-12 m ran away (speeds of
    1e12 rad/s after 2e-6 s) and ground for minutes in CVODES before this.  Its size: the
    largest distance between the joint points of the model (at the start)."""
    model = eom.model
    if model is None or eom.point_position is None:
        return []
    cut = [j for j in model.joints if j.closes_loop]
    if not cut:
        return []
    import casadi as ca

    names = list(dict.fromkeys([n for j in cut for n in (j.parent, j.child)]
                               + [n for j in model.joints for n in (j.parent, j.child)]))
    try:
        fn = eom.workspace.memo("preflight_joint_points", lambda: ca.Function(
            "joint_points", [eom.q, eom.t, eom.p], [ca.horzcat(*[ca.vec(eom.point_position(n)) for n in names])]))
    except Exception:  # noqa: BLE001 - a point without a position: nothing to judge here
        return []
    xyz = np.asarray(fn(q, t, pv), float).reshape(3, -1, order="F")
    if not xyz.size or not np.all(np.isfinite(xyz)):
        return []
    far = np.max(np.abs(xyz), axis=0)                   # per point
    loop_far = [max(far[names.index(j.parent)], far[names.index(j.child)]) for j in cut]
    k = int(np.argmax(loop_far))
    res = float(loop_far[k]) * np.finfo(float).eps
    if res > drift_bound:
        j = cut[k]
        return [Diagnostic("E749", f"the loop closed by joint '{j.name}' lies {loop_far[k]:.3g} from the origin: "
                                   f"double precision resolves its positions only to {res:.2g}, more than the "
                                   f"constraint drift the simulation holds ({drift_bound:.2g})", j.span,
                           "choose units (or an origin) that keep the positions moderate, or raise atol")]
    size = 2 * float(np.max(np.linalg.norm(xyz - xyz.mean(axis=1, keepdims=True), axis=0)))
    if xyz.shape[1] < 2 or size <= 0 or size >= LOOP_SIZE_FACTOR * drift_bound:
        return []
    j = cut[0]
    return [Diagnostic("E755", f"the mechanism closed by joint '{j.name}' measures only {size:.3g} across: the "
                               f"simulation holds its constraints to {drift_bound:.2g} (max(10 atol, 1e-10)), "
                               f"more than 1/{LOOP_SIZE_FACTOR:g} of its size, so its geometry is lost in the tolerance",
                       j.span, "choose units that make the lengths moderate (um or mm instead of m), "
                               "or check the lengths for a mistake")]


def _constraint_problem(eom, q, t, pv) -> list[Diagnostic]:
    """E826 (dae/init.py): a constraint residual or gradient that is inf/nan at the start."""
    from ..dae.init import check_defined

    if not np.all(np.isfinite(q)):
        return []
    try:
        check_defined(eom, _value(_constraint_fns(eom)[0], q, t, pv), _jacobian(eom, q, t, pv))
    except MechError as e:
        return e.diagnostics
    return []


def _constraint_fns(eom):
    from ..dae.init import _functions

    return _functions(eom)


def _jacobian(eom, q, t, pv) -> np.ndarray:
    return _value(_constraint_fns(eom)[1], q, t, pv).reshape(eom.m, eom.n)


# ----------------------------------------------------------------------------- helpers


def _mass(fs, t, x, pv, n) -> np.ndarray:
    """M at the start: (q, t, p), or (t, x, p) when it depends on the speeds (codegen)."""
    f = fs["mass_matrix"]
    args = (t, x, np.zeros(f.numel_in(2)), pv) if f.name_in(0) == "t" else (x[:n], t, pv)
    return _value(f, *args).reshape(n, n)


def _u(eom) -> np.ndarray:
    """The inputs u at their defaults (codegen's Functions take (t, x, u, p))."""
    return np.asarray(getattr(eom, "input_defaults", ()) or (), float)


def _value(f, *args) -> np.ndarray:
    out = f(*args)
    if isinstance(out, (tuple, list)):
        out = out[0]
    return np.array(out, float).ravel()


def _overridden(eom, x0) -> set[int]:
    """Indices of [q; qd] that the start overrides x0 replace."""
    if x0 is None:
        return set()
    if not isinstance(x0, dict):
        return set(range(2 * eom.n))
    out = set()
    for k in x0:
        name, speed = split_state(k)
        if name in eom.coords:
            out.add(eom.coords.index(name) + (eom.n if speed else 0))
    return out


def _huge_angles(eom, q0, given=frozenset()) -> list[Diagnostic]:
    """An angle so large that double precision resolves it to worse than ANGLE_RESOLUTION:
    sin and cos of it are noise, and constraints on it cannot be held."""
    if eom.model is None:
        return []
    out = []
    for i, c in enumerate(eom.model.coordinates[:eom.n]):
        res = abs(float(q0[i])) * np.finfo(float).eps
        if c.unit == "rad" and res > ANGLE_RESOLUTION and i not in given:
            out.append(Diagnostic("E748", f"the start angle of {c.name} ({q0[i]:.6g} rad) is too large to compute "
                                          f"with: double precision resolves it only to {res:.2g} rad",
                                  _coord_span(eom, c.name),
                                  "give the angle modulo 2 pi (between -pi and pi)"))
    return out


def _start_problem(eom, i: int, value: float) -> Diagnostic:
    name = eom.coords[i % eom.n]
    what = name if i < eom.n else f"der({name})"
    return Diagnostic("E741", f"the start value of {what} is not finite ({value:g})", _coord_span(eom, name),
                      "check its start/speed formula for a function outside its domain (asin of more than 1, "
                      "sqrt of a negative number) or a division by zero, with the parameter values in force")


def _negative_masses(eom, pv) -> list[Diagnostic]:
    """E747: a negative parameter that the kinetic energy uses as a mass or an inertia.

    Component models state their masses (E508/E509 judge them); in the equation layer
    (`kinetic = 1/2*(m1*ra^2 + ...)*der(beta)^2 + ...`) a negative mass need not make the
    reduced mass matrix indefinite (andrews.mech with m1 = -1 runs on), so it is identified
    here: a parameter with the unit of a mass (kg) or of a moment of inertia (kg.m2), a
    negative value and no declared `min`, on which the kinetic energy T depends linearly with
    a coefficient dT/dp that is a positive semidefinite quadratic form of the speeds (at the
    start and at PROBES seeded positions around it).  A product of inertia (dT/dp indefinite)
    and a mass difference with a declared range pass.  Cost: nothing unless such a parameter
    is negative."""
    model = eom.model
    if model is None or eom.n == 0 or eom.T is None:
        return []
    declared = {par.name: par for par in model.real_parameters}
    suspects = []
    for i, name in enumerate(eom.params):
        par = declared.get(name)
        if par is None or pv[i] >= 0 or par.min is not None or not par.unit:
            continue
        from ..model import units as U      # (fractions and decimal: 5 ms of a warm run; only for a negative one)

        try:
            dim = U.parse_unit(par.unit)[1]
        except ValueError:
            continue
        if dim in (U.MASS, U.INERTIA):
            suspects.append((i, par, "mass" if dim == U.MASS else "moment of inertia"))
    if not suspects:
        return []
    import casadi as ca

    T = ca.SX(eom.T)
    q0, _ = eom.start(pv)
    rng = np.random.default_rng(20260)
    probes = [np.asarray(q0, float)] + [np.asarray(q0, float) + rng.normal(size=eom.n) for _ in range(PROBES)]
    out = []
    for i, par, what in suspects:
        dT = ca.jacobian(T, eom.p[i])
        if ca.depends_on(dT, eom.p[i]) or dT.is_zero():
            continue
        H = ca.Function("dT_dp", [eom.q, eom.t, eom.p], [ca.hessian(dT, eom.qd)[0]])
        try:
            eigs = [np.linalg.eigvalsh(np.asarray(H(q, 0.0, pv), float)) for q in probes if np.all(np.isfinite(q))]
        except (RuntimeError, np.linalg.LinAlgError):
            continue
        if not eigs or not all(np.all(np.isfinite(e)) for e in eigs):
            continue
        scale = max(float(np.max(np.abs(e))) for e in eigs)
        if scale > 0 and all(float(np.min(e)) >= -1e-12 * scale for e in eigs):
            out.append(Diagnostic("E747", f"parameter '{par.name}' = {pv[i]:g} is a negative {what}: the kinetic "
                                          f"energy grows with it (unit {par.unit}), so it gives the motion negative "
                                          "inertia and the equations of motion no physical meaning",
                                  par.span,
                                  f"masses and moments of inertia are >= 0; if '{par.name}' is not one (a difference "
                                  f"of masses), declare its range: parameter Real {par.name}(unit = \"{par.unit}\", "
                                  f"min = {pv[i]:g})"))
    return out


def _param_span(model, name: str) -> Span:
    if model is not None:
        for p in model.parameters:
            if p.name == name:
                return p.span
    return Span()


def _owner_joint(eom, coord: str):
    model = eom.model
    if model is None:
        return None
    owner = next((c.owner for c in model.coordinates if c.name == coord), None)
    for j in model.joints:       # the joint that declared it, else one that it drives (phi = theta)
        if j.name == owner or (owner is None and any(v.coordinate == coord for v in j.variables)):
            return j
    return None


def _coord_span(eom, coord: str) -> Span:
    j = _owner_joint(eom, coord)
    if j is not None:
        return j.span
    if eom.model is not None:
        for c in eom.model.coordinates:
            if c.name == coord:
                return c.span
    return _model_span(eom)


def _model_span(eom) -> Span:
    return eom.model.span if eom.model is not None else Span()


def _body(model, name: str):
    for b in model.bodies:
        if b.name == name:
            return b
    return None
