"""The symbolic route: T, V, D, Q as sympy, and the exact linear model derived from them.

Two independent sources of sympy expressions:

- ``from_model(model)``: the equation layer of an ``ir.Model`` (kinetic/potential/dissipation
  terms and generalized forces) through ``exprs.to_sympy`` -- no CasADi involved;
- ``from_eom(eom)``: any EOM, by reading the CasADi SX graph instruction by instruction
  (``sx_to_sympy``); this is the route for component models.

``symbolic_linearization`` differentiates Lagrange's equations in sympy (d/dt by the chain
rule) and substitutes the state; parameters stay symbols.  Exact values (0, pi/2, ...) are
kept exact (numbers within 1e-12 of a small rational multiple of pi or a small rational).
"""
from __future__ import annotations

import math
from dataclasses import field
from fractions import Fraction

import numpy as np

from ..eom import fold_inputs
from ..model import ir
from ..model.exprs import to_sympy
from ..model.records import record


class Untranslatable(Exception):
    """An expression this symbolic route cannot express (the caller falls back to another route)."""


# --------------------------------------------------------------------------- numbers


def exact_number(v: float):
    """sympy number for v: an integer, a small rational, a rational multiple of pi, or a Float."""
    import sympy as sp

    v = float(v)
    if not math.isfinite(v):
        return sp.Float(v)
    if v == int(v) and abs(v) < 1e15:
        return sp.Integer(int(v))
    fr = Fraction(v).limit_denominator(1000)
    if abs(float(fr) - v) <= 1e-15 * max(1.0, abs(v)):
        return sp.Rational(fr.numerator, fr.denominator)
    fp = Fraction(v / math.pi).limit_denominator(48)
    if fp != 0 and abs(float(fp) * math.pi - v) <= 1e-13 * max(1.0, abs(v)):
        return sp.Rational(fp.numerator, fp.denominator) * sp.pi
    return sp.Float(v)


def exact_value(v: float, tol: float = 1e-12):
    """Like exact_number but accepting values within tol (a computed equilibrium, say)."""
    import sympy as sp

    v = float(v)
    if abs(v) <= tol:
        return sp.Integer(0)
    for den in (1, 2, 3, 4, 6, 8, 12):
        k = round(v / math.pi * den)
        if k and abs(k * math.pi / den - v) <= tol * max(1.0, abs(v)):
            return sp.Rational(k, den) * sp.pi
    fr = Fraction(v).limit_denominator(1000)
    if abs(float(fr) - v) <= tol * max(1.0, abs(v)):
        return sp.Rational(fr.numerator, fr.denominator)
    return sp.Float(v)


# --------------------------------------------------------------------------- SX -> sympy


def sx_to_sympy(exprs, inputs, symbols):
    """Translate CasADi SX expressions to sympy Matrices.

    inputs: list of purely symbolic SX (dense vectors); symbols: for each input, the sympy
    symbols of its entries.  Returns one sympy Matrix per expression (same shape).
    """
    import casadi as ca
    import sympy as sp

    f = ca.Function("to_sympy", list(inputs), [ca.SX(e) for e in exprs])
    work: dict[int, object] = {}
    outs = [[sp.Integer(0)] * f.sparsity_out(i).nnz() for i in range(f.n_out())]
    for k in range(f.n_instructions()):
        op = f.instruction_id(k)
        i = f.instruction_input(k)
        o = f.instruction_output(k)
        if op == ca.OP_INPUT:
            work[o[0]] = symbols[i[0]][i[1]]
        elif op == ca.OP_OUTPUT:
            outs[o[0]][o[1]] = work[i[0]]
        elif op == ca.OP_CONST:
            work[o[0]] = exact_number(f.instruction_constant(k))
        else:
            work[o[0]] = _apply(op, [work[j] for j in i])
    result = []
    for idx in range(f.n_out()):
        sp_ = f.sparsity_out(idx)
        rows, cols = sp_.get_triplet()
        Mx = sp.zeros(sp_.size1(), sp_.size2())
        for j, (r, c) in enumerate(zip(rows, cols)):
            Mx[r, c] = outs[idx][j]
        result.append(Mx)
    return result


