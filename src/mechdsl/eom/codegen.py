"""CasADi Functions from equations of motion, optional C code generation, fast calls.

``casadi_functions(eom, compiled=False)`` returns a lazy mapping name -> ``casadi.Function``;
a Function is built the first time it is asked for.  Names, inputs and outputs:

    ode            (t, x, u, p) -> xdot         x = [q; qd], xdot = [qd; qdd]
    ode_jacobian   (t, x, u, p) -> J            d xdot / d x, dense
    mass_matrix    (q, t, p) -> M               ((t, x, u, p) when M depends on the speeds)
    bias           (t, x, u, p) -> bias         M qdd = bias
    energy         (t, x, u, p) -> T, V, E
    outputs        (t, x, u, p) -> one output per EOM.outputs entry (named as the entry)
    constraints    (t, x, u, p) -> g, gdot      only when EOM.g exists
    start          (p) -> q0, qd0
    parameters     (free) -> p                  the free parameters (no binding, declaration order)
                                                to the full p, dependent parameters recomputed
    singularity    (t, x, u, p) -> one per EOM.singularity_monitors entry (when there are any)
    invariants     (t, x, u, p) -> one per EOM.invariants entry (when there are any)

u is the vector of the model's control inputs (``input`` declarations, in declaration order;
an empty (0, 1) column when there are none: pass ``[]`` or ``np.zeros(0)``).  The signature is
the same for every model, so glue written against it works for all.

Forward dynamics: EOM.qdd when the recursive route produced it; otherwise M qdd = bias is
solved NUMERICALLY at every call by CasADi's sparse Householder QR linear solver ('qr'),
wrapped around the SX expressions of M and bias in an MX Function.  Symbolic elimination on
SX (``casadi.solve`` on SX) is used only for one coordinate (a division).  See
docs/internals/numerics.md for the measurements behind this choice.

``compiled=True`` generates C for the requested Functions (plus the Jacobian of ``ode`` when
``ode_jacobian`` is requested: implicit integrators need it), compiles it with the system C compiler into
a shared library cached by the hash of the code, and loads it with ``casadi.external``.
Without a compiler the virtual-machine Functions are returned and ``.notes`` says why.

``FastFunction`` calls a Function through ``Function.buffer()`` (well under a microsecond of
overhead instead of tens of microseconds for a plain call); use it where Python is in the
loop.
"""
from __future__ import annotations

from ..digest import sha256
import logging
import os
from collections.abc import Mapping
from pathlib import Path

import numpy as np

from ..diagnostics import Diagnostic, MechError
from . import cachefiles
from .cachefiles import cache_dir      # (also imported from here: mechdsl.eom.codegen.cache_dir)
from .compiler import build_shared, find_compiler  # noqa: F401  (the compiler search, without CasADi: also warm_run's)
from .specialize import shared_derivatives, specialize

STANDARD = ("ode", "ode_jacobian", "mass_matrix", "bias", "energy", "outputs", "constraints",
            "start", "parameters", "singularity", "invariants")
LINSOL = "qr"          # sparse Householder QR: backward stable, code-generatable
log = logging.getLogger(__name__)


# --------------------------------------------------------------------------- building


def _ca():
    import casadi as ca

    return ca


TXUP = ["t", "x", "u", "p"]


class _Symbols:
    """SX symbols of an EOM: x = [q; qd] as one input, t, u (inputs), p."""

    def __init__(self, eom):
        ca = _ca()
        self.q, self.qd, self.t, self.p = eom.q, eom.qd, eom.t, eom.p
        self.u = eom.u_sym
        self.x = ca.vertcat(eom.q, eom.qd)
        self.n = eom.n
        self.txup = [self.t, self.x, self.u, self.p]


def _function(name, ins, outs, names_in, names_out):
    ca = _ca()
    try:  # an output may be named like an input ("x"): allowed, they live in separate schemes
        return ca.Function(name, ins, outs, names_in, names_out, {"allow_duplicate_io_names": True})
    except RuntimeError as e:  # free symbols: an expression outside (q, qd, t, u, p)
        msg = str(e).strip().splitlines()[-1]
        raise MechError(Diagnostic("E801", f"cannot build the CasADi Function '{name}': {msg}",
                                   help="every expression of the equations of motion must depend "
                                        "only on coordinates, their speeds, time, inputs and parameters")) from None


def _check_mass_matrix(eom):
    ca = _ca()
    M = ca.SX(eom.M)
    n = eom.n
    if M.shape != (n, n):
        raise MechError(Diagnostic("E802", f"mass matrix has shape {M.shape}, expected ({n}, {n})"))
    if ca.sprank(M.sparsity()) < n:
        empty = [eom.coords[i] for i in range(n) if M[:, i].nnz() == 0]
        which = f": {', '.join(empty)} {'has' if len(empty) == 1 else 'have'} no inertia" if empty else ""
        raise MechError(Diagnostic(
            "E803", f"the mass matrix of '{eom.name}' is structurally singular{which}",
            help="every coordinate must appear in the kinetic energy with its speed"))


SX_SOLVE_MAX = 40      # sx=True: unrolled LDL^T up to this many coordinates (O(n^3/6) SX operations)


def _lean(eom, plain):
    """Small models' ode from M and bias without the terms that cancel (mechdsl.eom.lean),
    the parameters' arithmetic folded into a few combinations (mechdsl.eom.fold)."""
    from .fold import fold_parameters
    from .lean import lean_ode

    ca = _ca()
    s = _Symbols(eom)
    return fold_parameters(lean_ode(eom, plain, s, lambda M, b: _function("ode", s.txup, [ca.vertcat(s.qd, ldl_solve(M, b))], TXUP,
                                                          ["xdot"]), _SMOOTH_OPS))


