"""``mech compile --emit eom``: the equations of motion as deterministic text in the model's names.

Every quantity of the EOM (T, V, D, Q, the lower triangle of M, bias, the explicit
accelerations of the recursive route, the constraints g, outputs, reactions, invariants,
singularity monitors and the start values) is written as

    name = expression                 (small: at most MAX_CHARS characters of text)
    name = <N operations in deps>     (large: its size and the symbols it depends on;
                                       '<large expression in deps>' past OPS_BUDGET)
      = v0; v1; v2                    (its values at the three states of the header)

Why this form (the golden files in tests/golden/ compare it):

- **Names, not CasADi's.**  The SX graph is read instruction by instruction and rebuilt as an
  IR expression over `Coord`/`Speed`/`Param` leaves, then printed by `exprs.to_text`, the
  printer of ``--emit model``: coordinates by name, speeds as ``der(name)``, parameters by
  name, ``time``, multipliers as ``lambda[constraint]``.  CasADi's own printer (``@1=...``
  shared-subexpression text, ``sq``, ``q_0``) changes between versions; its op codes do not.
- **Numbers as well as structure.**  Large expressions are unreadable and their text is
  fragile, so each quantity is also evaluated at three fixed states: the start state and
  two seeded random states around it (``random.Random(SEED)``, whose ``random()`` stream
  Python guarantees across versions; NumPy's Generator streams are not).  A change of the
  physics changes the numbers whatever the printer; 10 significant digits, compared with a
  tolerance by the golden test (different libm or CasADi simplifications change the last bits).
- **Noise.**  Values below NOISE times the largest of their line are rounding noise of an
  exact zero (``cos(pi/2)``) that differs between platforms; they print as 0.
- **Deterministic and fast.**  Declaration order everywhere; one CasADi Function for all
  quantities, evaluated three times; text is built only for expressions under the size cap.
"""
from __future__ import annotations

import random

from ..model import ir
from ..model.exprs import fmt_num, to_text

MAX_CHARS = 240          # longest expression text printed; larger ones are summarized
SEED = 20261124          # the seeded states
N_RANDOM = 2             # random states besides the start state
Q_SPREAD = 0.5           # random states: q = q0 + U(-Q_SPREAD, Q_SPREAD), likewise qd, lambda
QD_SPREAD = 1.0
OPS_BUDGET = 1_000_000   # operations the size counts of one dump may visit (see _count_ops)
NOISE = 1e-12            # relative size below which a value prints as 0 (see _nums)


def dump_eom(eom) -> str:
    import casadi as ca

    from . import fold_inputs

    eom = fold_inputs(eom)          # inputs print as trailing parameters at their defaults

    names = _symbol_names(eom)
    entries = _entries(eom)                 # [(label, SX scalar)] in print order
    ins = [eom.q, eom.qd, eom.t, eom.p] + ([eom.lam] if eom.lam is not None else [])
    states = _states(eom)
    values = _evaluate(ca, ins, [e for _, e in entries], states) if entries else []
    exprs, deps, ops = _read_graph(ca, ins, [e for _, e in entries], names)

    L = [f"eom {eom.name}: route {eom.route}, {_count(eom.n, 'coordinate')}, {_count(eom.m, 'constraint')}"]
    L.append("coordinates q = (" + ", ".join(eom.coords) + ")")
    L.append("speeds qd = (" + ", ".join(f"der({c})" for c in eom.coords) + ")")
    L.append("parameters p = (" + ", ".join(f"{n} = {fmt_num(float(v))}"
                                             for n, v in zip(eom.params, eom.param_values)) + ")")
    if eom.lam is not None:
        L.append("multipliers = (" + ", ".join(names[4]) + ")")
    L.append(f"states s0 (start), s1, s2 (seed {SEED}); the values after '=' below are at s0; s1; s2 "
             "(one value when an expression depends on parameters only):")
    L.append(f"  time = {_nums([s[2][0] for s in states])}")
    for k in (0, 1, 4):                     # coordinates, speeds, multipliers
        for i, name in enumerate(names[k]):
            L.append(f"  {name} = {_nums([s[k][i] for s in states])}")
    param_bits = ((1 << len(eom.params)) - 1) << (2 * eom.n + 1)     # inputs: q, qd, t, p, lambda
    n_nz = sum(1 for lab, _ in entries if lab.startswith("M["))
    for idx, (label, e) in enumerate(entries):
        if label.startswith("M[") and not entries[idx - 1][0].startswith("M["):
            L.append(f"M is symmetric: its lower triangle has {n_nz} nonzero entries of "
                     f"{eom.n * (eom.n + 1) // 2}; entries not listed are 0")
        if e.is_zero():
            L.append(f"{label} = 0")
            continue
        text = exprs[idx]
        if text is None:
            size = f"{ops[idx]} operations" if ops[idx] is not None else "large expression"
            text = f"<{size} in {_deps_text(deps[idx], names)}>"
        L.append(f"{label} = {text}")
        if e.is_constant():
            continue
        vs = [v[idx] for v in values]
        L.append(f"  = {_nums(vs if deps[idx] & ~param_bits else vs[:1])}")
    return "\n".join(L) + "\n"


