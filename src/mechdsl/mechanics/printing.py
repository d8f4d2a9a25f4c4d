"""Lagrange's equations as people write them (``mech equations``), through sympy.

    d/dt (dL/d der(q_i)) - dL/dq_i + dD/d der(q_i) = Q_i,    L = T - V

Small models (at most MAX_COORDS coordinates, every expression below MAX_OPS operations and
all the expressions handed to sympy's simplification together below MAX_TOTAL_OPS) are printed
simplified (trigsimp, accelerations collected); anything larger is described by its structure
instead (which accelerations, coordinates and speeds each equation involves, and its size),
computed from the CasADi equations so it never hangs.  The limits count operations, never
seconds: what is printed depends on the model only, not on the machine or its load.
"""
from __future__ import annotations

from ..model import ir

MAX_COORDS = 6
MAX_OPS = 3000            # operations (sympy count_ops) of one expression
MAX_TOTAL_OPS = 8000      # operations of everything simplified for one model (shipped models: <= 4300)


def _text_printer(names: dict[str, str]):
    import sympy as sp
    from sympy.core.function import AppliedUndef
    from sympy.printing.str import StrPrinter

    class P(StrPrinter):
        def _print_Derivative(self, e):
            s = self._print(e.expr)
            for _ in range(sum(c for _, c in e.variable_count)):
                s = f"der({s})"
            return s

        def _print_Function(self, e):
            if isinstance(e, AppliedUndef):
                return names.get(e.func.__name__, e.func.__name__)
            return super()._print_Function(e)

        def _print_Symbol(self, e):
            return names.get(e.name, e.name)

        def _print_Pow(self, e, rational=False):
            return super()._print_Pow(e, rational).replace("**", "^")

    return lambda e: P({"order": "none"}).doprint(e) if isinstance(e, sp.Basic) else str(e)


def format_equations(model: ir.Model, latex: bool = False, max_coords: int = MAX_COORDS,
                     max_ops: int = MAX_OPS, max_total_ops: int = MAX_TOTAL_OPS) -> str:
    n = len(model.coordinates)
    if n == 0:
        return f"{model.name}: no coordinates, nothing to integrate\n"
    if n > max_coords:
        return format_structure(model, f"{n} coordinates (more than {max_coords}): too large to print readably")
    try:
        return _format_small(model, latex, max_ops, max_total_ops)
    except _TooLarge as e:
        return format_structure(model, str(e))


class _TooLarge(Exception):
    pass


class _Budget:
    """Operations handed to sympy's simplification so far, against a fixed limit."""

    def __init__(self, limit: int):
        self.limit, self.used = limit, 0

    def spend(self, ops: int) -> None:
        self.used += ops
        if self.used > self.limit:
            raise _TooLarge(f"simplifying the equations needs more than {self.limit} operations: "
                            "too large to print readably")


def lagrange_equations(model: ir.Model, max_ops: int = MAX_OPS, max_total_ops: int = MAX_TOTAL_OPS):
    """(symbolic model, T, V, D, Q, [(acceleration terms, rest, Q_i)]) with T, V, D, Q
    simplified; each equation reads  acceleration terms + rest = Q_i.  _TooLarge when one
    expression exceeds max_ops operations or all of them together max_total_ops."""
    import sympy as sp

    from .symbolic import symbolic_model

    sm = symbolic_model(model)
    t = sm.t
    q = sm.coords
    qd = [sp.diff(x, t) for x in q]
    qdd = [sp.diff(x, t, 2) for x in q]
    budget = _Budget(max_total_ops)

    def trigsimp(e):
        budget.spend(sp.count_ops(e))
        return sp.trigsimp(e)

    def simp(e):
        if sp.count_ops(e) > max_ops:
            raise _TooLarge(f"an expression has more than {max_ops} operations: too large to print readably")
        return trigsimp(sp.expand(e))

    def quadratic(T):
        """T = 1/2 qd^T M qd + b qd + T0 with every coefficient simplified on its own (far
        cheaper than simplifying T whole)."""
        if sp.count_ops(T) > max_ops:
            raise _TooLarge(f"the kinetic energy has more than {max_ops} operations: too large to print readably")
        T = sp.expand(T)
        out = sp.S.Zero
        for i in range(len(qd)):
            for j in range(i, len(qd)):
                c = sp.diff(T, qd[i], qd[j])
                if c != 0:
                    c = sp.factor_terms(trigsimp(c))
                    out += (c / 2 if i == j else c) * qd[i] * qd[j]
        zero = {x: 0 for x in qd}
        lin = [sp.diff(T, x).subs(zero) for x in qd]
        out += sum(trigsimp(c) * x for c, x in zip(lin, qd) if c != 0)
        return out + trigsimp(T.subs(zero))

    T, V, D = quadratic(sm.T), simp(sm.V), simp(sm.D)
    Q = [simp(x) for x in sm.Q]
    L = T - V
    eqs = []
    for i in range(len(q)):
        lhs = sp.diff(sp.diff(L, qd[i]), t) - sp.diff(L, q[i]) + sp.diff(D, qd[i])
        lhs = sp.expand(lhs)
        if sp.count_ops(lhs) > max_ops:
            raise _TooLarge(f"the equation of {model.coordinates[i].name} has more than {max_ops} operations")
        parts = sp.collect(lhs, qdd, evaluate=False)
        terms = []
        for a in qdd:
            if a in parts:
                terms.append(trigsimp(parts[a]) * a)
        rest = parts.get(sp.S.One, sp.S.Zero)
        eqs.append((sp.Add(*terms, evaluate=False) if terms else sp.S.Zero, trigsimp(rest), Q[i]))
    return sm, T, V, D, Q, eqs