def ldl_solve(M, b):
    """M^-1 b for a symmetric M by an unrolled LDL^T factorization without pivoting (SX).

    Backward stable for symmetric positive definite M (a physical mass matrix): measured
    relative residuals |M a - b| / |b| of 1.7e-16 (3 links), 1.7e-16 (12), 3.6e-16 (30) on the
    N-link chain, against 3e-16 to 8e-16 for the numeric QR solve.  An indefinite or
    singular M gives inf/nan, as the numeric solve does."""
    ca = _ca()
    n = M.shape[0]
    L = [[None] * n for _ in range(n)]
    D = [None] * n
    for j in range(n):
        D[j] = M[j, j] - sum((L[j][k] ** 2 * D[k] for k in range(j)), ca.SX(0))
        for i in range(j + 1, n):
            L[i][j] = (M[i, j] - sum((L[i][k] * L[j][k] * D[k] for k in range(j)), ca.SX(0))) / D[j]
    y = []
    for i in range(n):
        y.append(b[i] - sum((L[i][k] * y[k] for k in range(i)), ca.SX(0)))
    x = [None] * n
    for i in reversed(range(n)):
        x[i] = y[i] / D[i] - sum((L[k][i] * x[k] for k in range(i + 1, n)), ca.SX(0))
    return ca.vertcat(*x)


LOOP_OPS = 8000    # compiled code loops over per-link kernels when the unrolled qdd has more SX operations


def looped_ode(eom, force: bool = False):
    """The ``ode`` Function as loops over per-link kernels (mechanics/chain.py), or None.

    Only for the recursive route with a run of identical links (``EOM.qdd_loop``) and, unless
    ``force``, an unrolled qdd of more than LOOP_OPS operations: the looped C compiles in about a
    second at any N but evaluates 2-3x slower than the unrolled C, and 10-20x slower in the
    virtual machine (benchmarks/chain_kernel.py), so it is used for compiled code only."""
    if eom.qdd is None or eom.__dict__.get("qdd_loop") is None:    # (not forcing a lazy plan)
        return None
    if not force:
        s = _Symbols(eom)
        if _function("qdd", s.txup, [eom.qdd], TXUP, ["qdd"]).n_instructions() <= LOOP_OPS:
            return None
    plan = eom.qdd_loop
    return None if plan is None else plan.ode(eom)


def build_ode(eom, sx: bool = False, loop: bool = False):
    """The ``ode`` Function (t, x, u, p) -> xdot.  sx=True: an SX Function also when M qdd =
    bias must be solved (``ldl_solve``, up to SX_SOLVE_MAX coordinates) instead of the MX
    Function around the numeric QR solve.  loop=True (not with sx): the looped form of
    ``looped_ode`` where it applies and pays."""
    ca = _ca()
    s = _Symbols(eom)
    n = eom.n
    if loop and not sx:
        f = looped_ode(eom)
        if f is not None:
            return f

    if eom.qdd is not None:
        xdot = ca.vertcat(s.qd, eom.qdd)
        f = _function("ode", s.txup, [xdot], TXUP, ["xdot"])
        return _lean(eom, f) if sx else f
    _check_mass_matrix(eom)
    if n == 1:  # one coordinate: the "solve" is a division, exact in SX
        xdot = ca.vertcat(s.qd, eom.bias / eom.M)
        f = _function("ode", s.txup, [xdot], TXUP, ["xdot"])
        if sx:
            from .fold import fold_parameters

            return fold_parameters(f)
        return f
    if sx and n <= SX_SOLVE_MAX:
        xdot = ca.vertcat(s.qd, ldl_solve(ca.SX(eom.M), ca.SX(eom.bias)))
        return _lean(eom, _function("ode", s.txup, [xdot], TXUP, ["xdot"]))
    mb = _function("mass_bias", s.txup, [eom.M, eom.bias], TXUP, ["M", "bias"])
    t = ca.MX.sym("t")
    x = ca.MX.sym("x", 2 * n)
    u = ca.MX.sym("u", s.u.numel())
    p = ca.MX.sym("p", s.p.numel())
    M, b = mb(t, x, u, p)
    qdd = ca.solve(M, b, LINSOL)
    return ca.Function("ode", [t, x, u, p], [ca.vertcat(x[n:], qdd)], TXUP, ["xdot"])


def jacobian_of(ode):
    """Dense d xdot/dx as a Function (t, x, u, p) -> J, built on ``ode``'s own Jacobian."""
    ca = _ca()
    t, x, u, p = (ca.MX.sym(nm, ode.sparsity_in(i)) for i, nm in enumerate(TXUP))
    jac = ode.jacobian()
    out = jac(t, x, u, p, ca.MX(ode.size1_out(0), 0))
    jx = out[jac.name_out().index("jac_xdot_x")] if isinstance(out, (list, tuple)) else out
    return ca.Function("ode_jacobian", [t, x, u, p], [ca.densify(jx)], TXUP, ["J"])


