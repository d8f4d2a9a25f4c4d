"""``Model.fit(..., method="ipopt")``: the least-squares problem handed to IPOPT (CasADi's nlpsol).

The NLP is one CasADi MX graph: the unknowns z (theta / scale, the log-parameter scaling the
Levenberg-Marquardt minimizer uses) -> each experiment's parameter vector (dependent
parameters through the model's ``parameters`` Function) and start (start values written as
expressions of parameters through ``start``; fitted start values and the settings' overrides
in their places) -> the prepared trajectory Function (``Prepared.trajectory``: the run's
integrator) -> the weighted residuals at the data's samples; objective 0.5 |r|^2, bounds the
parameters' min / max (or ``bounds``).  IPOPT's derivatives are CasADi's exact ones of that
graph (the gradient an adjoint of the integrator); the Hessian of the Lagrangian is the
Gauss-Newton one, J'J with J the forward sensitivities of the residuals (``hess_lag``), as
Levenberg-Marquardt uses: exact second derivatives through an integrator would cost a
second-order sensitivity run per iteration, and L-BFGS took twice the iterations.  A constrained model's consistent
initialization is a Newton solve outside the graph: refused here (method="lm" fits it).
"""
from __future__ import annotations

import casadi as ca
import numpy as np

from ..diagnostics import UsageError
from ..eom.codegen import casadi_functions, free_parameters
from ..eom.start import start_vector
from ..simulation.trajectory import overridden


def ipopt(runs, theta0, lo, hi, scale, max_iterations, tol=1e-9):
    """Minimize 0.5 |r(theta)|^2 over the bounds with IPOPT: (theta, success, message,
    iterations, evaluations, gradients), the fields of ``fit.Solution``."""
    for r in runs:
        if r.tr.constrained:
            raise UsageError(f"method='ipopt': {r.tr.eom.name} is constrained, and its consistent start is "
                             "solved outside CasADi's graph; fit it with method='lm'")
    k = theta0.size
    z = ca.MX.sym("z", k)
    theta = z * ca.DM(scale)
    res = [_residual(r, theta) for r in runs]
    r_all = ca.vertcat(*res)
    nlp = {"x": z, "f": 0.5 * ca.sumsqr(r_all)}
    J = ca.jacobian(r_all, z)                 # forward sensitivities of the runs, k directions
    lam_f, lam_g, p0 = ca.MX.sym("lam_f"), ca.MX.sym("lam_g", 0), ca.MX.sym("p", 0)
    hess = ca.Function("hess_gn", [z, p0, lam_f, lam_g], [ca.triu(lam_f * ca.mtimes(J.T, J))],
                       ["x", "p", "lam_f", "lam_g"], ["triu_hess_gamma_x_x"])
    opts = {"ipopt.print_level": 0, "ipopt.sb": "yes", "print_time": False, "error_on_fail": False,
            "ipopt.max_iter": int(max_iterations), "ipopt.tol": tol, "ipopt.acceptable_tol": 1e-10,
            "hess_lag": hess,
            "ipopt.nlp_scaling_method": "gradient-based", "calc_lam_p": False}
    solver = ca.nlpsol("fit_ipopt", "ipopt", nlp, opts)
    sol = solver(x0=theta0 / scale, lbx=lo / scale, ubx=hi / scale)
    st = solver.stats()
    z_opt = np.array(sol["x"], float).ravel()
    status = str(st.get("return_status", "unknown"))
    ok = bool(st.get("success", False))
    message = ("converged (IPOPT: " + status + ")") if ok else f"IPOPT: {status}"
    return (np.clip(z_opt * scale, lo, hi), ok, message, int(st.get("iter_count", 0)),
            int(st.get("n_call_nlp_f", 0)), int(st.get("n_call_nlp_grad_f", 0)))


def _residual(run, theta) -> ca.MX:
    """The run's weighted residuals as an MX expression of the global unknowns ``theta``."""
    tr, eom, unk = run.tr, run.tr.eom, run.unk
    local = [theta[int(j)] for j in run.where]
    pv = _parameters(eom, run.pv, unk, local)
    x = _start(eom, run.x0, run.pv, pv, unk, local)
    out = tr.function(x, pv)
    Y = out[0] if isinstance(out, (list, tuple)) else out
    rows = [int(i) for i in run.rows]
    cols = [int(c) for c in run.cols]
    model = ca.vertcat(*[Y[i, cols] for i in rows])            # (n_columns, N), data column order
    return ca.vec((model - ca.DM(run.exp.Y)) * ca.DM(run.w))


def _parameters(eom, pv0, unk, local) -> ca.MX:
    free = list(free_parameters(eom))
    if not free:
        return ca.MX(ca.DM(np.asarray(pv0, float)))
    values = [ca.MX(float(pv0[eom.params.index(n)])) for n in free]
    for u, v in zip(unk.items, local):
        if u.kind == "parameter":
            values[free.index(eom.params[u.index])] = v
    f = casadi_functions(eom, names=("parameters",))["parameters"]
    return f(ca.vertcat(*values))


def _start(eom, x0, pv0, pv, unk, local) -> ca.MX:
    """[q0; qd0]: the model's start values at the parameters ``pv`` (symbolic), the settings'
    overrides ``x0`` as given, the fitted start values at theirs."""
    f = casadi_functions(eom, names=("start",))["start"]
    q0, qd0 = f(pv)
    x = ca.vertcat(q0, qd0)
    given = start_vector(eom, x0, pv0)
    elems = [x[i] for i in range(2 * eom.n)]
    for i in overridden(eom, x0):
        elems[i] = ca.MX(float(given[i]))
    for u, v in zip(unk.items, local):
        if u.kind == "start":
            elems[u.index] = v
    return ca.vertcat(*elems)
