"""Fold the parameters' arithmetic of an SX ``ode`` into a few parameter combinations.

An ``ode`` (t, x, u, p) -> xdot built with p symbolic mixes the parameters into the state's
arithmetic: ``((cos(x1) * (m * (l/2))) / (M + m))`` multiplies by m l / 2 and divides by M + m
on every call, and IPOPT's exact Hessian differentiates each of those operations with respect
to p as well (an ``ode`` of an optimizer's dynamics is differentiated forward over reverse in
every direction, the parameters included: CasADi cannot know that p is a constant there).

``fold_parameters`` rewrites the instructions so that every factor that depends on p alone is
gathered into one coefficient per product: a product or quotient is carried as (coefficient
of p alone) x (body of t, x, u), and the coefficient is multiplied in only where the product
meets a sum, a function or an output.  The cart-pole's ``(cos(x1) * c1) / c2`` becomes
``cos(x1) * (c1 / c2)``, ``c3 * (sin(x1) * (m g))`` becomes ``(c3 m g) * sin(x1)``; the
parameter-only expressions are then shared (``casadi.cse``).  Fewer operations touch both p
and the state, so the ode and every derivative of it are cheaper, whatever the model
(benchmarks/control_swingup.py: the cart-pole's default ode).

The folded Function is kept only when it has fewer instructions than the one it replaces
and equals it at random points to 1e-12 relative (the reordered products differ by
round-off); else the Function is returned unchanged.  Functions of more than FOLD_MAX
instructions are not folded (the pass runs in Python, about 10 us an instruction).
"""
from __future__ import annotations

import numpy as np

FOLD_MAX = 20000
PROBES = 8


def _ops():
    import casadi as ca

    return ca.OP_INPUT, ca.OP_OUTPUT, ca.OP_CONST, ca.OP_MUL, ca.OP_DIV, ca.OP_NEG, ca.OP_SQ, ca.OP_ADD, ca.OP_SUB


def _rebuild(f, pin: int):
    """The outputs of ``f`` rebuilt with p-only factors gathered (lists of SX), and the inputs."""
    import casadi as ca

    OP_INPUT, OP_OUTPUT, OP_CONST, MUL, DIV, NEG, SQ, ADD, SUB = _ops()
    ins = [ca.SX.sym(f.name_in(i), f.sparsity_in(i)) for i in range(f.n_in())]
    outs = [ca.SX.zeros(f.sparsity_out(i)) for i in range(f.n_out())]
    w: dict = {}          # work index -> (coef, body): coef of p alone (or None: 1), body of t, x, u (None: none)
    uses = _uses(f)       # a product used more than once is multiplied out once, where it is made

    def mat(v):
        c, b = v
        if b is None:
            return c
        return b if c is None else c * b

    def mul(c1, c2):
        return c2 if c1 is None else (c1 if c2 is None else c1 * c2)

    for k in range(f.n_instructions()):
        op = f.instruction_id(k)
        i = f.instruction_input(k)
        o = f.instruction_output(k)
        if op == OP_INPUT:
            e = ins[i[0]].nz[i[1]]
            w[o[0]] = (e, None) if i[0] == pin else (None, e)
        elif op == OP_CONST:
            w[o[0]] = (ca.SX(f.instruction_constant(k)), None)
        elif op == OP_OUTPUT:
            outs[o[0]].nz[o[1]] = mat(w[i[0]])
        elif len(i) == 1:
            a = w[i[0]]
            if a[1] is None:
                w[o[0]] = (ca.SX.unary(op, a[0]), None)
            elif op == NEG:
                w[o[0]] = (None, -a[1]) if a[0] is None else (-a[0], a[1])
            elif op == SQ:
                w[o[0]] = (None if a[0] is None else ca.SX.unary(SQ, a[0]), ca.SX.unary(SQ, a[1]))
            else:
                w[o[0]] = (None, ca.SX.unary(op, mat(a)))
        else:
            a, b = w[i[0]], w[i[1]]
            if a[1] is None and b[1] is None:                      # parameters alone
                w[o[0]] = (ca.SX.binary(op, a[0], b[0]), None)
            elif op == MUL:
                w[o[0]] = (mul(a[0], b[0]), b[1] if a[1] is None else (a[1] if b[1] is None else a[1] * b[1]))
            elif op == DIV and b[1] is None:                        # (c x) / d -> (c / d) x
                w[o[0]] = ((1 / b[0]) if a[0] is None else a[0] / b[0], a[1])
            elif op == DIV and a[1] is None:                        # d / (c x) -> (d / c) / x
                w[o[0]] = (None, (a[0] if b[0] is None else a[0] / b[0]) / b[1])
            elif op == DIV:                                         # (c x) / (d y) -> (c / d) (x / y)
                c = a[0] if b[0] is None else (1 / b[0] if a[0] is None else a[0] / b[0])
                w[o[0]] = (c, a[1] / b[1])
            elif op in (ADD, SUB) and a[1] is not None and b[1] is not None and a[0] is not None \
                    and b[0] is not None and ca.is_equal(a[0], b[0], 2):   # c x +- c y -> c (x +- y)
                w[o[0]] = (a[0], ca.SX.binary(op, a[1], b[1]))
            else:
                w[o[0]] = (None, ca.SX.binary(op, mat(a), mat(b)))
        if op != OP_OUTPUT and uses[k] > 1 and w[o[0]][0] is not None and w[o[0]][1] is not None:
            w[o[0]] = (None, mat(w[o[0]]))
    return ins, outs