# ----------------------------------------------------------------------------- what is listed


def _entries(eom) -> list:
    import casadi as ca

    def col(x, n):
        x = ca.SX(x)
        if x.numel() == 1 and n != 1 and x.is_zero():
            return [x] * n
        return [x[i] for i in range(x.numel())]

    out = []
    if eom.q0 is not None:
        out += [(f"start {c}", x) for c, x in zip(eom.coords, col(eom.q0, eom.n))]
    if eom.qd0 is not None:
        out += [(f"start der({c})", x) for c, x in zip(eom.coords, col(eom.qd0, eom.n))]
    out += [("T", ca.SX(eom.T)), ("V", ca.SX(eom.V)), ("D", ca.SX(eom.D))]
    out += [(f"Q[{c}]", x) for c, x in zip(eom.coords, col(eom.Q, eom.n))]
    M = ca.SX(eom.M)
    sp, nz = M.sparsity(), M.nonzeros()
    lower: dict = {}                        # (i, j), i >= j -> nonzero index; the lower one wins
    for k, (i, j) in enumerate(zip(sp.row(), sp.get_col())):
        if j <= i or (j, i) not in lower:
            lower[(max(i, j), min(i, j))] = k
    out += [(f"M[{eom.coords[i]},{eom.coords[j]}]", nz[lower[i, j]]) for i, j in sorted(lower)
            if not nz[lower[i, j]].is_zero()]
    out += [(f"bias[{c}]", x) for c, x in zip(eom.coords, col(eom.bias, eom.n))]
    if eom.qdd is not None:
        out += [(f"qdd[{c}]", x) for c, x in zip(eom.coords, col(eom.qdd, eom.n))]
    if eom.g is not None:
        out += [(f"g[{c}]", x) for c, x in zip(eom.constraint_names, col(eom.g, eom.m))]
    for kind, d in (("output", eom.outputs), ("reaction", eom.reactions),
                    ("invariant", eom.invariants), ("monitor", eom.singularity_monitors)):
        for k, v in d.items():
            v = ca.SX(v)
            if v.numel() == 1:
                out.append((f"{kind} {k}", v))
            else:
                out += [(f"{kind} {k}[{i + 1}]", v[i]) for i in range(v.numel())]
    return out


def _count(n: int, word: str) -> str:
    return f"{n} {word}" + ("" if n == 1 else "s")


def _symbol_names(eom) -> tuple:
    """Print names of the inputs, by input index: q, qd, t, p, lambda."""
    lam = tuple(f"lambda[{c}]" for c in eom.constraint_names) if eom.lam is not None else ()
    return (tuple(eom.coords), tuple(f"der({c})" for c in eom.coords), ("time",),
            tuple(eom.params), lam)


# ----------------------------------------------------------------------------- states and numbers