def _build(eom, name, outputs, sx=False, loop=False):
    ca = _ca()
    s = _Symbols(eom)
    txup = s.txup
    if name == "ode":
        return build_ode(eom, sx, loop)
    if name == "mass_matrix":
        if ca.depends_on(ca.SX(eom.M), s.qd):
            return _function("mass_matrix", txup, [eom.M], TXUP, ["M"])
        return _function("mass_matrix", [s.q, s.t, s.p], [eom.M], ["q", "t", "p"], ["M"])
    if name == "bias":
        return _function("bias", txup, [eom.bias], TXUP, ["bias"])
    if name == "energy":
        return _function("energy", txup, [eom.T, eom.V, eom.T + eom.V], TXUP, ["T", "V", "E"])
    if name == "outputs":
        names = list(eom.outputs) if outputs is None else list(outputs)
        exprs = [ca.SX(eom.outputs[k]) for k in names]
        return _function("outputs", txup, exprs, TXUP, names)
    if name == "constraints":
        g = ca.SX(eom.g)
        gdot = ca.jtimes(g, s.q, s.qd) + ca.jacobian(g, s.t)
        return _function("constraints", txup, [g, gdot], TXUP, ["g", "gdot"])
    if name == "start":
        return _function("start", [s.p], [ca.SX(eom.q0), ca.SX(eom.qd0)], ["p"], ["q0", "qd0"])
    if name == "parameters":
        return build_parameters(eom)
    if name == "singularity":
        mons = dict(singularity_monitors(eom))
        return _function("singularity", txup, [ca.SX(v) for v in mons.values()], TXUP, list(mons))
    if name == "invariants":
        inv = dict(eom.invariants)
        return _function("invariants", txup, [ca.SX(v) for v in inv.values()], TXUP, list(inv))
    raise KeyError(name)


def free_parameters(eom) -> tuple[str, ...]:
    """The parameters without a binding (the inputs of the ``parameters`` Function), in order."""
    bound = _bindings(eom)
    return tuple(n for n in eom.params if n not in bound)


def _bindings(eom) -> dict:
    model = getattr(eom, "model", None)
    if model is None:
        return {}
    return {p.name: p.binding for p in model.real_parameters if p.binding is not None and p.name in eom.params}


def build_parameters(eom):
    """(free) -> p: dependent parameters recomputed from their bindings (SX)."""
    ca = _ca()
    from ..model import exprs as X
    from ..model import ir

    bound = _bindings(eom)
    free = free_parameters(eom)
    syms = {n: ca.SX.sym(n) for n in free}
    model = getattr(eom, "model", None)
    known = {p.name: p.value for p in (model.parameters if model is not None else ())}
    vals: dict = dict(syms)

    def leaf(n):
        if isinstance(n, ir.Const):
            return n.value
        if isinstance(n, ir.Param):
            return vals[n.name] if n.name in vals else known[n.name]
        raise ValueError(f"cannot translate {X.to_text(n)} in a parameter binding")

    for name in eom.params:          # declaration order: a binding refers to earlier parameters
        if name in bound:
            vals[name] = X._translate(bound[name], leaf, X._casadi_ops, ca)
    out = ca.vertcat(*[ca.SX(vals[n]) for n in eom.params]) if eom.params else ca.SX(0, 1)
    free_vec = ca.vertcat(*[syms[n] for n in free]) if free else ca.SX(0, 1)
    return _function("parameters", [free_vec], [out], ["free"], ["p"])


def singularity_monitors(eom) -> dict:
    """name -> SX scalar that is 0 at a singular configuration (e.g. cos(theta) for ZYX angles).

    Entries may also be (expr, threshold) pairs; only the expression is used here.
    """
    mons = getattr(eom, "singularity_monitors", None) or {}
    return {k: (v[0] if isinstance(v, tuple) else v) for k, v in mons.items()}


def available(eom) -> tuple[str, ...]:
    names = ["ode", "ode_jacobian", "mass_matrix", "bias", "energy", "outputs", "start", "parameters"]
    if eom.g is not None:
        names.append("constraints")
    if singularity_monitors(eom):
        names.append("singularity")
    if getattr(eom, "invariants", None):
        names.append("invariants")
    return tuple(n for n in STANDARD if n in names)


