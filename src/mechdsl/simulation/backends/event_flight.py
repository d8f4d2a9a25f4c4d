"""Free flight with contacts in the compiled stepping loop (``simulation/crk.c``).

A segment of a contact run in which no row is active (no closed contact, no fixation, no
model constraint: every contact open, only its gap watched) is one C call: the loop of
``mechdsl.simulation.crk`` steps the model's ``ode`` (dopri5 = scipy's RK45, dop853 = DOP853,
the same steps as the Python path), evaluates the CasADi-generated gaps of all contacts on
the continuous extension of every accepted step, locates the first event (the same sampling
and Illinois iteration as ``Run.find_event``) and returns with the output rows before it and
the state at it.  Python applies the impact law (``Run.handle``) and calls again.  The simple
impacts (one touching contact, restitution rebounding faster than rest_speed, no constraint
rows, no fixations) are applied in the loop itself with ``contact_impact`` (``impact_function``)
and recorded in a buffer that ``Run._decode_impacts`` reads: the ball bounces in one C call.

Everything else stays in Python (``Run``): segments with active rows (closed contacts,
fixations, model constraints: the constrained accelerations, releases on the multipliers,
projections), the implicit methods (radau, bdf, lsoda), ``max_step``, models with inputs,
an event at a segment's very start, and any segment the C loop fails on (it is then
stepped again in Python, which words the failure as before).  Without a C compiler the
whole run is Python.
"""
from __future__ import annotations

import numpy as np

from ...eom.codegen import casadi_functions, find_compiler
from ...eom.workspace import of
from . import crk


# scipy class (impacts.one_step) -> method of the compiled loop
COMPILED_CLASSES = {"DOP853": "dop853", "RK45": "dopri5"}
OK, EVENT = 0, 9
CANCELLED = crk.CANCELLED


class CompiledFlight:
    """The compiled loop with gap events for one ContactSystem (``loop``: crk.Loop of the
    model's ode, contact_gap and, when the simple impacts run in C, contact_impact)."""

    def __init__(self, loop):
        self.loop = loop
        self.impact = loop.fun("contact_impact")

    def segment(self, method: str, grid, y0, p, rtol, atol, max_steps, k, offset, samples, tick=None,
                impacts=None):
        """One C call from grid[0] to grid[-1]: (status, time reached, state there, rows written,
        stats dict).  status OK: reached grid[-1]; EVENT: stopped at an event; CANCELLED: stopped
        by Ctrl-C (the rows and impacts up to there are returned); others: failed.
        ``impacts`` (restitution (k,), rest_speed, v_eps, touch, rest band, capacity) lets the loop apply
        the simple impacts itself (``impact_in_c`` in crk.c); their records are in
        stats["impacts"], an (m, 5 + 2 nx) array of rows (time, contact, impulse, speed before,
        speed after, state before, state after)."""
        grid = np.ascontiguousarray(grid, float)
        nx = y0.size
        X = np.full((len(grid), nx), np.nan)
        x0c = np.ascontiguousarray(y0, float)
        pc = np.ascontiguousarray(np.ravel(p), float)
        uc = np.zeros(0)
        stats = np.zeros(6)
        use = impacts is not None and self.impact is not None and impacts[5] > 0
        if use:
            rest = np.ascontiguousarray(impacts[0], float)
            limits = np.array(impacts[1:5], float)
            buf = np.zeros((int(impacts[5]), 5 + 2 * nx))
            imp, cap = self.impact, int(impacts[5])
        else:
            rest, limits, buf = np.zeros(1), np.zeros(4), np.zeros((1, 5 + 2 * nx))
            imp, cap = None, 0
        ctl = np.zeros(2, dtype=np.int64)
        xend = np.zeros(nx)
        _P = crk._ptr

        loop = self.loop

        def call():
            return loop.run_events(loop.fun("ode"), crk.CRK_METHODS[method][0], nx, _P(grid), len(grid), _P(x0c),
                                   _P(uc), _P(pc), float(rtol), float(atol), 0.0, int(max_steps), _P(X), _P(stats),
                                   ctl.ctypes.data_as(crk._I64P), _P(xend), loop.fun("contact_gap"), int(k),
                                   float(offset), int(samples), _P(pc), imp, _P(rest), _P(limits), _P(buf), cap)

        try:
            status = crk.call_here_or_in_thread(call, ctl, None if tick is None else
                                                lambda r: tick(float(grid[r - 1])))
        except KeyboardInterrupt:       # Ctrl-C: the loop stopped at its next step; what it did is kept
            status = CANCELLED
        st = {"steps": int(stats[0]), "rhs": int(stats[1]), "rejected": int(stats[2]), "root": int(stats[4]),
              "impacts": buf[:int(stats[5])]}
        return int(status), float(stats[3]), xend, X[:int(ctl[0])], st


