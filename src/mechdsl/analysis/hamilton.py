"""Hamilton's equations by the Legendre transform.

T is quadratic in the speeds, T = 1/2 qd'M qd + b'qd + T0, so the momenta are linear in them:

    p = dL/dqd = M qd + b,    qd = M^-1 (p - b),
    H(q, p, t) = p'qd - L = 1/2 (p - b)'M^-1 (p - b) - T0 + V,
    q' = dH/dp = qd(q, p, t),    p' = -dH/dq + Q_nc = dL/dq |_(q, qd(q,p), t) + Q - dD/dqd.

(-dH/dq at fixed p equals dL/dq at fixed qd: the identity that keeps the numeric form free of
derivatives of M^-1.)  Two forms:

- ``hamiltonian(eom)``: CasADi SX in (q, p, t, params) for the integrators (symplectic.py);
- ``format_hamiltonian(model)``: sympy text (or LaTeX) for ``mech equations --hamiltonian``,
  fully symbolic for small models (M inverted by sympy), otherwise in matrix form.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..diagnostics import Diagnostic, MechError
from ..eom import fold_inputs
from ..model import ir
from .core import Probe, dense, param_vector, parts, structure
from .symbolic import _latex_name, equation_layer_only, from_model, lagrangian_of, latex
from .symbolic import simplify_small as simplify
from .symbolic import sx_to_sympy, text


SYMBOLIC_MAX_N = 3            # sympy inverts M up to this size
SYMBOLIC_MAX_OPS = 400        # ... and when its entries are this small
SIMPLIFY_MAX_N = 12           # entries are simplified (sympy, ~0.05 s each) up to this many coordinates


@dataclass
class Hamiltonian:
    """CasADi form of H and Hamilton's equations (SX in q, pm, t, p)."""

    coords: tuple[str, ...]
    q: object
    pm: object                     # momentum symbols (n)
    t: object
    p: object
    H: object
    qd_of_p: object                # M^-1 (pm - b)
    pdot: object                   # dL/dq at qd(q, pm) + Q - dD/dqd
    momenta: object                # M qd + b, SX in (q, qd, t, p) of the EOM
    separable: bool                # M constant, b = 0, forces independent of the speeds
    autonomous: bool
    notes: list[str] = field(default_factory=list)
    # constrained models: Hamilton's equations hold with p' = -dH/dq + Q - G' lambda on g = 0
    # (the multipliers as in the DAE); mechdsl.rattle integrates them
    constrained: bool = False
    eom: object = field(default=None, repr=False)
    _fns: dict = field(default_factory=dict, repr=False)

    @property
    def n(self) -> int:
        return len(self.coords)

    def function(self, name: str):
        """Cached CasADi Functions: 'rhs' (q, pm, t, p) -> (qdot, pdot); 'H'; 'qd' (q, pm, t, p) -> qd;
        'momenta' (q, qd, t, p) -> pm; 'force' (q, t, p) -> pdot for separable H."""
        import casadi as ca

        f = self._fns.get(name)
        if f is None:
            a = [self.q, self.pm, self.t, self.p]
            if name == "rhs":
                f = ca.Function("ham_rhs", a, [self.qd_of_p, self.pdot])
            elif name == "H":
                f = ca.Function("ham_H", a, [self.H])
            elif name == "qd":
                f = ca.Function("ham_qd", a, [self.qd_of_p])
            elif name == "momenta":
                f = ca.Function("ham_p", [self.eom.q, self.eom.qd, self.eom.t, self.eom.p], [self.momenta])
            else:
                raise KeyError(name)
            self._fns[name] = f
        return f


def hamiltonian(eom, p=None) -> Hamiltonian:
    """The CasADi Hamiltonian of an EOM (for a constrained one: of its Lagrangian; the
    constraint forces -G' lambda are added by the integrator, mechdsl.rattle)."""
    eom = fold_inputs(eom)          # inputs held at their defaults: trailing parameters
    import casadi as ca

    pv = param_vector(eom, p)
    st = structure(eom, pv)
    if not st.quadratic_T:
        raise MechError(Diagnostic("E905", f"the kinetic energy of '{eom.name}' is not quadratic in the "
                                           "speeds: no Legendre transform in closed form"))
    pt = parts(eom)
    n = eom.n
    pm = ca.SX.sym("pm", n)
    M = eom.M
    b = pt.b
    qd_of_p = ca.solve(M, pm - b) if n else ca.SX.zeros(0)
    H = 0.5 * ca.dot(pm - b, qd_of_p) - pt.T0 + eom.V
    dLdq = ca.gradient(pt.L, eom.q)
    pdot = ca.substitute(dLdq + pt.Qtot, eom.qd, qd_of_p)
    momenta = ca.gradient(eom.T, eom.qd)
    sep, notes = _separable(eom, pt, st, pv)
    constrained = eom.g is not None and eom.m > 0
    if constrained:
        notes = notes + ["constrained: der(p) = -dH/dq + Q - G' lambda with g(q, t) = 0 (multipliers lambda)"]
    h = Hamiltonian(coords=tuple(eom.coords), q=eom.q, pm=pm, t=eom.t, p=eom.p, H=H, qd_of_p=qd_of_p,
                    pdot=pdot, momenta=momenta, separable=sep, autonomous=st.autonomous, notes=notes,
                    eom=eom, constrained=constrained)
    _check_regular(eom, pt, pv)
    return h