def multiplier_terms(model: ir.Model, sm) -> tuple[list, dict]:
    """The constraint forces of Lagrange's equations, one term per multiplier:
    ([-sum_c dg_c/dq_i lambda[c] for each coordinate i], {sympy name: "lambda[c]"}).  Explicit
    constraints from their residuals; loop-closing joints from the closure rows of the derived
    equations (their multipliers are reaction components).  ([0, ...], {}) without constraints."""
    import sympy as sp

    n = len(sm.coords)
    if not model.constraints and not any(j.closes_loop for j in model.joints):
        return [sp.S.Zero] * n, {}
    from .symbolic import _Builder

    b = _Builder(model)
    b.build()
    rows = [(c.name, b.tr(c.residual)) for c in model.constraints]
    if any(j.closes_loop for j in model.joints):
        import casadi as ca

        from ..analysis.symbolic import sx_to_sympy
        from .derive import derive

        e = derive(model)
        explicit = {c.name for c in model.constraints}
        idx = [i for i, nm in enumerate(e.constraint_names) if nm not in explicit]
        qs = [b.q[c] for c in e.coords]
        ps = [b.p[p] for p in e.params]
        (g,) = sx_to_sympy([ca.vertcat(*[e.g[i] for i in idx])], [e.q, e.p, e.t], [qs, ps, [b.t]])
        rows += [(e.constraint_names[i], g[k, 0]) for k, i in enumerate(idx)]
    names, terms = {}, [sp.S.Zero] * n
    for k, (name, g) in enumerate(rows):
        lam = sp.Symbol(f"lambda[{name}]")
        names[lam.name] = f"lambda[{name}]"
        for i, x in enumerate(sm.coords):
            d = sp.diff(g, x)
            if d != 0:
                d = sp.trigsimp(sp.expand(d))
            if d != 0:
                terms[i] = terms[i] - d * lam
    return terms, names


def _format_small(model: ir.Model, latex: bool, max_ops: int, max_total_ops: int) -> str:
    sm, T, V, D, Q, eqs = lagrange_equations(model, max_ops, max_total_ops)
    q = sm.coords
    names = [c.name for c in model.coordinates]
    lam_terms, lam_names = multiplier_terms(model, sm)
    if latex:
        return _latex(model, sm, T, V, D, Q, eqs, lam_terms, lam_names)
    pr = _text_printer({**sm.names, **lam_names})
    out = [f"{model.name}: Lagrange's equations in {len(q)} coordinate{'s' * (len(q) != 1)} ({', '.join(names)})",
           "  d/dt(dL/d der(q)) - dL/dq + dD/d der(q) = Q,   L = T - V", "",
           f"  T = {pr(T)}", f"  V = {pr(V)}", f"  D = {pr(D)}"]
    nz = [(names[i], Q[i]) for i in range(len(q)) if Q[i] != 0]
    out += [f"  Q[{nm}] = {pr(x)}" for nm, x in nz] if nz else ["  Q = 0"]
    out.append("")
    quat = _quaternion_blocks(model)
    for nm, (acc, rest, Qi), lt in zip(names, eqs, lam_terms):
        lhs = pr(acc) if rest == 0 else (pr(rest) if acc == 0 else f"{pr(acc)} + {pr(rest)}")
        force = Qi + lt
        extra = f" + 2*mu[{quat[nm]}]*{nm}" if nm in quat else ""
        rhs = (f"{pr(force)}{extra}" if force != 0 else extra.replace(" + ", "", 1)) if extra else pr(force)
        out.append(f"  {nm}:  {lhs} = {rhs}")
    for j in dict.fromkeys(quat.values()):
        qs = [k for k, v in quat.items() if v == j]
        out.append(f"  with {' + '.join(f'{k}^2' for k in qs)} = 1 (unit quaternion of {j}; "
                   f"mu[{j}] is its multiplier)")
    out += _constraint_lines(model, pr, sm)
    return "\n".join(out).replace("+ -", "- ") + "\n"