def flight(system, tag: str = "model") -> tuple[CompiledFlight | None, str]:
    """(CompiledFlight or None, note) for a ContactSystem; the library is cached per model."""
    if find_compiler() is None:
        return None, "no C compiler"
    eom = system.eom
    try:
        ode = casadi_functions(eom, names=("ode",))["ode"]
    except Exception as e:  # noqa: BLE001 - no ode Function for this model: stay in Python
        return None, f"no right-hand side Function ({e})"
    n = system.n
    if ode.numel_in(1) != 2 * n or ode.numel_in(2) != 0 or ode.numel_in(3) != system.p.size:
        return None, "the model has inputs or fixed parameters: contact stepping stays in Python"
    # kept in the EOM's workspace per right-hand side and contact objects (the contacts' own
    # objects are kept per model by impacts.simulate): building and serializing the gap and
    # impact Functions for the library's cache key costs ~1 ms a run

    return of(eom).by_content(eom, (), ("compiled_flight", system.m, bool(system.fixations)),
                              lambda: _build_flight(system, ode, tag), extra=(ode, *system.gaps))


def _build_flight(system, ode, tag: str) -> tuple[CompiledFlight | None, str]:
    import casadi as ca

    eom = system.eom
    x = ca.vertcat(eom.q, eom.qd)
    gapv = ca.vertcat(*[ca.SX(g.gap) for g in system.gaps]) if system.gaps else ca.SX.zeros(0, 1)
    gapf = ca.Function("contact_gap", [eom.t, x, eom.p], [gapv], ["t", "x", "p"], ["gap"])
    impf = impact_function(system, x)
    extra = {"contact_gap": gapf} if impf is None else {"contact_gap": gapf, "contact_impact": impf}
    engine = crk.engine_for(ode)
    loop, note = crk.cached_library((id(ode), gapf.serialize(), None if impf is None else impf.serialize(), engine),
                                    ode, extra, tag, engine)
    return (None if loop is None else CompiledFlight(loop)), note or ""


MAX_IMPACT_DOF = 12     # the symbolic M^-1 A^T of contact_impact grows as n^3


def impact_function(system, x):
    """``contact_impact(t, x, p) -> (g, u, D, W)`` for the impacts applied in C, or None when the
    model is not the simple case (model constraints, fixations, more than MAX_IMPACT_DOF
    coordinates): gaps g, normal speeds u = A q' + g_t, D = M^-1 A^T (n x k) and
    W_i = a_i M^-1 a_i^T, A = dg/dq."""
    import casadi as ca

    eom = system.eom
    if system.m or system.fixations or not system.gaps or system.n > MAX_IMPACT_DOF:
        return None
    g = ca.vertcat(*[ca.SX(gi.gap) for gi in system.gaps])
    A = ca.jacobian(g, eom.q)
    u = ca.mtimes(A, eom.qd) + ca.jacobian(g, eom.t)
    D = ca.solve(ca.SX(eom.M), A.T)
    W = ca.vertcat(*[ca.mtimes(A[i, :], D[:, i]) for i in range(system.k)])
    return ca.Function("contact_impact", [eom.t, x, eom.p], [ca.densify(g), ca.densify(u), ca.densify(D), ca.densify(W)],
                       ["t", "x", "p"], ["g", "u", "D", "W"])