class FunctionSet(Mapping):
    """A lazy mapping name -> casadi.Function for one EOM (see the module docstring).

    ``compiled`` says whether the Functions are native code; ``notes`` explains fallbacks;
    ``library`` is the path of the shared library when compiled.
    """

    def __init__(self, eom, *, compiled: bool = False, names=None, outputs=None, derivatives: int = 0,
                 sx: bool = False, fixed=(), jacobian: str = "full", each: bool = False, budget: int | None = None):
        self.eom = eom
        # each: compile every Function on its own when it is first asked for, and only it (its
        # derivatives when ``derivatives`` asks), failing with a located error (E804, E805)
        # instead of falling back; otherwise the Functions asked for are compiled together
        # into one library on first use, and a failure falls back to the virtual machine
        # with a note (the simulator's runs, which say so in their warnings)
        self.each, self.budget = bool(each), budget
        self.jacobian_kind = jacobian     # compiled: "full" Jacobian, or "forward" derivative only
        self.derivatives = int(derivatives)
        self.sx = bool(sx)
        self.fixed = tuple((int(i), float(v)) for i, v in fixed)
        fixed_at = dict(self.fixed)
        self.parameter_names = tuple(n for i, n in enumerate(eom.params) if i not in fixed_at)
        self.outputs = None if outputs is None else tuple(outputs)
        if self.outputs is not None:
            unknown = [o for o in self.outputs if o not in eom.outputs]
            if unknown:
                raise KeyError(f"unknown output(s): {', '.join(unknown)}")
        avail = available(eom)
        self._names = avail if names is None else tuple(n for n in avail if n in names)
        self.want_compiled = compiled
        self.compiled = False
        self.library: str | None = None
        self.notes: list[str] = []
        self._cache: dict = {}
        self._compiled_done = False
        self.looped = False

    def __getitem__(self, name):
        if name not in self._names:
            raise KeyError(f"no Function {name!r}; available: {', '.join(self._names)}")
        if self.want_compiled and self.each:
            if name not in self._cache:
                self._compile_one(name)
            return self._cache[name]
        if self.want_compiled and not self._compiled_done:
            self._compile_all()
        if name not in self._cache:
            # read from the model cache (Functions with parameters built in are not stored)
            stored = None if self.fixed else self.eom.workspace.stored_functions(self.eom)
            hit = stored.get((name, self.outputs, self.sx)) if stored else None
            if hit is not None:
                self._cache[name] = hit
            elif name == "ode_jacobian":
                self._cache[name] = jacobian_of(self["ode"])
            else:
                self._cache[name] = self._make(name)
            if self.sx:               # called in an MX graph with p as numbers: specialized (eom.numeric_p)
                from .numeric_p import numeric_p

                self._cache[name] = numeric_p(self._cache[name])
        return self._cache[name]

    def _make(self, name, loop: bool = False):
        # the looped ode (big chains, compiled only) is an MX Function: parameters are not
        # specialized into it (specialize keeps the Function's kind)
        f = _build(self.eom, name, self.outputs, self.sx, loop=loop and not self.fixed)
        if self.fixed:
            f = specialize(f, self.fixed, len(self.eom.params))
            f = drop_cancelled(f) if name == "ode" else f
        return shared_derivatives(f) if self.sx else f

    def __iter__(self):
        return iter(self._names)

    def __len__(self):
        return len(self._names)

    def __repr__(self):
        kind = "compiled" if self.compiled else "virtual machine"
        return f"<FunctionSet {self.eom.name!r} ({kind}): {', '.join(self._names)}>"

    def _compile_one(self, name):
        f = jacobian_of(self._make("ode")) if name == "ode_jacobian" else self._make(name, loop=True)
        loaded, note, lib = compile_functions([f], tag=f"{self.eom.name}_{name}", jacobian=False,
                                              derivatives=self.derivatives, budget=self.budget, strict=True)
        self.notes.append(note)
        self.compiled, self.library = True, lib
        self._cache[name] = loaded[f.name()]

    def _compile_all(self):
        self._compiled_done = True
        funcs = [self._make(n, loop=True) for n in self._names if n != "ode_jacobian"]
        if "ode_jacobian" in self._names and "ode" not in self._names:
            funcs.append(self._make("ode", loop=True))
        ode = next((f for f in funcs if f.name() == "ode"), None)
        self.looped = ode is not None and ode.is_a("MXFunction") and self.eom.qdd is not None
        forward = self.looped or self.jacobian_kind == "forward"
        jac = ("forward" if forward else True) if "ode_jacobian" in self._names else False
        loaded, note, lib = compile_functions(funcs, tag=self.eom.name, jacobian=jac,
                                              derivatives=self.derivatives)
        if note:
            self.notes.append(note)
        if loaded is None:
            return
        if self.looped:
            self.notes.append("the ode loops over per-link kernels (a chain of identical links)")
        self.compiled = True
        self.library = lib
        for f in funcs:
            if f.name() in self._names:
                self._cache[f.name()] = loaded[f.name()]
        if "ode_jacobian" in self._names:
            self._cache["ode_jacobian"] = jacobian_of(loaded["ode"])


_STRUCTURE = ("q", "qd", "t", "u", "p", "T", "V", "M", "bias", "qdd", "g", "outputs", "q0", "qd0",
              "singularity_monitors", "invariants")


_SMOOTH_OPS = ("ASSIGN", "ADD", "SUB", "MUL", "DIV", "NEG", "EXP", "LOG", "POW", "CONSTPOW", "SQRT", "SQ",
               "TWICE", "SIN", "COS", "TAN", "ASIN", "ACOS", "ATAN", "SINH", "COSH", "TANH", "ASINH", "ACOSH",
               "ATANH", "ATAN2", "CONST", "INPUT", "OUTPUT", "PARAMETER", "INV", "HYPOT", "LOG1P", "EXPM1")
CANCEL_PROBES = 16


def drop_cancelled(f):
    """``f`` (an SX Function (t, x, u, p) -> xdot) without the terms that cancel: an output entry
    whose derivative with respect to an input entry is zero (to round-off) at random states
    does not depend on it; setting that input to 0 in that output lets SX fold the terms that
    cancelled only numerically (the cart-pole's cart speed in the recursive route's
    velocity products).  Only for analytic expressions (no if_else, fmin, fabs, ...: a
    piecewise term can vanish at every probe and not elsewhere); the result must equal ``f``
    at other random states to 1e-12 relative, else ``f`` is returned unchanged."""
    ca = _ca()
    if not f.is_a("SXFunction") or f.n_out() != 1:
        return f
    smooth = {getattr(ca, "OP_" + o) for o in _SMOOTH_OPS if hasattr(ca, "OP_" + o)}
    if any(f.instruction_id(k) not in smooth for k in range(f.n_instructions())):
        return f
    ins = [ca.SX.sym(nm, f.sparsity_in(i)) for i, nm in enumerate(f.name_in())]
    out = f.call(ins)[0]
    free = [i for i, nm in enumerate(f.name_in()) if nm != "p"]
    z = ca.vertcat(*[ins[i] for i in free])
    if z.numel() == 0:
        return f
    jac = ca.Function("J", ins, [ca.jacobian(out, z)])
    rng = np.random.default_rng(20240613)

    def draw():
        return [rng.uniform(-1.0, 1.0, f.numel_in(i)) + (0.17 if f.name_in(i) != "t" else 1.3) for i in range(f.n_in())]

    scale = np.zeros((out.numel(), z.numel()))
    seen = 0
    for _ in range(CANCEL_PROBES):
        J = np.abs(np.array(jac(*draw()), float))
        if np.isfinite(J).all():
            scale, seen = np.maximum(scale, J), seen + 1
    if seen < CANCEL_PROBES // 2:
        return f
    rows = []
    for i in range(out.numel()):
        dead = [j for j in range(z.numel()) if scale[i, j] <= 1e-12 * max(scale[i].max(), 1.0)]
        rows.append(ca.substitute(out[i], z[dead], ca.DM.zeros(len(dead))) if dead else out[i])
    g = ca.Function(f.name(), ins, [ca.vertcat(*rows)], f.name_in(), f.name_out())
    if g.n_instructions() >= f.n_instructions():
        return f
    for _ in range(CANCEL_PROBES):
        args = draw()
        a, b = np.array(f(*args), float), np.array(g(*args), float)
        if np.isfinite(a).all() and not (np.abs(a - b) <= 1e-12 * (1.0 + np.abs(a))).all():
            return f
    return g