def _states(eom) -> list:
    """[(q, qd, (t,), p, lam)] * 3: the start state at t = 0, then two seeded random ones."""
    import numpy as np

    q0, qd0 = eom.start() if eom.q0 is not None else (np.zeros(eom.n), np.zeros(eom.n))
    p = [float(v) for v in np.asarray(eom.param_values, float).ravel()]
    rng = random.Random(SEED)

    def u(spread):
        return spread * (2.0 * rng.random() - 1.0)

    out = [(list(map(float, q0)), list(map(float, qd0)), [0.0], p, [0.0] * eom.m)]
    for _ in range(N_RANDOM):
        q = [float(x) + u(Q_SPREAD) for x in q0]
        qd = [float(x) + u(QD_SPREAD) for x in qd0]
        t = [rng.random()]
        lam = [u(QD_SPREAD) for _ in range(eom.m)]
        out.append((q, qd, t, p, lam))
    return out


def _evaluate(ca, ins, exprs, states) -> list:
    import numpy as np

    f = ca.Function("dump_eom", ins, [ca.densify(ca.vertcat(*exprs))])
    out = []
    for s in states:
        args = list(s[:4]) + ([s[4]] if len(ins) == 5 else [])
        out.append([float(x) for x in np.asarray(f(*args), float).ravel()])
    return out


def _num(v: float) -> str:
    if v != v:
        return "nan"
    if v in (float("inf"), float("-inf")):
        return "inf" if v > 0 else "-inf"
    if v == 0.0:
        return "0"
    return f"{v:.10g}"


def _nums(vs) -> str:
    """Values at the states; those below NOISE times the largest are rounding noise of an
    exact zero (sin(pi), cancellations) that differs between platforms, and print as 0."""
    finite = [abs(v) for v in vs if v == v and abs(v) != float("inf")]
    cut = NOISE * max(finite, default=0.0)
    return "; ".join(_num(0.0 if abs(v) <= cut else v) for v in vs)


# ----------------------------------------------------------------------------- the SX graph


_UNARY = {"NEG": "neg", "SQRT": "sqrt", "SIN": "sin", "COS": "cos", "TAN": "tan", "ASIN": "asin",
          "ACOS": "acos", "ATAN": "atan", "SINH": "sinh", "COSH": "cosh", "TANH": "tanh",
          "EXP": "exp", "LOG": "log", "FABS": "abs", "SIGN": "sign", "FLOOR": "floor",
          "CEIL": "ceil", "NOT": "not"}
_BINARY = {"ADD": "add", "SUB": "sub", "MUL": "mul", "DIV": "div", "POW": "pow", "CONSTPOW": "pow",
           "ATAN2": "atan2", "FMIN": "min", "FMAX": "max", "LT": "lt", "LE": "le", "EQ": "eq",
           "NE": "ne", "AND": "and", "OR": "or"}


def _op_names(ca) -> dict:
    return {getattr(ca, n): n[3:] for n in dir(ca) if n.startswith("OP_")}