def _apply(op, a):
    import casadi as ca
    import sympy as sp

    table = {
        ca.OP_ASSIGN: lambda: a[0], ca.OP_ADD: lambda: a[0] + a[1], ca.OP_SUB: lambda: a[0] - a[1],
        ca.OP_MUL: lambda: a[0] * a[1], ca.OP_DIV: lambda: a[0] / a[1], ca.OP_NEG: lambda: -a[0],
        ca.OP_EXP: lambda: sp.exp(a[0]), ca.OP_LOG: lambda: sp.log(a[0]), ca.OP_POW: lambda: a[0] ** a[1],
        ca.OP_CONSTPOW: lambda: a[0] ** a[1], ca.OP_SQRT: lambda: sp.sqrt(a[0]),
        ca.OP_SQ: lambda: a[0] ** 2, ca.OP_TWICE: lambda: 2 * a[0], ca.OP_SIN: lambda: sp.sin(a[0]),
        ca.OP_COS: lambda: sp.cos(a[0]), ca.OP_TAN: lambda: sp.tan(a[0]), ca.OP_ASIN: lambda: sp.asin(a[0]),
        ca.OP_ACOS: lambda: sp.acos(a[0]), ca.OP_ATAN: lambda: sp.atan(a[0]),
        ca.OP_ATAN2: lambda: sp.atan2(a[0], a[1]), ca.OP_SINH: lambda: sp.sinh(a[0]),
        ca.OP_COSH: lambda: sp.cosh(a[0]), ca.OP_TANH: lambda: sp.tanh(a[0]),
        ca.OP_ASINH: lambda: sp.asinh(a[0]), ca.OP_ACOSH: lambda: sp.acosh(a[0]),
        ca.OP_ATANH: lambda: sp.atanh(a[0]), ca.OP_INV: lambda: 1 / a[0], ca.OP_FABS: lambda: sp.Abs(a[0]),
        ca.OP_SIGN: lambda: sp.sign(a[0]), ca.OP_FLOOR: lambda: sp.floor(a[0]),
        ca.OP_CEIL: lambda: sp.ceiling(a[0]), ca.OP_FMIN: lambda: sp.Min(a[0], a[1]),
        ca.OP_FMAX: lambda: sp.Max(a[0], a[1]), ca.OP_HYPOT: lambda: sp.sqrt(a[0] ** 2 + a[1] ** 2),
        ca.OP_LOG1P: lambda: sp.log(1 + a[0]), ca.OP_EXPM1: lambda: sp.exp(a[0]) - 1,
        ca.OP_FMOD: lambda: sp.Mod(a[0], a[1]), ca.OP_COPYSIGN: lambda: sp.Abs(a[0]) * sp.sign(a[1]),
        ca.OP_LT: lambda: sp.Piecewise((1, sp.Lt(a[0], a[1])), (0, True)),
        ca.OP_LE: lambda: sp.Piecewise((1, sp.Le(a[0], a[1])), (0, True)),
        ca.OP_EQ: lambda: sp.Piecewise((1, sp.Eq(a[0], a[1])), (0, True)),
        ca.OP_NE: lambda: sp.Piecewise((1, sp.Ne(a[0], a[1])), (0, True)),
        ca.OP_NOT: lambda: sp.Piecewise((1, sp.Eq(a[0], 0)), (0, True)),
        ca.OP_AND: lambda: sp.Piecewise((1, sp.And(sp.Ne(a[0], 0), sp.Ne(a[1], 0))), (0, True)),
        ca.OP_OR: lambda: sp.Piecewise((1, sp.Or(sp.Ne(a[0], 0), sp.Ne(a[1], 0))), (0, True)),
        ca.OP_IF_ELSE_ZERO: lambda: sp.Piecewise((a[1], sp.Ne(a[0], 0)), (0, True)),
        ca.OP_ERF: lambda: sp.erf(a[0]),
    }
    fn = table.get(op)
    if fn is None:
        raise Untranslatable(f"CasADi operation {op} has no sympy translation")
    return fn()


# --------------------------------------------------------------------------- T, V, D, Q as sympy


