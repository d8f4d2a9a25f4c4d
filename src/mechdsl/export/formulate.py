"""What the exporter takes from the rest of mechdsl beyond the stable API, in one place.

The FMU needs, per model, the problem ``mech simulate`` solves: the minimal-coordinate ODE,
or for a constrained model the index-1 ODE with the multipliers solved (the "projection"
formulation's right-hand side without its Baumgarte terms), the contacts and fixations,
and the defaults of the contact and DAE options.  Every import of a module that is being
moved (simulation back ends, dae/, impacts/) is here, so that a merge re-points only this
file.  When ``Model.casadi()`` returns the formulated problem's Functions (issue 22),
``index1_ode`` can become ``model.casadi()["ode"]``.
"""
from __future__ import annotations

import numpy as np


def index1_ode(eom, pv):
    """(Function ``(t, x, u, p) -> (xdot, lam)``, active rows) of a constrained model: the
    index-1 ODE M q'' + G' lam = bias, G q'' = -(G q')' of an independent subset of the
    constraints (chosen at the consistent start, as the DAE back end does: dae.dof), lam of
    every constraint (0 for a dropped redundant one), in the EOM's sign convention
    (M q'' = bias - G' lam).  Inputs are folded into the parameters for the DAE pieces and
    passed on as u.  Built from dae.constrained_system (the formulation), only here."""
    import casadi as ca

    from ..dae.dof import dof_report
    from ..dae.init import initialize
    from ..dae.constrained_system import ConstrainedSystem
    from ..eom import fold_inputs

    folded = fold_inputs(eom)
    pf = np.r_[np.asarray(pv, float).ravel(), np.asarray(eom.input_defaults, float).ravel()]
    try:
        q0 = initialize(folded, p=pf).q
    except Exception:  # noqa: BLE001 - an inconsistent start is the FMU's to report (at its start)
        q0 = folded.start(pf)[0]
    active = tuple(int(i) for i in dof_report(folded, q0, 0.0, pf).independent)
    system = ConstrainedSystem.build(folded, pf, active)
    n, nu, m = eom.n, eom.nu, eom.m
    Sym = ca.SX if system.route in ("sx", "schur") else ca.MX
    t, x, u, p = Sym.sym("t"), Sym.sym("x", 2 * n), Sym.sym("u", nu), Sym.sym("p", eom.p.numel())
    qdd, lam = system.fn["accel"](x[:n], x[n:], t, ca.vertcat(p, u), 0, 0)
    pos = {i: j for j, i in enumerate(active)}
    lam_full = ca.vertcat(*[lam[pos[i]] if i in pos else Sym(0) for i in range(m)]) if m else Sym(0, 1)
    f = ca.Function("mech_ode", [t, x, u, p], [ca.vertcat(x[n:], qdd), lam_full],
                    ["t", "x", "u", "p"], ["xdot", "lam"])
    return f, active


def contacts(eom):
    """(gaps, fixations) of the model's contacts (mechdsl.impacts.gaps)."""
    from ..impacts.gaps import contact_gaps

    return contact_gaps(eom)


def point_position(eom, point):
    """World position (SX (3,)) of a named point (a fixation's point)."""
    from ..impacts.gaps import point_position as pp

    return pp(eom, point)


def contact_defaults(settings) -> dict:
    """The contact options of a run with these settings (the settings group ``contacts``, with
    the tolerances the event loop derives from them, mechdsl.impacts.contact_run.ContactRun):
    rest_speed, impact order (0 simultaneous, 1 sequential), max_events, samples, acc_tol."""
    from ..impacts.contact_run import ContactRun

    o = ContactRun(settings.contacts, settings.rtol, settings.atol)
    return {"rest_speed": o.rest_speed, "impact_order": 1 if o.impact_order == "sequential" else 0,
            "max_events": o.max_events, "samples": o.samples, "acc_tol": o.acc_tol}


def dae_drift_bound(atol: float) -> float:
    """The DAE back end's default drift bound (simulation.settings.DaeOptions.bound)."""
    from ..simulation.settings import DaeOptions

    return DaeOptions().bound(float(atol))