def _separable(eom, pt, st, pv) -> tuple[bool, list[str]]:
    """H = 1/2 p'M^-1 p + U(q, t) with constant M and speed-independent forces?"""
    import casadi as ca

    notes = []
    if st.has_T1:
        notes.append("not separable: T has terms linear in the speeds (gyroscopic / moving frame)")
        return False, notes
    pr = Probe.states(eom.n)
    fM = ca.Function("dM", pt.args, [ca.jacobian(ca.reshape(eom.M, -1, 1), ca.vertcat(eom.q, eom.t)),
                                     ca.jacobian(pt.Qtot, eom.qd), eom.M, pt.Qtot])
    vals = [[dense(o) for o in fM(pr.q[i], pr.qd[i], pr.t[i], pv)] for i in range(len(pr))]
    vals = [v for v in vals if all(np.all(np.isfinite(x)) for x in v)]
    if not vals:
        return False, ["not separable: could not evaluate M"]
    Ms = max(float(np.max(np.abs(v[2]))) for v in vals) or 1.0
    if any(np.max(np.abs(v[0]), initial=0.0) > 1e-10 * Ms for v in vals):
        notes.append("not separable: the mass matrix depends on the coordinates (or time)")
        return False, notes
    Qs = max(max(float(np.max(np.abs(v[3]), initial=0.0)) for v in vals), 1e-300)
    if any(np.max(np.abs(v[1]), initial=0.0) > 1e-10 * max(Qs, 1.0) for v in vals):
        notes.append("not separable in the Verlet sense: forces depend on the speeds (damping)")
        return False, notes
    return True, notes


def _check_regular(eom, pt, pv) -> None:
    """M must be invertible at the start state (else no Legendre transform there)."""
    try:
        q0, qd0 = eom.start(pv)
    except Exception:  # pragma: no cover - start values not evaluable: checked later by the caller
        return
    M, _ = pt.M_bias(q0, qd0, 0.0, pv)
    if M.size and (not np.all(np.isfinite(M)) or np.linalg.cond(M) > 1e14):
        raise MechError(Diagnostic("E906", f"the mass matrix of '{eom.name}' is singular at the start "
                                           "values: the momenta do not determine the speeds there",
                                   help="choose start values away from the coordinate singularity "
                                        "(e.g. Euler angles with theta = 0)"))


# --------------------------------------------------------------------------- text form