@record(frozen=False)
class SymbolicLagrangian:
    """T, V, D (sympy scalars) and Q (list) in the symbols q, qd, t and params."""

    coords: tuple[str, ...]
    params: tuple[str, ...]
    q: list
    qd: list
    t: object
    p: list
    T: object
    V: object
    D: object
    Q: list
    route: str                     # 'ir' | 'casadi'

    @property
    def L(self):
        return self.T - self.V

    @property
    def param_symbols(self) -> dict:
        return dict(zip(self.params, self.p))


def make_symbols(coords, params):
    import sympy as sp

    q = [sp.Symbol(c, real=True) for c in coords]
    qd = [sp.Symbol(f"der({c})", real=True) for c in coords]
    t = sp.Symbol("time", real=True)
    p = [sp.Symbol(n, real=True) for n in params]
    return q, qd, t, p


def from_eom(eom) -> SymbolicLagrangian:
    import casadi as ca


    eom = fold_inputs(eom)          # inputs appear as symbols, like parameters (F in Q of the cart-pole)
    q, qd, t, p = make_symbols(eom.coords, eom.params)
    T, V, D, Q = sx_to_sympy([eom.T, eom.V, eom.D, ca.SX(eom.Q)], [eom.q, eom.qd, eom.t, eom.p],
                             [q, qd, [t], p])
    return SymbolicLagrangian(tuple(eom.coords), tuple(eom.params), q, qd, t, p, T[0, 0], V[0, 0],
                              D[0, 0], [Q[i, 0] for i in range(len(q))], "casadi")


def equation_layer_only(model) -> bool:
    """True when the model is written with T, V, D, Q only (no bodies, joints or other forces)."""
    return (not model.bodies and not model.joints and not model.constraints
            and all(isinstance(f, ir.GeneralizedForce) for f in model.forces))


def from_model(model) -> SymbolicLagrangian:
    """T, V, D, Q of an equation-layer ir.Model through exprs.to_sympy (independent of CasADi)."""
    import sympy as sp


    if not equation_layer_only(model):
        raise Untranslatable("the ir route covers equation-layer models (T, V, D, Q) only")
    coords = model.coordinate_names
    params = tuple(pp.name for pp in model.real_parameters)
    q, qd, t, p = make_symbols(coords, params)
    qi = dict(zip(coords, q))
    qdi = dict(zip(coords, qd))
    pi_ = dict(zip(params, p))
    # dependent parameters that are not entries of p (integer parameters): their values
    others = {pp.name: pp for pp in model.parameters if pp.name not in pi_}

    def leaf(n):
        if isinstance(n, ir.Param):
            if n.name in pi_:
                return pi_[n.name]
            return exact_number(others[n.name].value)
        if isinstance(n, ir.Coord):
            return qi[n.name]
        if isinstance(n, ir.Speed):
            return qdi[n.name]
        if isinstance(n, ir.Time):
            return t
        if isinstance(n, ir.TimeDer):
            inner = to_sympy(n.expr, leaf)
            return sum(sp.diff(inner, a) * b for a, b in zip(q, qd)) + sp.diff(inner, t)
        raise Untranslatable(f"{type(n).__name__} in an equation-layer model")

    def conv(expr):      # folded constants arrive as Floats (1/2 -> 0.5): back to exact numbers
        e = to_sympy(expr, leaf)
        return e.xreplace({f: exact_number(float(f)) for f in e.atoms(sp.Float)})

    T = V = D = sp.Integer(0)
    for term in model.terms:
        e = conv(term.expr)
        if term.kind == "kinetic":
            T += e
        elif term.kind == "potential":
            V += e
        elif term.kind == "dissipation":
            D += e
    Q = [sp.Integer(0)] * len(q)
    for f in model.forces:
        Q[coords.index(f.coordinate)] += conv(f.Q)
    return SymbolicLagrangian(tuple(coords), params, q, qd, t, p, T, V, D, Q, "ir")


def lagrangian_of(eom) -> SymbolicLagrangian:
    """The ir route when the EOM came from an equation-layer model, else the CasADi route."""
    model = getattr(eom, "model", None)
    if model is not None and equation_layer_only(model) and tuple(model.coordinate_names) == tuple(eom.coords):
        try:
            return from_model(model)
        except Untranslatable:
            pass
    return from_eom(eom)


