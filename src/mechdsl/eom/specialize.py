"""Functions rebuilt from their own expressions: with numbers built in for parameters
(``specialize``: ``casadi(fixed_parameters=...)``, eom.numeric_p) and with their derivatives
built with common subexpressions merged (``shared_derivatives``)."""
from __future__ import annotations


def _ca():
    import casadi as ca

    return ca


DERIVATIVE_LEVELS = 2     # first and second derivatives (an optimizer's exact Hessian: forward over reverse)
SHARED_MAX = 200          # instructions: above, merging costs ~10x the derivatives' build for ~1 % fewer instructions


def shared_derivatives(f):
    """``f`` (an SX Function) with the same expressions, whose derivative Functions (forward,
    reverse, Jacobian, and theirs, DERIVATIVE_LEVELS deep) CasADi builds with common
    subexpression elimination (the option ``cse`` in ``der_options``): the chain rule makes
    again what the Function already has (the partial of cos(x) is a new sin(x), the same
    quotient in every direction); merged, the cart-pole ``ode``'s forward-over-reverse
    derivative in 3 directions goes from 641 to 624 instructions and its sin and cos are
    evaluated once (benchmarks/control_swingup.py: 6-8 % less time in IPOPT's Jacobian and
    Hessian).  Only up to SHARED_MAX instructions: on the N-link chain (84 to 3467
    instructions) the merge saved 0.5-2 % of the derivatives' instructions and made building
    forward, reverse, Jacobian and forward over reverse 5-10x slower (N = 10: 35 -> 357 ms of
    CPU).  Other Functions (MX, larger) are returned as they are.  The values are the same
    operations on the same inputs: equal to the last bit."""
    if not f.is_a("SXFunction") or f.n_instructions() > SHARED_MAX:
        return f
    ca = _ca()
    opts: dict = {"cse": True}
    for _ in range(DERIVATIVE_LEVELS - 1):
        opts = {"cse": True, "der_options": opts}
    ins = f.sx_in()
    return ca.Function(f.name(), ins, f.call(ins), f.name_in(), f.name_out(),
                       {"allow_duplicate_io_names": True, "der_options": opts})


def specialize(f, fixed, n_p: int):
    """``f`` with the parameter entries ``fixed`` ((index in p, value) pairs) built in as numbers:
    its input "p" (or its output "p", for the ``parameters`` Function) keeps only the other
    entries, in order.  The Function is rebuilt from its own expression graph (an SX Function
    stays SX), so CasADi folds the constants: operations on parameters alone disappear."""
    ca = _ca()
    at = dict(fixed)
    keep = [i for i in range(n_p) if i not in at]
    if "p" in f.name_in():
        sym = ca.SX if f.is_a("SXFunction") else ca.MX
        ins = [sym.sym(nm, f.sparsity_in(i)) for i, nm in enumerate(f.name_in())]
        k = f.name_in().index("p")
        ins[k] = sym.sym("p", len(keep))
        rest = iter(ca.vertsplit(ins[k]))
        full = ca.vertcat(*[sym(at[i]) if i in at else next(rest) for i in range(n_p)]) if n_p else sym(0, 1)
        outs = f.call([full if i == k else a for i, a in enumerate(ins)])
        return ca.Function(f.name(), ins, outs, f.name_in(), f.name_out(), {"allow_duplicate_io_names": True})
    if "p" in f.name_out():               # parameters: free -> p, the kept entries of p
        ins = [ca.SX.sym(nm, f.sparsity_in(i)) for i, nm in enumerate(f.name_in())]
        outs = f.call(ins)
        k = f.name_out().index("p")
        outs[k] = outs[k][keep] if keep else ca.SX(0, 1)
        return ca.Function(f.name(), ins, outs, f.name_in(), f.name_out())
    return f