def _quaternion_blocks(model: ir.Model) -> dict[str, str]:
    """coordinate name -> joint name for quaternion joints whose variables are coordinates."""
    out = {}
    for j in model.tree_joints:
        if j.kind in ("spherical", "free") and j.option("parametrization", "euler").lower() == "quaternion":
            for v in j.variables:
                if v.role in ("q0", "q1", "q2", "q3") and v.coordinate:
                    out[v.coordinate] = j.name
    return out


def _constraint_lines(model: ir.Model, pr, sm) -> list[str]:
    """The constraints g = 0 whose multipliers lambda enter as -G^T lambda, G = dg/dq."""
    if not model.constraints and not any(j.closes_loop for j in model.joints):
        return []
    from ..model.units import multiplier_unit
    from . import joints as J
    from .symbolic import _Builder

    out = ["", "  constraints g(q, t) = 0, each multiplier lambda[c] in J / [g_c] (docs/constraints.md):"]
    b = _Builder(model)
    b.build()
    for c in model.constraints:
        unit = multiplier_unit(c.dim)
        out.append(f"  {c.name}:  {pr(b.tr(c.residual))} = 0" + (f"   (lambda[{c.name}] in {unit})" if unit else ""))
    for j in model.joints:
        if j.closes_loop:
            cl = J.kind_of(j).closure
            out.append(f"  loop closed by {j.kind} joint {j.name}: its two joint frames coincide "
                       f"(translation {cl.translation}, rotation {cl.rotation}); multipliers = reaction "
                       f"components on the child in the joint frame at {j.parent}")
    return out


def _latex(model, sm, T, V, D, Q, eqs, lam_terms=None, lam_names=None) -> str:
    import sympy as sp
    from sympy.physics.vector.printing import vlatex

    names = [c.name for c in model.coordinates]
    sub = {sp.Symbol(k): sp.Symbol(r"\lambda_{\mathrm{" + _tex_escape(v[7:-1]) + "}}")
           for k, v in (lam_names or {}).items()}
    lam_terms = [x.subs(sub) for x in (lam_terms or [sp.S.Zero] * len(eqs))]
    rows = [f"T &= {vlatex(T)}", f"V &= {vlatex(V)}", f"D &= {vlatex(D)}"]
    for nm, x in zip(names, Q):
        if x != 0:
            rows.append(f"Q_{{\\mathrm{{{_tex_escape(nm)}}}}} &= {vlatex(x)}")
    for (acc, rest, Qi), lt in zip(eqs, lam_terms):
        lhs = vlatex(acc) if rest == 0 else (vlatex(rest) if acc == 0 else f"{vlatex(acc)} + {vlatex(rest)}")
        rows.append(f"{lhs} &= {vlatex(Qi + lt)}")
    body = " \\\\\n".join(rows).replace("+ -", "- ")
    return (f"% {model.name}: Lagrange's equations, coordinates {', '.join(names)}\n"
            f"\\begin{{align}}\n{body}\n\\end{{align}}\n")


def _tex_escape(s: str) -> str:
    return s.replace("_", r"\_")


def format_structure(model: ir.Model, reason: str) -> str:
    """Which accelerations, coordinates and speeds each equation involves, and its size."""
    import casadi as ca

    from .derive import derive

    e = derive(model)
    n = e.n
    qdd = ca.SX.sym("qdd", n)
    out = [f"{model.name}: {reason}; the structure of M(q) der(der(q)) = bias(q, der(q), t) instead",
           f"  {e.notes[0] if e.notes else 'route ' + e.route}", ""]
    names = list(e.coords)
    w = max(len(x) for x in names)
    for i in range(n):
        row = ca.mtimes(e.M[i, :], qdd) - e.bias[i]
        acc = [j for j, d in enumerate(ca.which_depends(row, qdd, 1, False)) if d]
        pos = [j for j, d in enumerate(ca.which_depends(row, e.q, 1, False)) if d]
        spd = [j for j, d in enumerate(ca.which_depends(row, e.qd, 1, False)) if d]
        ops = ca.Function("r", [e.q, e.qd, e.t, e.p, qdd], [row]).n_instructions()
        out.append(f"  {names[i]:<{w}}  accelerations {_span(acc, names, n)}; coordinates {_span(pos, names, n)}; "
                   f"speeds {_span(spd, names, n)}; {ops} operations")
    if n <= 60:
        out += ["", "  mass-matrix pattern (x: nonzero):"]
        for i in range(n):
            out.append("  " + "".join("x" if not ca.SX(e.M[i, j]).is_zero() else "." for j in range(n)))
    if e.m:
        out += ["", f"  {e.m} constraint equations: {', '.join(e.constraint_names)}"]
    return "\n".join(out) + "\n"


def _span(idx, names, n) -> str:
    if not idx:
        return "none"
    if len(idx) == n:
        return f"all {n}"
    if len(idx) <= 4:
        return ", ".join(names[j] for j in idx)
    return f"{len(idx)} of {n} ({names[idx[0]]} .. {names[idx[-1]]})"