# --------------------------------------------------------------------------- linearization


@record(frozen=False)
class SymbolicLinearization:
    coords: tuple[str, ...]
    M: object                      # sympy Matrix (parameters as symbols)
    C: object
    K: object
    Bq: object
    inputs: tuple[str, ...]
    state: dict                    # symbol -> exact value used
    lagrangian: SymbolicLagrangian = field(repr=False)

    @property
    def route(self) -> str:
        return self.lagrangian.route

    def numeric(self, p=None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """M, C, K with parameter values substituted (default: the values in ``p``)."""
        lg = self.lagrangian
        vals = dict(zip(lg.p, [float(v) for v in p])) if p is not None else {}
        out = []
        for Mx in (self.M, self.C, self.K):
            out.append(np.array(Mx.subs(vals).evalf(17).tolist(), dtype=float).reshape(Mx.shape))
        return tuple(out)


def symbolic_linearization(eom, q, qd, t, acc=None, inputs=(), exact: bool = True,
                           q_exact: dict | None = None, lagrangian: SymbolicLagrangian | None = None
                           ) -> SymbolicLinearization:
    """Exact M, C, K of Lagrange's equations about (q, qd, t) with reference acceleration acc.

    E_i = d/dt(dL/dqd_i) - dL/dq_i + dD/dqd_i - Q_i;  M = dE/dqdd, C = dE/dqd, K = dE/dq.
    q_exact: coordinate name -> sympy expression to use instead of the numeric value.
    """
    import sympy as sp

    lg = lagrangian or lagrangian_of(eom)
    n = len(lg.q)
    qdd = [sp.Symbol(f"der(der({c}))", real=True) for c in lg.coords]
    L = lg.L
    E = []
    for i in range(n):
        pL = sp.diff(L, lg.qd[i])
        ddt = (sum(sp.diff(pL, lg.q[j]) * lg.qd[j] + sp.diff(pL, lg.qd[j]) * qdd[j] for j in range(n))
               + sp.diff(pL, lg.t))
        E.append(ddt - sp.diff(L, lg.q[i]) + sp.diff(lg.D, lg.qd[i]) - lg.Q[i])
    E = sp.Matrix(E)
    conv = exact_value if exact else (lambda v: sp.Float(float(v)))
    acc = np.zeros(n) if acc is None else np.asarray(acc, float)
    state = {}
    for i, c in enumerate(lg.coords):
        state[lg.q[i]] = (q_exact or {}).get(c, conv(q[i]))
        state[lg.qd[i]] = conv(qd[i])
        state[qdd[i]] = conv(acc[i])
    state[lg.t] = conv(t)

    def at(Mx):
        simp = _simp if exact else (lambda e: e)
        return sp.Matrix(Mx.shape[0], Mx.shape[1], lambda i, j: simp(Mx[i, j].subs(state)))

    M = at(E.jacobian(qdd))
    C = at(E.jacobian(lg.qd))
    K = at(E.jacobian(lg.q))
    cols = []
    for name in inputs or ():
        if name.startswith("force("):
            e = sp.zeros(n, 1)
            e[lg.coords.index(name[6:-1]), 0] = 1
            cols.append(e)
        else:
            cols.append(at(-E.jacobian([lg.p[lg.params.index(name)]])))
    Bq = sp.Matrix.hstack(*cols) if cols else sp.zeros(n, 0)
    return SymbolicLinearization(tuple(lg.coords), M, C, K, Bq, tuple(inputs or ()), state, lg)


def _simp(e):
    import sympy as sp

    if sp.count_ops(e) <= 120:
        return sp.simplify(e)
    return sp.expand(e)


# --------------------------------------------------------------------------- printing


def simplify_small(e, angles=(), limit: int = 80):
    """A short readable form: the shorter of e and its trig normal form (:func:`trig_normal`),
    then sympy.simplify when that is small."""
    import sympy as sp

    try:
        best = e
        if e.atoms(sp.sin, sp.cos):
            cand = trig_normal(e, angles)
            if sp.count_ops(cand) < sp.count_ops(best):
                best = cand
        if sp.count_ops(best) <= limit:
            cand = sp.simplify(best)
            if sp.count_ops(cand) <= sp.count_ops(best):
                best = cand
        return best
    except Exception:  # pragma: no cover - sympy could not handle it; keep the expression
        return e


def trig_normal(e, angles=(), max_ops: int = 100000):
    """Normal form of e as a polynomial in sin(x), cos(x) of the angle symbols x.

    sin and cos of sums are expanded; every polynomial in s = sin x, c = cos x is reduced modulo
    s^2 + c^2 - 1 (these polynomials form a Groebner basis, so the remainder is unique and is 0
    exactly when e vanishes identically).  Rational expressions are treated as numerator /
    denominator.  Of the two reductions (eliminate s^2 or c^2) the shorter is returned.
    Expressions that are not polynomial in sin/cos, or too large, are returned expanded.
    """
    import sympy as sp

    try:
        if sp.count_ops(e) > max_ops:
            return e
        e = sp.expand_trig(e)
        atoms = sorted({f.args[0] for f in e.atoms(sp.sin, sp.cos)} | set(),
                       key=sp.default_sort_key)
        if not atoms:
            return sp.expand(e)
        best = None
        for elim_sin in (True, False):
            try:        # polynomial in sin/cos with coefficients in everything else
                cand = _reduce_trig(e, atoms, elim_sin)
            except sp.PolynomialError:      # sin/cos in a denominator: numerator / denominator
                num, den = sp.fraction(sp.together(e))
                cand = _reduce_trig(num, atoms, elim_sin) / _reduce_trig(den, atoms, elim_sin)
            if best is None or sp.count_ops(cand) < sp.count_ops(best):
                best = cand
        return best
    except (sp.PolynomialError, sp.polys.polyerrors.PolificationFailed, RecursionError, TypeError):
        return e


def _reduce_trig(e, angles, elim_sin: bool):
    import sympy as sp

    s = [sp.Dummy(f"s{i}") for i in range(len(angles))]
    c = [sp.Dummy(f"c{i}") for i in range(len(angles))]
    rep = {}
    for a, si, ci in zip(angles, s, c):
        rep[sp.sin(a)] = si
        rep[sp.cos(a)] = ci
    x = sp.expand(e).xreplace(rep)
    gens = (s + c) if elim_sin else (c + s)
    basis = [si ** 2 + ci ** 2 - 1 for si, ci in zip(s, c)]
    if x == 0:
        return sp.Integer(0)
    _, r = sp.reduced(x, basis, *gens, order="lex")
    back = {si: sp.sin(a) for si, a in zip(s, angles)}
    back.update({ci: sp.cos(a) for ci, a in zip(c, angles)})
    return sp.expand(r.xreplace(back))


def text(e) -> str:
    """mechdsl-style text of a sympy expression (``^`` for powers)."""
    import sympy as sp

    return sp.sstr(e, order="none").replace("**", "^")


def latex(e, lg: "SymbolicLagrangian | None" = None, extra: dict | None = None) -> str:
    """LaTeX with der(x) printed as a dot and the momenta as p_x."""
    import sympy as sp

    names = {}
    if lg is not None:
        for c, s, sd in zip(lg.coords, lg.q, lg.qd):
            names[s] = _latex_name(c)
            names[sd] = r"\dot{" + _latex_name(c) + "}"
        names[lg.t] = "t"
    names.update(extra or {})
    return sp.latex(e, symbol_names=names)


def _latex_name(name: str) -> str:
    import re

    greek = {"alpha", "beta", "gamma", "delta", "epsilon", "zeta", "eta", "theta", "iota", "kappa",
             "lambda", "mu", "nu", "xi", "pi", "rho", "sigma", "tau", "upsilon", "phi", "chi", "psi",
             "omega", "Gamma", "Delta", "Theta", "Lambda", "Xi", "Pi", "Sigma", "Phi", "Psi", "Omega"}
    m = re.fullmatch(r"([A-Za-z]+)_?(\d*)", name)
    if m:
        base = "\\" + m.group(1) if m.group(1) in greek else m.group(1)
        return base + (f"_{{{m.group(2)}}}" if m.group(2) else "")
    return r"\mathrm{" + name.replace("_", r"\_") + "}"