def _uses(f) -> list:
    """How many instructions read the result of each instruction (work slots are reused)."""
    import casadi as ca

    n = f.n_instructions()
    uses = [0] * n
    made: dict = {}
    for k in range(n):
        op = f.instruction_id(k)
        if op not in (ca.OP_INPUT, ca.OP_CONST):
            for j in f.instruction_input(k):
                uses[made[j]] += 1
        if op != ca.OP_OUTPUT:
            made[f.instruction_output(k)[0]] = k
    return uses


def fold_parameters(f, pin: int = 3):
    """``f`` (an SX Function with the parameters as input ``pin``) with the parameters'
    arithmetic folded (see the module docstring), or ``f`` itself when that is not leaner or
    not equal at random points."""
    import casadi as ca

    if not f.is_a("SXFunction") or f.has_free() or f.n_instructions() > FOLD_MAX or f.n_in() <= pin \
            or f.nnz_in(pin) == 0:
        return f
    ins, outs = _rebuild(f, pin)
    flat = ca.cse(ca.vertcat(*[ca.vec(o) for o in outs])) if outs else ca.SX(0, 1)
    parts, at = [], 0
    for o in outs:
        parts.append(ca.reshape(flat[at:at + o.numel()], o.size1(), o.size2()))
        at += o.numel()
    g = ca.Function(f.name(), ins, parts, f.name_in(), f.name_out(), {"allow_duplicate_io_names": True})
    g = simplify_parameters(g, pin)
    if g.n_instructions() >= f.n_instructions():
        return f
    rng = np.random.default_rng(20261127)
    for _ in range(PROBES):
        args = [rng.uniform(-1.0, 1.0, f.nnz_in(i)) + (0.37 if i != pin else 1.3) for i in range(f.n_in())]
        a = np.concatenate([np.ravel(np.array(v, float)) for v in (f(*args) if f.n_out() > 1 else [f(*args)])])
        b = np.concatenate([np.ravel(np.array(v, float)) for v in (g(*args) if g.n_out() > 1 else [g(*args)])])
        if not (np.isfinite(a).all() and np.isfinite(b).all()) or \
                np.abs(a - b).max() > 1e-12 * max(1.0, np.abs(a).max()):
            return f
    return g


# --------------------------------------------------------------------------- parameter combinations

COMBO_MAX = 60        # operations of one parameter combination that sympy simplifies