def casadi_functions(eom, compiled: bool = False, *, names=None, outputs=None, derivatives: int = 0,
                     sx: bool = False, fixed=(), jacobian: str = "full", each: bool = False,
                     budget: int | None = None, kind=None) -> FunctionSet:
    """The CasADi Functions of ``eom`` (lazy mapping; see the module docstring).

    each=True (with compiled=True): every Function is compiled on its own when first asked for
    (``Model.casadi``: only what is used is compiled), and a compile that cannot be done
    raises (E804; E805 over ``budget`` bytes of C) instead of falling back.
    kind: the FunctionSet class (default FunctionSet; a constrained model's problem Functions:
    mechdsl.dae.functions.ConstrainedFunctionSet).

    derivatives=2 (with compiled=True): the library also holds the first and second
    derivatives of every Function (jac_, fwd1_, adj1_ and their own jac_/fwd1_/adj1_), which
    ``casadi.external`` finds by name: Jacobians and the exact Hessian of a Lagrangian (IPOPT)
    then run in compiled code instead of failing ("Derivatives cannot be calculated").
    sx=True: ``ode`` is an SX Function for every model up to SX_SOLVE_MAX coordinates (see
    ``build_ode``); the simulator keeps the numeric QR solve (sx=False).
    fixed: (index in p, value) pairs built into every Function as numbers (``specialize``);
    "p" then holds only the other parameters (``.parameter_names``).

    jacobian="forward" (compiled): compile the forward derivative of ``ode`` instead of its
    dense Jacobian, for methods that only need derivatives to be available (CVODES-Adams with
    functional iteration sets up a Jacobian it never evaluates).

    A looped ``ode`` (``looped_ode``: big chains, compiled) always gets the forward derivative:
    its Jacobian as C would unroll the loops over every direction (3.3 MB at N = 50).

    names: restrict to these Functions (default: all that apply); outputs: restrict the
    ``outputs`` Function to these EOM.outputs entries (default: all).  Results are cached
    (per EOM structure), so asking twice costs nothing.
    """
    # keyed by the identity of every field the Functions are built from (raw __dict__ entries,
    # so lazily derived fields are not forced): copies made by EOM.replace (other parameter
    # values) share Functions, compiled libraries and the integrators built on them
    objs = tuple(eom.__dict__.get(f) for f in _STRUCTURE)
    key = (tuple(map(id, objs)), bool(compiled), None if names is None else tuple(sorted(names)),
           None if outputs is None else tuple(outputs), int(derivatives), bool(sx),
           tuple((int(i), float(v)) for i, v in fixed), jacobian, bool(each), budget, kind)
    hit = _SETS.get(key)
    if hit is not None and all(a is b for a, b in zip(hit[0], objs)):
        _SETS[key] = _SETS.pop(key)            # most recently used last
        return hit[1]
    fs = (kind or FunctionSet)(eom, compiled=compiled, names=names, outputs=outputs, derivatives=derivatives,
                               sx=sx, fixed=fixed, jacobian=jacobian, each=each, budget=budget)
    if len(_SETS) >= _SETS_MAX:
        _SETS.pop(next(iter(_SETS)))
    _SETS[key] = (objs, fs)                    # holding the objects keeps their ids unique
    return fs


_SETS: dict = {}
_SETS_MAX = 64


# --------------------------------------------------------------------------- C code generation


def compiler_version(cc: str) -> str:
    """The first line of ``cc --version`` (``cc`` when it says nothing), part of a compiled
    library's key.  Kept in ``<cache_dir()>/compilers`` by the compiler's real path, size and
    modification time, so a warm run starts no process (nor imports subprocess) to ask again."""
    try:
        st = os.stat(cc)
        tag = f"{os.path.realpath(cc)}\t{st.st_size}\t{st.st_mtime_ns}\t"
    except OSError:
        tag = None
    memo = cache_dir() / "compilers"
    if tag is not None:
        data, _ = cachefiles.read_bytes(memo)        # (a file only this user can write)
        for line in (data or b"").decode("utf-8", "replace").splitlines():
            if line.startswith(tag):
                return line[len(tag):] or cc
    import subprocess

    try:
        version = subprocess.run([cc, "--version"], capture_output=True, text=True, timeout=30).stdout
        version = version.splitlines()[0] if version else cc
    except (OSError, subprocess.SubprocessError):
        return cc
    if tag is not None and "\n" not in version and cachefiles.trusted_folder(memo.parent, create=True):
        try:
            # one short line: appends do not interleave
            fd = os.open(memo, os.O_WRONLY | os.O_APPEND | os.O_CREAT | getattr(os, "O_NOFOLLOW", 0), 0o600)
            with os.fdopen(fd, "a", encoding="utf-8") as f:
                f.write(tag + version + "\n")
        except OSError:
            pass
    return version