def _read_graph(ca, ins, exprs, names):
    """For each expression: its text (None when over MAX_CHARS), the bit set of the input
    symbols it depends on and its number of operations (counted only when the text is not
    shown), from one SX Function's instructions (live_variables off, so every instruction
    has its own work slot)."""
    if not exprs:
        return [], [], []
    offsets, k = [], 0
    for x in ins:
        offsets.append(k)
        k += int(x.numel())
    f = ca.Function("dump_eom_graph", ins, exprs, {"live_variables": False})
    opname = _op_names(ca)
    node: dict[int, ir.Expr] = {}       # work slot -> IR expression
    size: dict[int, int] = {}           # work slot -> bound of its text length (MAX_CHARS + 1: too long)
    dep: dict[int, int] = {}            # work slot -> bit set of input symbols
    kids: dict[int, list] = {}          # work slot of an operation -> its argument slots
    texts = [None] * len(exprs)
    deps = [0] * len(exprs)
    ops: list = [None] * len(exprs)
    budget = [OPS_BUDGET]
    for k in range(f.n_instructions()):
        op = opname.get(f.instruction_id(k), "?")
        i_in = list(f.instruction_input(k))
        i_out = list(f.instruction_output(k))
        if op == "OUTPUT":
            w, o = i_in[0], i_out[0]
            text = to_text(node[w]) if size[w] <= MAX_CHARS else None
            texts[o] = text if text is not None and len(text) <= MAX_CHARS else None
            deps[o] = dep[w]
            if texts[o] is None:
                ops[o] = _count_ops(w, kids, budget)
            continue
        w = i_out[0]
        if op == "INPUT":
            a, nz = i_in
            node[w] = _leaf(a, nz, names)
            size[w], dep[w] = len(to_text(node[w])), 1 << (offsets[a] + nz)
            continue
        if op == "CONST":
            node[w] = ir.Const(float(f.instruction_constant(k)))
            size[w], dep[w] = len(to_text(node[w])), 0
            continue
        args = i_in[:_arity(op)]
        node[w] = _ir_op(op, [node[j] for j in args])
        size[w] = min(sum(size[j] for j in args) + len(op) + 6, MAX_CHARS + 1)
        dep[w], kids[w] = 0, args
        for j in args:
            dep[w] |= dep[j]
    return texts, deps, ops


def _count_ops(w: int, kids: dict, budget: list) -> int | None:
    """Operations in the graph below slot w, each shared one counted once; None once the
    walks of one dump have visited OPS_BUDGET operations (then for every later expression
    too, so a large model's dump stays fast and its lines uniform)."""
    seen, stack = set(), [w]
    while stack:
        v = stack.pop()
        if v in seen or v not in kids:
            continue
        if len(seen) >= budget[0]:
            budget[0] = 0
            return None
        seen.add(v)
        stack.extend(kids[v])
    budget[0] -= len(seen)
    return len(seen)


def _arity(op: str) -> int:
    return 2 if op in _BINARY or op in ("IF_ELSE_ZERO", "HYPOT", "COPYSIGN", "FMOD") else 1


def _leaf(a: int, nz: int, names) -> ir.Expr:
    if a == 0:
        return ir.Coord(names[0][nz])
    if a == 1:
        return ir.Speed(names[0][nz])
    if a == 2:
        return ir.Time()
    return ir.Param(names[a][nz])


def _ir_op(op: str, args: list) -> ir.Expr:
    if op in _BINARY:
        return ir.Op(_BINARY[op], tuple(args))
    if op in _UNARY:
        return ir.Op(_UNARY[op], tuple(args))
    if op == "SQ":
        return ir.Op("pow", (args[0], ir.Const(2.0)))
    if op == "TWICE":
        return ir.Op("mul", (ir.Const(2.0), args[0]))
    if op == "INV":
        return ir.Op("div", (ir.Const(1.0), args[0]))
    if op == "IF_ELSE_ZERO":
        return ir.Op("if", (args[0], args[1], ir.Const(0.0)))
    return ir.Op(op.lower(), tuple(args))       # printed as op(args)


def _deps_text(bits: int, names) -> str:
    """The symbols an expression depends on: runs of 3 or more consecutive symbols of one
    kind as 'first .. last (k)', a whole kind as 'all coordinates' etc."""
    kinds = (("coordinates", names[0]), ("speeds", names[1]), ("", names[2]), ("parameters", names[3]),
             ("multipliers", names[4]))
    parts, off = [], 0
    for word, group in kinds:
        idx = [i for i in range(len(group)) if bits >> (off + i) & 1]
        off += len(group)
        if not idx:
            continue
        if len(idx) == len(group) and len(group) >= 3:
            parts.append(f"all {len(group)} {word}")
            continue
        run: list[int] = []
        for i in idx + [None]:
            if run and (i is None or i != run[-1] + 1):
                parts.append(f"{group[run[0]]} .. {group[run[-1]]} ({len(run)})" if len(run) >= 3
                             else ", ".join(group[j] for j in run))
                run = []
            if i is not None:
                run.append(i)
    return ", ".join(parts) if parts else "no symbols"