def format_hamiltonian(model, latex: bool = False) -> str:
    """Momenta, H(q, p, t) and Hamilton's equations as text (or LaTeX).

    ``model``: an ir.Model (equation layer through exprs.to_sympy; component models through
    their derived EOM), an EOM, or an object with an ``.eom`` attribute (mechdsl.api.Model).
    """
    import sympy as sp


    lg, eom = _lagrangian_for(model)
    n = len(lg.q)
    # a size limit, not a clock: larger models print their entries as derived (deterministic)
    simplify_small = simplify if n <= SIMPLIFY_MAX_N else (lambda e, angles=(): e)
    s = symbolic_hamilton(lg)
    P, pexpr, Msym, bsym, T0, small = s["P"], s["momenta"], s["M"], s["b"], s["T0"], s["small"]
    title = getattr(model, "name", None) or (eom.name if eom is not None else "model")
    fmt = (lambda e: _latex(e, lg, P)) if latex else (lambda e: _text(e))
    qdname = (lambda c: r"\dot{" + _lname(c) + "}") if latex else (lambda c: f"der({c})")
    pname = (lambda c: _latex(P[lg.coords.index(c)], lg, P)) if latex else (lambda c: _momentum_name(c, lg))
    lines = []
    cons = _constraint_items(eom, lg, fmt) if eom is not None and eom.m else []

    def lam_term(c, text=None):
        if not cons:
            return ""
        if latex:
            t = r" - (G^\top \lambda)" + ("" if c is None else "_{" + _lname(c) + "}")
        else:
            t = " - G' lambda" if c is None else f" - (G' lambda)[{c}]"
        return t if text != "0" else "-" + t[3:]

    if small:
        qd_sol, H, pdot = s["qd"], s["H"], s["pdot"]
        lines.append(("momenta", [(pname(c), fmt(e)) for c, e in zip(lg.coords, pexpr)]))
        lines.append(("Hamiltonian", [("H", fmt(H))]))
        lines.append(("Hamilton's equations", [(qdname(c), fmt(e)) for c, e in zip(lg.coords, qd_sol)]
                      + [(r"\dot{" + pname(c) + "}" if latex else f"der({pname(c)})", (lambda x, c: ("" if x == "0" and cons else x) + lam_term(c, x))(fmt(e), c))
                         for c, e in zip(lg.coords, pdot)]))
        how = "symbolic Legendre transform"
    else:
        lines.append(("momenta", [(pname(c), fmt(e)) for c, e in zip(lg.coords, pexpr)]))
        Msimp = Msym.applyfunc(lambda e: simplify_small(e, lg.q))
        entries = [(f"M[{i + 1},{j + 1}]", fmt(Msimp[i, j])) for i in range(n) for j in range(i, n)
                   if Msimp[i, j] != 0]
        lines.append(("mass matrix (p = M der(q) + b)", entries
                      + [(f"b[{i + 1}]", fmt(simplify_small(bsym[i], lg.q))) for i in range(n) if bsym[i] != 0]))
        lines.append(("Hamiltonian", [("H", "1/2 (p - b)' M^-1 (p - b) + V - T0" if not latex else
                                       r"\tfrac12 (p - b)^\top M^{-1} (p - b) + V - T_0"),
                                      ("V - T0" if not latex else "V - T_0", fmt(simplify_small(lg.V - T0, lg.q)))]))
        lines.append(("Hamilton's equations", [("der(q)" if not latex else r"\dot q", "M^-1 (p - b)" if not latex
                                                else r"M^{-1}(p - b)"),
                                               ("der(p)" if not latex else r"\dot p",
                                                ("dL/dq (at der(q) = M^-1 (p - b)) + Q - dD/d(der(q))" if not latex
                                                 else r"\partial L/\partial q + Q - \partial D/\partial \dot q")
                                                + lam_term(None))]))
        how = f"Legendre transform in matrix form ({n} coordinates: M is inverted numerically)"
        if n > SIMPLIFY_MAX_N:
            how += f"; entries not simplified (more than {SIMPLIFY_MAX_N} coordinates)"
    scleronomic = all(e == 0 for e in bsym) and sp.simplify(T0) == 0 and not lg.T.has(lg.t)
    note = ("H equals the energy T + V (scleronomic)" if scleronomic else
            "H = T2 - T0 + V is the Jacobi integral, not the energy T + V (moving frame)")
    if cons:
        lines.append(("constraints g(q, t) = 0, G = dg/dq (multipliers lambda; integrate with "
                      "method = rattle)" if not latex else r"constraints $g(q, t) = 0$, $G = \partial g/\partial q$",
                      cons))
    return _render(lines, title, how, note, latex)


def _render(lines, title: str, how: str, note: str, latex: bool) -> str:
    """format_hamiltonian's sections ``lines`` ((heading, [(name, value)])) as text or LaTeX."""
    if latex:
        body = [r"\begin{aligned}"]
        for head, items in lines:
            body.append(r"&\text{" + head + r"}\\")
            body += [f"{k} &= {v}\\\\" for k, v in items]
        body.append(r"\end{aligned}")
        return "% Hamiltonian of " + title + f" ({how}); {note}\n" + "\n".join(body) + "\n"
    out = [f"Hamiltonian of {title} ({how})"]
    for head, items in lines:
        out.append(f"  {head}:")
        w = max((len(k) for k, _ in items), default=0)
        out += [f"    {k.ljust(w)} = {v}" for k, v in items]
    out.append(f"  note: {note}")
    return "\n".join(out) + "\n"


