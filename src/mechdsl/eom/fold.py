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
instructions are not folded (the pass runs in Python, about 30 us an instruction:
the 30-link chain's 3,467 instructions in 0.09 s CPU, on the first run only).
"""
from __future__ import annotations

import numpy as np

FOLD_MAX = 4000       # instructions: the pass costs about 30 us an instruction, once (then the model cache holds it)
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

    bin_, one = ca.SX.binary, ca.SX(1.0)     # SX.binary: a third of the time of the * operator

    def mat(v):
        c, b = v
        if b is None:
            return c
        return b if c is None else bin_(MUL, c, b)

    def mul(c1, c2):
        return c2 if c1 is None else (c1 if c2 is None else bin_(MUL, c1, c2))

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
                w[o[0]] = (None, ca.SX.unary(NEG, a[1])) if a[0] is None else (ca.SX.unary(NEG, a[0]), a[1])
            elif op == SQ:
                w[o[0]] = (None if a[0] is None else ca.SX.unary(SQ, a[0]), ca.SX.unary(SQ, a[1]))
            else:
                w[o[0]] = (None, ca.SX.unary(op, mat(a)))
        else:
            a, b = w[i[0]], w[i[1]]
            if a[1] is None and b[1] is None:                      # parameters alone
                w[o[0]] = (ca.SX.binary(op, a[0], b[0]), None)
            elif op == MUL:
                w[o[0]] = (mul(a[0], b[0]), b[1] if a[1] is None else (a[1] if b[1] is None else bin_(MUL, a[1], b[1])))
            elif op == DIV and b[1] is None:                        # (c x) / d -> (c / d) x
                w[o[0]] = (bin_(DIV, one if a[0] is None else a[0], b[0]), a[1])
            elif op == DIV and a[1] is None:                        # d / (c x) -> (d / c) / x
                w[o[0]] = (None, bin_(DIV, a[0] if b[0] is None else bin_(DIV, a[0], b[0]), b[1]))
            elif op == DIV:                                         # (c x) / (d y) -> (c / d) (x / y)
                c = a[0] if b[0] is None else bin_(DIV, one if a[0] is None else a[0], b[0])
                w[o[0]] = (c, bin_(DIV, a[1], b[1]))
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

TERMS_MAX = 64        # terms of one combination's polynomial: beyond, the combinations stay as they are


class _TooBig(Exception):
    """A combination this simplification leaves as it is."""


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


class _Poly:
    """Parameter combinations as Laurent polynomials {monomial: coefficient}; a monomial is a
    sorted tuple of (atom, exponent), an atom a parameter (its index) or a sum met in a
    denominator or under a function (an index past the parameters, ``atoms``).  Products,
    quotients by a single term, like terms and fractions (m l^2 / 12 + m (l/2)^2 = m l^2 / 3)
    fold here, without sympy (whose import costs a run's first ode 0.3 s)."""

    def __init__(self, n_p):
        self.n_p = n_p
        self.atoms: list = []          # (op, poly a, poly b or None)
        self.keys: dict = {}

    @staticmethod
    def const(v):
        return {(): float(v)} if v != 0 else {}

    def atom(self, op, a, b=None):
        key = (op, tuple(sorted(a.items())), None if b is None else tuple(sorted(b.items())))
        if key not in self.keys:
            self.keys[key] = self.n_p + len(self.atoms)
            self.atoms.append((op, a, b))
        return {((self.keys[key], 1),): 1.0}

    @staticmethod
    def add(a, b, sign=1.0):
        out = dict(a)
        for k, c in b.items():
            v = out.get(k, 0.0) + sign * c
            if v == 0.0:
                out.pop(k, None)
            else:
                out[k] = v
        return out

    @staticmethod
    def _mono(k1, k2):
        e = dict(k1)
        for at, x in k2:
            e[at] = e.get(at, 0) + x
        return tuple(sorted((at, x) for at, x in e.items() if x != 0))

    def mul(self, a, b):
        out: dict = {}
        for k1, c1 in a.items():
            for k2, c2 in b.items():
                k = self._mono(k1, k2)
                v = out.get(k, 0.0) + c1 * c2
                if v == 0.0:
                    out.pop(k, None)
                else:
                    out[k] = v
        if len(out) > TERMS_MAX:
            raise _TooBig
        return out

    def inv(self, a):
        import casadi as ca

        if not a:
            raise _TooBig                                      # a division by zero: left as it is
        if len(a) == 1:
            (k, c), = a.items()
            return {tuple((at, -x) for at, x in k): 1.0 / c}
        (key, _), = self.atom(ca.OP_ADD, a).items()          # the sum itself an atom, to the power -1
        return {((key[0][0], -1),): 1.0}


def _polys(exprs, p):
    """The combinations ``exprs`` (SX of p alone) as Laurent polynomials, and the _Poly."""
    import casadi as ca

    f = ca.Function("c", [p], [ca.vertcat(*exprs)])
    P = _Poly(p.numel())
    work: dict = {}
    out = [None] * len(exprs)
    for k in range(f.n_instructions()):
        op, i, o = f.instruction_id(k), f.instruction_input(k), f.instruction_output(k)
        a = [work[j] for j in i] if op not in (ca.OP_INPUT, ca.OP_CONST, ca.OP_OUTPUT) else None
        if op == ca.OP_INPUT:
            work[o[0]] = {((i[1], 1),): 1.0}
        elif op == ca.OP_CONST:
            work[o[0]] = P.const(f.instruction_constant(k))
        elif op == ca.OP_OUTPUT:
            out[o[1]] = work[i[0]]
        elif op == ca.OP_ADD:
            work[o[0]] = P.add(a[0], a[1])
        elif op == ca.OP_SUB:
            work[o[0]] = P.add(a[0], a[1], -1.0)
        elif op == ca.OP_NEG:
            work[o[0]] = P.add({}, a[0], -1.0)
        elif op == ca.OP_TWICE:
            work[o[0]] = P.add(a[0], a[0])
        elif op == ca.OP_MUL:
            work[o[0]] = P.mul(a[0], a[1])
        elif op == ca.OP_SQ:
            work[o[0]] = P.mul(a[0], a[0])
        elif op == ca.OP_DIV:
            work[o[0]] = P.mul(a[0], P.inv(a[1]))
        elif op == ca.OP_INV:
            work[o[0]] = P.inv(a[0])
        else:                                                 # a function of p: an atom
            work[o[0]] = P.atom(op, a[0], a[1] if len(a) > 1 else None)
    return out, P


def _emit(polys, P, p):
    """SX of the polynomials: a monomial is built as a multiple of the cheapest earlier one
    when that saves operations (m l^2 / 3 = (m l / 2) (2 l / 3)), each atom once."""
    import casadi as ca

    atom_sx: dict = {}
    done: list = []                    # (monomial, coefficient, SX) built so far

    def atom(at):
        if at < P.n_p:
            return p[at]
        if at not in atom_sx:
            op, a, b = P.atoms[at - P.n_p]
            if op == ca.OP_ADD:
                atom_sx[at] = poly(a)
            else:
                atom_sx[at] = ca.SX.unary(op, poly(a)) if b is None else ca.SX.binary(op, poly(a), poly(b))
        return atom_sx[at]

    def power(mono):
        num = den = None
        for at, x in mono:
            base = atom(at)
            v = base if abs(x) == 1 else (ca.SX.unary(ca.OP_SQ, base) if abs(x) == 2 else base ** abs(x))
            if x > 0:
                num = v if num is None else num * v
            else:
                den = v if den is None else den * v
        if den is None:
            return num
        return (1 / den) if num is None else num / den

    def pcost(mono):                   # operations of power(mono)
        return len(mono) - 1 + sum(abs(x) > 1 for _, x in mono) + all(x < 0 for _, x in mono)

    def term(mono, c):
        best, how = (pcost(mono) if mono else 0) + (c != 1.0), None
        for m2, c2, sx in done:
            rest = P._mono(mono, tuple((at, -x) for at, x in m2))
            r = c / c2
            k = (pcost(rest) + 1 if rest else 0) + (r != 1.0)
            if k < best:
                best, how = k, (rest, r, sx)
        if how is None:
            v = power(mono) if mono else None
            out = ca.SX(c) if v is None else (v if c == 1.0 else (-v if c == -1.0 else c * v))
        else:
            rest, r, sx = how
            v = sx if not rest else sx * power(rest)
            out = v if r == 1.0 else (-v if r == -1.0 else r * v)
        if mono:
            done.append((mono, c, out))
        return out

    def poly(a):
        if not a:
            return ca.SX(0)
        terms = [term(k, c) for k, c in sorted(a.items(), key=lambda kc: (len(kc[0]), kc[0]))]
        return sum(terms[1:], terms[0])

    order = sorted(range(len(polys)), key=lambda i: (sum(len(k) for k in polys[i]), i))
    out = [None] * len(polys)
    for i in order:
        out[i] = poly(polys[i])
    return out


def simplify_parameters(g, pin: int = 3):
    """``g`` with its parameter combinations (the parameter-only operands of its state
    operations) simplified (``_Poly``) and built with their common factors once, or ``g``."""
    import casadi as ca

    ins, outs, cs, exprs = _split(g, pin)
    if not cs:
        return g
    p = ins[pin]
    try:
        polys, P = _polys(exprs, p)
        new = _emit(polys, P, p)
    except _TooBig:
        return g
    sub = ca.substitute([ca.vec(o) for o in outs], [ca.vertcat(*cs)], [ca.vertcat(*new)])
    flat = ca.cse(ca.vertcat(*sub))
    sub, at = [], 0
    for o in outs:
        sub.append(flat[at:at + o.numel()])
        at += o.numel()
    return ca.Function(g.name(), ins, [ca.reshape(s, o.size1(), o.size2()) for s, o in zip(sub, outs)],
                       g.name_in(), g.name_out(), {"allow_duplicate_io_names": True})