JAC_MAX_CODE = 1_000_000   # above this, compile the forward derivative of ode instead of its Jacobian
COMPILE_BUDGET = 16_000_000   # bytes of generated C one compile may hand to the compiler (compile_functions)


def _names_of(funcs) -> str:
    names = [f.name() for f in funcs]
    return ("the Function " if len(names) == 1 else "the Functions ") + ", ".join(names)


def cflags_for(code_size: int) -> list[str]:
    """Optimization level by size: gcc time grows much faster than linearly with function size.

    Measured (10-link chain, Lagrange route, ode Jacobian = 1.1 MB of C): -O0 2.9 s,
    -O1 27 s, -O2 40 s of gcc; run time -O0 3x slower than -O1, -O1 within 15% of -O2.
    """
    env = os.environ.get("MECHDSL_CFLAGS")
    if env:
        return env.split()
    if code_size <= 300_000:
        return ["-O2"]
    if code_size <= 1_000_000:
        return ["-O1"]
    return ["-O0"]


def derivative_functions(funcs, order: int = 2) -> list:
    """Derivatives of ``funcs`` up to ``order`` under the names casadi.external looks for:
    directional ones only, whose size grows like the Function's own (a dense ``jac_`` of a
    7-joint arm's ode is 8x the ode, its second Jacobian 100x; with them the arm's library was
    43 MB of C, 75 s of gcc and 3 GB): first order ``fwd1_`` and ``adj1_`` (CasADi assembles
    Jacobians from sweeps of them), second order ``fwd1_adj1_`` (forward over reverse: the
    Hessian-vector products of an exact Hessian, e.g. IPOPT's)."""
    out = []
    for f in funcs:
        fwd, adj = f.forward(1), f.reverse(1)
        out += [fwd, adj]
        if order >= 2:
            out.append(adj.forward(1))
    return out


NOT_CACHED = "not in the cache (not compiled: cached_only)"


def compile_functions(funcs, tag: str = "model", jacobian: bool | str = True, derivatives: int = 0,
                      extra_units: tuple[str, ...] = (), extra_flags: list[str] | None = None,
                      budget: int | None = None, strict: bool = False, cached_only: bool = False):
    """Generate C for ``funcs`` (+ the Jacobian of any 'ode' unless jacobian=False), compile, load.

    ``jacobian="forward"``: only the forward derivative of 'ode' (CasADi assembles a Jacobian
    from it by sweeps if one is ever evaluated), never the dense Jacobian.

    ``extra_units``: hand-written C sources linked into the same library (the compiled
    stepping loop of mechdsl.simulation.crk, code of mechdsl.eom.sxcode); they are part of the
    cache key.  ``extra_flags``: their optimization flags instead of the size rule (sxcode's
    chunked code compiles in linear time at any level), one list for all or one per unit.  No ``funcs``: only the extra units.

    ``budget``: most bytes of generated C to hand to the compiler (default COMPILE_BUDGET;
    the compiler's time and memory grow faster than the code: a 7-joint arm's 40 MB took 298 s,
    the 20-link chain's Functions with second derivatives 7 GB); more is not compiled and the
    note says so.  ``strict``: a compile that cannot be done (no compiler, over the budget, a
    failed build) raises MechError (E804, E805) instead of returning None with a note.
    ``cached_only``: load the library when the cache holds it, else return (None, NOT_CACHED,
    None) without compiling (the stepping loop's pay-back rule, simulation/backends/payback.py).

    Returns (dict name -> external Function or None, note or None, library path or None).
    The Functions and the Jacobians go into two translation units, each optimized by its own
    size (``cflags_for``) and compiled in parallel, then linked into one shared library.  The
    library is cached under ``cache_dir()`` by the SHA-256 of the code and the flags; it is
    built in a temporary folder and renamed into place (safe under concurrency).
    """
    ca = _ca()
    cc = find_compiler()
    if cc is None:
        return _no_compiler(funcs, strict)
    units, flags, jac_kind = _units(ca, funcs, jacobian, derivatives, extra_units, extra_flags)
    limit = COMPILE_BUDGET if budget is None else int(budget)
    total = sum(len(code) for code in units)
    if total > limit:
        what = (f"{_names_of(funcs)}" + (f" with derivatives to order {derivatives}" if derivatives else "")
                + f" are {total / 1e6:.3g} MB of C, over the compile budget of {limit / 1e6:.3g} MB")
        if strict:
            raise MechError(Diagnostic("E805", f"not compiled: {what}",
                                       help="ask for fewer Functions or no derivatives, use the virtual-machine "
                                            "Functions (compiled=False), or raise compile_budget (bytes of C)"))
        return None, f"not compiled: {what} (compile_budget); using the CasADi virtual machine", None
    version = compiler_version(cc)
    key = "\n".join([*units, repr(flags), version, ca.__version__])
    full = sha256(key.encode()).hexdigest()
    digest = full[:24]
    d = cache_dir()
    # a library runs code when loaded: only from a folder no other user owns or can write
    # (mechdsl.eom.cachefiles); otherwise it is built for this run alone in a private folder
    private = None if cachefiles.trusted_folder(d, create=True) else _private_folder()
    lib = (private or d) / f"{digest}.so"
    size_kb = sum(len(c) for c in units) // 1000
    problem = _cache_problem(lib, full) if private is None and lib.exists() else None
    if private is None and lib.exists() and problem is None:
        note = f"loaded compiled model from cache {lib}"
        cachefiles.hit("compiled-code", digest)
    elif cached_only:
        return None, NOT_CACHED, None
    else:
        log.info("compiling %d kB of C with %s into %s", size_kb, Path(cc).name, lib)
        cachefiles.miss("compiled-code", digest, "not built yet" if private is None and problem is None
                        else problem or "the cache folder is not used")
        failed = _compile_into(cc, units, flags, funcs, lib, full, private or d, private is None, strict)
        if failed is not None:
            return None, failed, None
        note = (f"compiled {size_kb} kB of C with {Path(cc).name} "
                f"({', '.join(dict.fromkeys(' '.join(f) for f in flags))}) into {lib}"
                + (f"; the ode Jacobian through its compiled {jac_kind}" if jac_kind else ""))
        if problem:
            note = f"the cached library {lib} {problem}: rebuilt; " + note
    log.debug("%s", note)
    loaded = {f.name(): ca.external(f.name(), str(lib)) for f in funcs}
    if private is not None:             # loaded (mapped): the files are not needed any more
        import shutil

        shutil.rmtree(private, ignore_errors=True)
        note += " (a private folder for this run: the cache folder is not used)"
    return loaded, note, str(lib)