def _split(f, pin: int):
    """(inputs, outputs with each parameter-only operand of a state operation replaced by a
    symbol c_k, the c symbols, their expressions in p)."""
    import casadi as ca

    ins = [ca.SX.sym(f.name_in(i), f.sparsity_in(i)) for i in range(f.n_in())]
    outs = [ca.SX.zeros(f.sparsity_out(i)) for i in range(f.n_out())]
    w: dict = {}                 # work index -> (expr, parameters only, producing instruction)
    cs, exprs, made = [], [], {}

    def use(j):
        e, ponly, k = w[j]
        if not ponly or e.is_constant():
            return e
        if k not in made:
            made[k] = ca.SX.sym(f"c{len(cs)}")
            cs.append(made[k])
            exprs.append(e)
        return made[k]

    for k in range(f.n_instructions()):
        op, i, o = f.instruction_id(k), f.instruction_input(k), f.instruction_output(k)
        if op == ca.OP_INPUT:
            w[o[0]] = (ins[i[0]].nz[i[1]], i[0] == pin, k)
        elif op == ca.OP_CONST:
            w[o[0]] = (ca.SX(f.instruction_constant(k)), True, k)
        elif op == ca.OP_OUTPUT:
            outs[o[0]].nz[o[1]] = use(i[0])
        else:
            ponly = all(w[j][1] for j in i)
            args = [w[j][0] for j in i] if ponly else [use(j) for j in i]
            e = ca.SX.unary(op, args[0]) if len(args) == 1 else ca.SX.binary(op, args[0], args[1])
            w[o[0]] = (e, ponly, k)
    return ins, outs, cs, exprs


def _to_sympy(exprs, p, psyms):
    """sympy expressions of the parameter-only SX ``exprs`` (arithmetic only), or None."""
    import casadi as ca
    import sympy as sp

    f = ca.Function("c", [p], [ca.vertcat(*exprs)])
    table = {ca.OP_ADD: lambda a: a[0] + a[1], ca.OP_SUB: lambda a: a[0] - a[1], ca.OP_MUL: lambda a: a[0] * a[1],
             ca.OP_DIV: lambda a: a[0] / a[1], ca.OP_NEG: lambda a: -a[0], ca.OP_SQ: lambda a: a[0] ** 2,
             ca.OP_TWICE: lambda a: 2 * a[0], ca.OP_INV: lambda a: 1 / a[0], ca.OP_SQRT: lambda a: sp.sqrt(a[0])}
    work: dict = {}
    out = [None] * len(exprs)
    for k in range(f.n_instructions()):
        op, i, o = f.instruction_id(k), f.instruction_input(k), f.instruction_output(k)
        if op == ca.OP_INPUT:
            work[o[0]] = psyms[i[1]]
        elif op == ca.OP_CONST:
            v = f.instruction_constant(k)
            work[o[0]] = sp.Integer(int(v)) if v == int(v) and abs(v) < 1e15 else sp.Float(v, 17)
        elif op == ca.OP_OUTPUT:
            out[o[1]] = work[i[0]]
        elif op in table:
            work[o[0]] = table[op]([work[j] for j in i])
        else:
            return None
    return out


def _to_sx(exprs, psyms, p):
    """SX of sympy ``exprs`` (arithmetic of ``psyms`` = the entries of ``p``), shared subterms once."""
    import casadi as ca
    import sympy as sp

    env = {s: p[i] for i, s in enumerate(psyms)}

    def conv(e):
        if e in env:
            return env[e]
        if e.is_Integer or e.is_Rational or e.is_Float:
            return ca.SX(float(e))
        if e.is_Add:
            terms = [conv(a) for a in e.args]
            return sum(terms[1:], terms[0])
        if e.is_Mul:
            num = [a for a in e.args if not (a.is_Pow and a.exp.is_negative)]
            den = [1 / a for a in e.args if a.is_Pow and a.exp.is_negative]
            top = ca.SX(1.0)
            for a in num:
                top = conv(a) if top.is_one() else top * conv(a)
            if den:
                bot = conv(sp.Mul(*den))
                return top / bot
            return top
        if e.is_Pow:
            b, x = e.args
            if x == 2:
                return ca.SX.unary(ca.OP_SQ, conv(b))
            if x == -1:
                return 1 / conv(b)
            if x == sp.Rational(1, 2):
                return ca.sqrt(conv(b))
            if x.is_Integer and x > 0:
                return conv(b) ** int(x)
            return conv(b) ** conv(x)
        raise ValueError(e)

    order, forms, names = _shared(exprs, lambda e: _cost(conv, e, env))
    for i in order:                   # common subterms: casadi.cse of the whole ode after
        env[names[i]] = conv(forms[i])
    return [env[names[i]] for i in range(len(exprs))]


