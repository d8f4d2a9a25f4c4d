"""A leaner ``ode`` for small models: M and bias with the terms that cancel removed, then solved.

The recursive route's accelerations (and the Lagrange route's M and bias) carry terms that
cancel only numerically: the cart-pole's mass matrix has m cos^2 + m sin^2 for m, its bias
velocity products of the cart speed that add to zero.  ``lean_entries`` finds, for each entry
of an expression, the inputs it does not depend on (its derivative with respect to them is
zero to round-off at random points) and sets them to 0 in that entry, so CasADi folds what
cancelled (cos(0) = 1, sin(0) = 0, x * 0 = 0).  ``lean_ode`` builds ``ode`` from the leaned M
and bias with the unrolled LDL^T solve and keeps it when it has fewer instructions than the
plain ``ode``: the cart-pole's default ``ode`` (parameters as the input p) goes from 72 to 43
instructions (38 after mechdsl.eom.fold folds the parameters' arithmetic), against 35 for
one written by hand with its numbers built in (benchmarks/control_swingup.py).

Only smooth expressions are leaned (a piecewise term can vanish at every probe and not
elsewhere), and the leaned ``ode`` must equal the plain one at other random points to 1e-12
relative, else the plain one is kept.
"""
from __future__ import annotations

import numpy as np

LEAN_MAX = 6          # coordinates: above this the recursive route's ode is the leaner one
PROBES = 16


def _smooth(e, smooth_ops) -> bool:
    import casadi as ca

    f = ca.Function("e", ca.symvar(e), [e]) if ca.symvar(e) else None
    if f is None:
        return True
    ok = {getattr(ca, "OP_" + o) for o in smooth_ops if hasattr(ca, "OP_" + o)}
    return all(f.instruction_id(k) in ok for k in range(f.n_instructions()))


def lean_entries(entries, inputs, rng, smooth_ops) -> list:
    """Each scalar SX entry with the scalar ``inputs`` it does not depend on set to 0 (entries
    made of ``smooth_ops`` only: codegen._SMOOTH_OPS)."""
    import casadi as ca

    z = ca.vertcat(*inputs)
    E = ca.vertcat(*entries)
    n = z.numel()
    J = ca.Function("J", [z], [ca.jacobian(E, z)])
    scale = np.zeros((E.numel(), n))
    for _ in range(PROBES):
        scale = np.maximum(scale, np.abs(np.array(J(rng.uniform(-1.0, 1.0, n) + 0.17), float)))
    out = []
    for i in range(E.numel()):
        e = E[i]
        zero = [j for j in range(n) if scale[i, j] <= 1e-12 * max(1.0, scale[i].max()) and ca.depends_on(e, z[j])]
        if zero and _smooth(e, smooth_ops):
            e = ca.substitute(e, ca.vertcat(*[z[j] for j in zero]), ca.SX.zeros(len(zero)))
        out.append(e)
    return out


def lean_ode(eom, plain, s, build, smooth_ops):
    """The ``ode`` of leaned M and bias, when it has fewer instructions than ``plain`` (an SX
    Function) and equals it at random points; else ``plain``.  ``s``: codegen's symbols of
    ``eom``; ``build(M, b)``: the ode Function of M qdd = b (codegen: its LDL^T solve);
    ``smooth_ops``: codegen._SMOOTH_OPS (this module imports nothing of codegen's)."""
    import casadi as ca

    n = eom.n
    if n < 2 or n > LEAN_MAX or not plain.is_a("SXFunction"):
        return plain
    inputs = ca.vertsplit(ca.vertcat(s.t, s.x, s.u, s.p))
    rng = np.random.default_rng(20250611)
    M, b = ca.SX(eom.M), ca.SX(eom.bias)
    if M.shape != (n, n):
        return plain
    ml = lean_entries([M[i, j] for j in range(n) for i in range(n)], inputs, rng, smooth_ops)
    bl = lean_entries([b[i] for i in range(n)], inputs, rng, smooth_ops)
    lean = build(ca.reshape(ca.vertcat(*ml), n, n), ca.vertcat(*bl))
    if lean.n_instructions() >= plain.n_instructions():
        return plain
    for _ in range(PROBES):
        args = [rng.uniform(-1.0, 1.0, plain.numel_in(i)) + (0.17 if i != 0 else 1.3) for i in range(plain.n_in())]
        a, b_ = np.array(plain(*args), float), np.array(lean(*args), float)
        if not (np.isfinite(a).all() and np.isfinite(b_).all()) or \
                np.abs(a - b_).max() > 1e-12 * max(1.0, np.abs(a).max()):
            return plain
    return lean