def _no_compiler(funcs, strict: bool):
    """compile_functions's answer without a C compiler (E804 when ``strict``)."""
    env_cc = os.environ.get("CC")
    looked = (f"$CC = {env_cc!r} is not a program on PATH (CC names one program, without flags)" if env_cc
              else "looked for $CC, gcc, cc, clang")
    if strict:
        raise MechError(Diagnostic("E804", f"cannot compile {_names_of(funcs)}: no C compiler found ({looked})",
                                   help="install a C compiler (gcc, clang) or set $CC, or use the "
                                        "virtual-machine Functions (compiled=False)"))
    return None, (f"no C compiler found ({looked}); "
                  "using the CasADi virtual machine instead of compiled code"), None


def _units(ca, funcs, jacobian, derivatives: int, extra_units, extra_flags):
    """(the translation units' C, each unit's flags, what the ode's Jacobian is compiled as or
    None): the Functions as chunked C, their derivatives, the ode's Jacobian (or its forward
    derivative when the Jacobian's C is too large), then the extra units."""
    from .sxcode import c_unit

    units = []
    # SX Functions as chunked straight-line C (mechdsl.eom.sxcode: gcc's time linear in the
    # code; CasADi's one-function-per-Function C took gcc 10-14 s for 25,000 operations)
    if funcs or not extra_units:
        units.append(c_unit(funcs, "mechdsl_model.c"))
    odes = [f for f in funcs if f.name() == "ode"] if jacobian and not derivatives else []
    if derivatives:
        units.append(c_unit(derivative_functions(funcs, derivatives), "mechdsl_derivatives.c"))
    jac_kind = None
    if odes:
        code, jac_kind = "", None
        if jacobian != "forward":
            jg = ca.CodeGenerator("mechdsl_jac.c", {"with_header": False, "verbose": False})
            jg.add(odes[0].jacobian())
            code = jg.dump()
            jac_kind = "jacobian"
        if jacobian == "forward" or len(code) > JAC_MAX_CODE:
            # a huge Jacobian compiles for minutes and, at -O0, runs slower than the virtual
            # machine: generate the forward derivative instead (CasADi assembles J by sweeps)
            jg = ca.CodeGenerator("mechdsl_fwd.c", {"with_header": False, "verbose": False})
            jg.add(odes[0].forward(1))
            code = jg.dump()
            jac_kind = "forward derivative"
        units.append(code)
    # chunked C (no CasADi-generated function in the unit) compiles in linear time: -O1 at any size
    flags = [cflags_for(len(code)) if "CASADI_PREFIX" in code or os.environ.get("MECHDSL_CFLAGS")
             else ["-O1"] for code in units]
    units += list(extra_units)
    env_flags = os.environ.get("MECHDSL_CFLAGS")
    per_unit = extra_flags is not None and bool(extra_flags) and isinstance(extra_flags[0], (list, tuple))
    flags += [cflags_for(len(code)) if extra_flags is None or env_flags else
              list(extra_flags[i] if per_unit else extra_flags) for i, code in enumerate(extra_units)]
    return units, flags, jac_kind


def _compile_into(cc: str, units, flags, funcs, lib: Path, full: str, folder: Path, shared: bool, strict: bool):
    """Compile ``units`` into ``lib`` (built in a temporary folder in ``folder``, its hash recorded
    first when ``shared``: the cache folder, then renamed into place); None, or why it failed
    (E804 when ``strict``)."""
    import tempfile        # (only a build needs it: a warm run loads the cached library)

    try:
        cachefiles.remove_stale_builds(folder)
        with tempfile.TemporaryDirectory(dir=folder, prefix=f".build-{os.getpid()}-") as tmp:
            built, errors = build_shared(cc, units, flags, tmp)
            out = Path(built) if built else None
            if errors:
                tail = " | ".join(errors[0].splitlines()[-3:])
                if strict:
                    raise MechError(Diagnostic("E804", f"C compilation of {_names_of(funcs)} failed ({cc}): "
                                                       f"{tail}", help="use the virtual-machine Functions "
                                                                       "(compiled=False)"))
                return f"C compilation failed ({cc}): {tail}; using the CasADi virtual machine"
            os.chmod(out, 0o600)
            if shared:
                _record_digest(out, lib, full)  # the hash first: a library in place always has its hash
            os.replace(out, lib)
    except OSError as e:
        if strict:
            raise MechError(Diagnostic("E804", f"cannot compile {_names_of(funcs)} into {folder}: {e}",
                                       help="check that the cache folder (MECHDSL_CACHE) is writable")) from None
        return f"cannot compile into {folder}: {e}; using the CasADi virtual machine"
    return None