def _cost(conv, e, env):
    """Operations of the SX of ``e`` (the symbols it names free)."""
    import casadi as ca

    free = [s for s in e.free_symbols if s not in env]
    for s in free:
        env[s] = ca.SX.sym(str(s))
    try:
        x = conv(e)
        syms = ca.symvar(x)
        f = ca.Function("cost", [ca.vertcat(*syms)] if syms else [], [x])
        return f.n_instructions() - len(syms) - 1
    finally:
        for s in free:
            del env[s]


SHARE_MAX = 40        # combinations: up to this many, each is tried as a multiple of a simpler one


def _shared(exprs, cost):
    """(an order to compute ``exprs`` in, the forms to compute them by, their names): a
    product that is a cheaper multiple of an earlier one is written so, its name times the
    quotient (m l^2 / 3 = (m l / 2) (2 l / 3)): sympy's cse finds common factors, not such
    quotients."""
    import sympy as sp

    names = [sp.Symbol(f"_c{i}") for i in range(len(exprs))]
    if len(exprs) > SHARE_MAX:
        return range(len(exprs)), list(exprs), names
    costs = [cost(e) for e in exprs]
    order = sorted(range(len(exprs)), key=lambda i: (costs[i], i))
    out = list(exprs)
    for a, i in enumerate(order):
        if not exprs[i].is_Mul:
            continue
        best = costs[i]
        for j in order[:a]:
            if exprs[j].is_Mul:
                q = sp.cancel(exprs[i] / exprs[j])
                c = cost(names[j] * q)
                if c < best:
                    out[i], best = names[j] * q, c
    return order, out, names


def _rational(e):
    """``e`` with its floating-point numbers that are small fractions (1/3, 1/12) made exact."""
    import sympy as sp
    from fractions import Fraction

    def exact(v):
        fr = Fraction(float(v)).limit_denominator(1000)
        return sp.Rational(fr.numerator, fr.denominator) if abs(float(fr) - float(v)) <= 1e-15 * abs(float(v)) else v

    return e.xreplace({f: exact(f) for f in e.atoms(sp.Float)})


def simplify_parameters(g, pin: int = 3):
    """``g`` with its parameter combinations (the parameter-only operands of its state
    operations) simplified by sympy and their common factors computed once, or ``g``."""
    import casadi as ca
    import sympy as sp

    ins, outs, cs, exprs = _split(g, pin)
    if not cs:
        return g
    p = ins[pin]
    psyms = sp.symbols(f"p0:{p.numel()}")
    if any(ca.Function("c", [p], [e]).n_instructions() > COMBO_MAX for e in exprs):
        return g
    es = _to_sympy(exprs, p, psyms)
    if es is None:
        return g
    try:
        new = _to_sx([sp.factor(sp.cancel(_rational(e))) for e in es], psyms, p)
    except (ValueError, TypeError, sp.PolynomialError):
        return g
    sub = ca.substitute([ca.vec(o) for o in outs], [ca.vertcat(*cs)], [ca.vertcat(*new)])
    flat = ca.cse(ca.vertcat(*sub))
    sub, at = [], 0
    for o in outs:
        sub.append(flat[at:at + o.numel()])
        at += o.numel()
    return ca.Function(g.name(), ins, [ca.reshape(s, o.size1(), o.size2()) for s, o in zip(sub, outs)],
                       g.name_in(), g.name_out(), {"allow_duplicate_io_names": True})