def symbolic_hamilton(lg) -> dict:
    """The Legendre transform of a SymbolicLagrangian in sympy: momentum symbols "P", "momenta"
    dL/dqd, "M", "b", "T0"; and when M is small enough to invert ("small"), "qd" = M^-1 (p - b),
    "H" and "pdot" = dL/dq + Q - dD/dqd at qd(q, p)."""
    import sympy as sp


    n = len(lg.q)
    # a size limit, not a clock: larger models keep their entries as derived (deterministic)
    simplify_small = simplify if n <= SIMPLIFY_MAX_N else (lambda e, angles=(): e)
    P = [sp.Symbol(_momentum_name(c, lg), real=True) for c in lg.coords]
    pexpr = [simplify_small(sp.diff(lg.L, v), lg.q) for v in lg.qd]
    Msym = sp.Matrix(pexpr).jacobian(lg.qd)
    zero = {v: 0 for v in lg.qd}
    bsym = sp.Matrix([e.subs(zero) for e in pexpr])
    T0 = lg.T.subs(zero)
    out = {"P": P, "momenta": pexpr, "M": Msym, "b": bsym, "T0": T0,
           "small": n <= SYMBOLIC_MAX_N and all(sp.count_ops(e) <= SYMBOLIC_MAX_OPS for e in Msym)}
    if out["small"]:
        det = simplify_small(Msym.det(), lg.q)
        fdet = sp.factor(det)
        det = fdet if sp.count_ops(fdet) <= sp.count_ops(det) else det
        out["small"] = det != 0
    if not out["small"]:
        return out
    Qtot = [lg.Q[i] - sp.diff(lg.D, lg.qd[i]) for i in range(n)]
    adj = Msym.adjugate().applyfunc(lambda e: simplify_small(e, lg.q))
    dp = sp.Matrix(P) - bsym
    qd_sol = [_compact(simplify_small(sp.expand(e), lg.q) / det) for e in adj * dp]
    sub = dict(zip(lg.qd, qd_sol))
    out["qd"] = qd_sol
    out["H"] = (_compact(simplify_small(sp.expand((dp.T * adj * dp)[0, 0]), lg.q) / (2 * det))
                + simplify_small(lg.V - T0, lg.q))
    dLdq = [simplify_small(sp.diff(lg.L, qi), lg.q) for qi in lg.q]
    out["pdot"] = [(a + Qi).xreplace(sub) for a, Qi in zip(dLdq, Qtot)]
    return out


def _constraint_items(eom, lg, fmt) -> list[tuple[str, str]]:
    """(name, residual) for explicit constraint equations; one line per loop-closing joint."""
    import casadi as ca


    explicit = {c.name for c in eom.model.constraints} if eom.model is not None else set(eom.constraint_names)
    out, joints = [], []
    for i, name in enumerate(eom.constraint_names):
        if name in explicit:
            g = sx_to_sympy([ca.SX(eom.g)[i]], [eom.q, eom.t, eom.p], [lg.q, [lg.t], lg.p])[0][0, 0]
            out.append((f"g[{name}]", fmt(g)))
        else:
            j = name.split(".")[0]
            if j not in joints:
                joints.append(j)
    for j in joints:
        names = [c for c in eom.constraint_names if c.split(".")[0] == j]
        out.append((f"g[{j}.*]", f"closure of the loop at joint {j} ({', '.join(names)}); see mech equations"))
    return out


def _compact(e):
    """The shorter of e and its factored form (cancels common factors of a fraction)."""
    import sympy as sp

    try:
        f = sp.factor(e)
    except Exception:  # pragma: no cover - sympy could not factor; keep e
        return e
    return f if sp.count_ops(f) < sp.count_ops(e) else e


def _momentum_name(c: str, lg) -> str:
    name = f"p_{c}"
    return name if name not in lg.params and name not in lg.coords else f"p[{c}]"


def _text(e) -> str:
    return text(e)


def _latex(e, lg, P) -> str:
    return latex(e, lg, {Pi: "p_{" + _latex_name(c) + "}" for Pi, c in zip(P, lg.coords)})


def _lname(c):
    return _latex_name(c)


def _lagrangian_for(model):
    """(SymbolicLagrangian, eom or None) for an ir.Model, an EOM or an api Model."""
    if hasattr(model, "T") and hasattr(model, "qd"):          # an EOM
        return lagrangian_of(model), model
    if isinstance(model, ir.Model):
        if equation_layer_only(model):
            return from_model(model), None
        eom = _derive(model)
        return lagrangian_of(eom), eom
    if hasattr(model, "eom"):                                 # mechdsl.api.Model
        eom = model.eom
        return lagrangian_of(eom), eom
    raise TypeError(f"cannot form the Hamiltonian of {type(model).__name__}")


def _derive(model):
    """EOM of a component model through the mechanics stage (imported lazily)."""
    import importlib

    for mod, fn in (("mechdsl.derive", "derive"), ("mechdsl.mechanics", "derive")):
        try:
            m = importlib.import_module(mod)
        except ModuleNotFoundError:
            continue
        if hasattr(m, fn):
            return getattr(m, fn)(model)
    raise MechError(Diagnostic("E907", f"the Hamiltonian of component model '{model.name}' needs the "
                                       "mechanics stage (derive), which is not available"))