def _private_folder() -> Path:
    import tempfile

    return Path(tempfile.mkdtemp(prefix="mechdsl-build-"))     # 0700


def _digest_path(lib: Path) -> Path:
    return lib.with_suffix(".sha256")


def _file_sha256(path: Path) -> str:
    h = sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def _record_digest(built: Path, lib: Path, key: str) -> None:
    """Write the hash of the library ``built`` and its full key next to its cache place ``lib``
    (``<name>.sha256``: "<file sha256> <key sha256>"), atomically, mode 0600."""
    if not cachefiles.write_bytes(_digest_path(lib), f"{_file_sha256(built)} {key}\n".encode("ascii")):
        raise OSError(f"cannot write {_digest_path(lib)}")


def _cache_problem(lib: Path, key: str) -> str | None:
    """None if the cached library is the one built here for ``key``, else what is wrong with it.

    A truncated library kills the process that loads it (SIGBUS); another library under the
    right name gives wrong numbers (or runs what it likes when loaded).  The file hash and the
    full key recorded at build time catch both, and are checked without loading the library;
    a file another user owns or can write is not used at all (mechdsl.eom.cachefiles)."""
    why = cachefiles.check_file(lib)
    if why:
        return why
    data, why = cachefiles.read_bytes(_digest_path(lib))
    if data is None:
        return "has no recorded content hash" if why == "no entry" else f"has no usable hash record ({why})"
    parts = data.decode("ascii", "replace").split()
    if len(parts) != 2:
        return "has a hash record without its key (an older format, or written by hand)"
    if parts[1] != key:
        return "was built for another key (swapped or copied)"
    try:
        actual = _file_sha256(lib)
    except OSError as e:
        return f"cannot be read ({e.strerror or e})"
    if actual != parts[0]:
        return "does not match its recorded content hash (truncated or replaced)"
    return None


# --------------------------------------------------------------------------- fast calls


def dense_function(f):
    """``f`` itself when its inputs and outputs are dense, else a thin wrapper Function that
    takes and returns dense arrays (what FastFunction's buffers need)."""
    if all(f.sparsity_out(i).is_dense() for i in range(f.n_out())) and \
            all(f.sparsity_in(i).is_dense() for i in range(f.n_in())):
        return f
    ca = _ca()
    ins = [ca.MX.sym(f.name_in(i), f.size1_in(i), f.size2_in(i)) for i in range(f.n_in())]
    outs = f.call([ca.project(a, f.sparsity_in(i)) if not f.sparsity_in(i).is_dense() else a
                   for i, a in enumerate(ins)])
    return ca.Function(f.name() + "_dense", ins, [ca.densify(o) for o in outs], f.name_in(), f.name_out())


class FastFunction:
    """Call a casadi.Function through ``Function.buffer()`` with preallocated numpy arrays.

    ``ff(*args)`` copies the arguments into the input buffers, evaluates, and returns the
    outputs as numpy arrays (a vector for a column, a 2-D array for a matrix, dense).  With
    ``copy=False`` the returned arrays are the internal buffers, overwritten by the next call.
    Sparse outputs are densified by a thin wrapper Function.
    """

    def __init__(self, f, copy: bool = True):
        f = dense_function(f)
        self.function = f
        self.copy = copy
        self._buf, self._eval = f.buffer()
        self._args = [np.zeros(f.numel_in(i)) for i in range(f.n_in())]
        self._res = [np.zeros(f.numel_out(i)) for i in range(f.n_out())]
        self._shapes = [(f.size1_out(i), f.size2_out(i)) for i in range(f.n_out())]
        for i, a in enumerate(self._args):
            self._buf.set_arg(i, memoryview(a))
        for i, r in enumerate(self._res):
            self._buf.set_res(i, memoryview(r))
        self._views = [r if s[1] == 1 else r.reshape(s[1], s[0]).T for r, s in zip(self._res, self._shapes)]
        self._single = len(self._res) == 1

    def bind(self, **fixed):
        """A faster callable of the remaining inputs, with ``fixed`` inputs (by name) set once.

        E.g. ``rhs = FastFunction(f["ode"]).bind(u=u, p=p)`` gives ``rhs(t, x)`` for scipy.  The
        closure shares this object's buffers: do not mix it with direct calls.
        """
        names = self.function.name_in()
        for k, v in fixed.items():
            if k not in names:
                raise KeyError(f"{self.function.name()} has no input {k!r} (inputs: {', '.join(names)})")
            self._args[names.index(k)][:] = v
        free = [self._args[i] for i, n in enumerate(names) if n not in fixed]
        ev = self._eval
        views = self._views
        copy = self.copy
        if self._single and len(free) == 2 and free[0].size == 1:
            a0, a1 = free
            out = views[0]
            copyto = np.copyto

            def call2(u, v):
                a0[0] = u
                copyto(a1, v)
                ev()
                return out.copy() if copy else out
            call2.owner = self   # keeps the FunctionBuffer (and its memory) alive
            return call2

        def call(*args):
            for dst, a in zip(free, args):
                dst[:] = a
            ev()
            if self._single:
                return views[0].copy() if copy else views[0]
            return tuple(v.copy() for v in views) if copy else tuple(views)
        call.owner = self
        return call

    def __call__(self, *args):
        for dst, a in zip(self._args, args):
            dst[:] = np.ravel(a, order="F") if np.ndim(a) > 1 else a    # matrices column-major
        self._eval()
        if self._single:
            v = self._views[0]
            return v.copy() if self.copy else v
        return tuple(v.copy() for v in self._views) if self.copy else tuple(self._views)
