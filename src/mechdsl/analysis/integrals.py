"""First integrals: conserved momenta of cyclic coordinates (and of translation symmetries) and
the Jacobi integral.

- A coordinate q_k is cyclic when dL/dq_k == 0 identically and no generalized force acts on it
  (Q_k - dD/dqd_k == 0, and no constraint force: dg/dq_k == 0).  Then p_k = dL/dqd_k is
  conserved.  "Identically" is decided on the SX first (no dependence at all: ``symbolic``);
  otherwise the derivative is evaluated at deterministic random states and, if it vanishes
  there, sympy is asked to simplify it to 0 (``symbolic``) or the check stays ``numeric``.
- More generally, a direction N with dL/dq . N == 0 and Q . N == 0 at every state (a
  translation symmetry: two free bodies) conserves p . N (Noether); found as the null space
  of those rows stacked over random states.  Coordinate axes in it are the cyclic coordinates.
- A rotation of coordinate pairs about their origin (skew A, ``rotations.py``) that leaves L
  and the forces invariant conserves the angular momentum p . A q (Kepler in x, y: x p_y - y p_x).
- The Jacobi integral h = sum qd_k dL/dqd_k - L = T2 - T0 + V is conserved when L has no
  explicit time, no dissipation and no non-conservative force act (and the constraints do not
  move).  It is the energy T + V when T = T2 (scleronomic); otherwise the two differ.
"""
from __future__ import annotations

from dataclasses import field

import numpy as np

from ..eom import fold_inputs
from .core import N_PROBE, Probe, _is_structural_zero, at_states, null_space, param_vector, parts, structure, vanishes
from .rotations import label as rotation_label
from .rotations import rotation_symmetries
from .symbolic import make_symbols, simplify_small, sx_to_sympy, text, trig_normal
from ..model.records import record


MAX_PRINT_INSTRUCTIONS = 3000      # larger expressions are not converted to text


@record(frozen=False)
class FirstIntegral:
    """A conserved quantity.  ``expression`` (text) and ``verified`` are computed on first use
    (they call sympy); ``sx`` is ready at once (CasADi SX in eom.q, eom.qd, eom.t, eom.p)."""

    name: str
    kind: str                          # 'momentum' | 'angular_momentum' | 'jacobi' | 'energy'
    sx: object = field(repr=False)     # CasADi's text (p_0*qd_1*q_0) is no one's to read: see __repr__
    coordinate: str | None = None      # the cyclic coordinate (momentum of one coordinate)
    direction: dict | None = None      # coordinate weights of a combined momentum p . N
    rotation: dict | None = None       # angular momentum p . A q: {"x,y": a_yx} (A skew, A[y, x] = a)
    note: str = ""
    _text: object = field(default=None, repr=False)       # str or a callable producing it
    _verified: object = field(default=None, repr=False)   # 'symbolic' | 'numeric' or a callable

    def __repr__(self) -> str:
        """In the model's names (issue 23: the repr showed CasADi's p_0*qd_1*q_0)."""
        return f"FirstIntegral({self.name} = {self.expression} ({self.kind}: {self.note}))"

    __str__ = __repr__

    @property
    def expression(self) -> str:
        if callable(self._text):
            self._text = self._text()
        return self._text

    @property
    def verified(self) -> str:
        """'symbolic' (proved on the SX or by sympy) or 'numeric' (at random states only)."""
        if callable(self._verified):
            self._verified = self._verified()
        return self._verified

    def to_dict(self) -> dict:
        d = {"name": self.name, "kind": self.kind, "expression": self.expression, "verified": self.verified}
        if self.coordinate:
            d["coordinate"] = self.coordinate
        if self.direction:
            d["direction"] = self.direction
        if self.rotation:
            d["rotation"] = self.rotation
        if self.note:
            d["note"] = self.note
        return d


def first_integrals(eom, p=None) -> list[FirstIntegral]:
    """The conserved quantities this analysis can prove (for the given parameter values)."""
    eom = fold_inputs(eom)          # inputs held at their defaults: trailing parameters
    import casadi as ca

    pv = param_vector(eom, p)
    pt = parts(eom)
    n = eom.n
    st = structure(eom, pv)
    # enough states that the stacked rows (two or more per state) can have full rank n:
    # with fewer, every model would show spurious "symmetries"
    pr = Probe.states(n, count=max(N_PROBE, n + 4))
    G = ca.jacobian(eom.g, eom.q) if eom.m else ca.SX.zeros(0, n)
    gt = ca.jacobian(eom.g, eom.t) if eom.m else ca.SX.zeros(0, 1)
    f = ca.Function("fi_probe", pt.args, [ca.gradient(pt.L, eom.q), pt.Qtot, G, gt, pt.L])
    rows = []
    for vals in at_states(f, pr, pv):
        if all(np.all(np.isfinite(v)) for v in vals):
            rows.append(vals)
    out: list[FirstIntegral] = []
    if not rows:
        return out
    gscale = max(max(float(np.max(np.abs(r[0]), initial=0.0)) for r in rows),
                 max(float(np.max(np.abs(r[4]), initial=0.0)) for r in rows), 1e-300)
    qscale = max(max(float(np.max(np.abs(r[1]), initial=0.0)) for r in rows), gscale)
    Gscale = max((float(np.max(np.abs(r[2]), initial=0.0)) for r in rows), default=0.0) or 1.0

    # directions of invariance: rows dL/dq, Q and G stacked over the probe states
    stack = []
    for r in rows:
        stack.append(r[0].reshape(1, n) / gscale)
        stack.append(r[1].reshape(1, n) / qscale)
        if eom.m:
            stack.append(r[2] / Gscale)

    N = null_space(np.vstack(stack), rel=1e-9) if n else np.zeros((0, 0))
    dLdqd = ca.gradient(eom.T, eom.qd)     # V does not depend on the speeds
    texts = _Texts(eom)
    for col in N.T:
        axis = np.flatnonzero(np.abs(col) > 1e-9)
        if len(axis) == 1:
            k = int(axis[0])
            c = eom.coords[k]
            sym = (not ca.depends_on(pt.L, eom.q[k]) and _is_structural_zero(pt.Qtot[k])
                   and (not eom.m or _is_structural_zero(G[:, k])))
            dLk = ca.gradient(pt.L, eom.q)[k]
            verified = "symbolic" if sym else (lambda dLk=dLk, Qk=pt.Qtot[k]: _sympy_confirms(eom, dLk, Qk))
            sx = dLdqd[k]
            out.append(FirstIntegral(name=f"p_{c}", kind="momentum", sx=sx, coordinate=c,
                                     note=f"{c} is cyclic: dL/d{c} = 0 and no generalized force on {c}",
                                     _text=texts.of(sx), _verified=verified))
        else:
            w = col / np.max(np.abs(col))
            w = np.where(np.abs(w - np.round(w)) < 1e-9, np.round(w), w)
            sx = ca.dot(ca.SX(w.reshape(n, 1)), dLdqd)
            label = _combination(w, eom.coords)
            out.append(FirstIntegral(name=f"p_({label})", kind="momentum", sx=sx,
                                     direction={c: float(v) for c, v in zip(eom.coords, w) if v != 0},
                                     note=f"L and the forces are invariant under the translation "
                                          f"q -> q + s*({label}) (Noether)",
                                     _text=texts.of(sx), _verified="numeric"))

    for A in rotation_symmetries(eom, pt, pv):
        sx = ca.dot(dLdqd, ca.mtimes(ca.SX(A), eom.q))
        lab = rotation_label(A, eom.coords)
        out.append(FirstIntegral(name=f"L_({lab})", kind="angular_momentum", sx=sx,
                                 rotation={f"{eom.coords[i]},{eom.coords[j]}": float(A[j, i])
                                           for i in range(n) for j in range(i + 1, n) if A[j, i] != 0},
                                 note="L and the forces are invariant under the rotation of the coordinate "
                                      f"pair(s) ({lab}) about their origin (Noether): p . A q, for a pair "
                                      "(x, y) x p_y - y p_x",
                                 _text=texts.of(sx), _verified="numeric"))

    time_free_constraints = not eom.m or bool(vanishes([r[3] for r in rows], Gscale))
    if st.lagrangian_time_free and st.conservative and time_free_constraints and st.quadratic_T:
        verified = "symbolic" if _sym_time_free(eom, pt) else "numeric"
        if st.scleronomic:
            sx = eom.T + eom.V
            out.append(FirstIntegral(name="energy", kind="energy", sx=sx,
                                     note="Jacobi integral h = sum der(q) dL/d(der(q)) - L; equals the "
                                          "energy T + V (scleronomic)",
                                     _text=texts.of(sx), _verified=verified))
        else:
            sx = ca.dot(eom.qd, dLdqd) - pt.L
            what = " and ".join(x for x, y in (("T1 (terms linear in the speeds)", st.has_T1),
                                               ("T0 (terms without speeds)", st.has_T0)) if y)
            out.append(FirstIntegral(name="jacobi", kind="jacobi", sx=sx,
                                     note=f"Jacobi integral h = T2 - T0 + V; differs from the energy T + V "
                                          f"because T has {what or 'explicit time'} (moving frame)",
                                     _text=texts.of(sx), _verified=verified))
    return out


def integral_signals(eom, p=None) -> dict[str, object]:
    """{name: SX in (q, qd, t, p)} of every first integral, for recording during simulation."""
    return {fi.name: fi.sx for fi in first_integrals(eom, p)}


def describe_integrals(eom, p=None, expressions: bool = False) -> list[str]:
    """Lines for ``mech check`` / ``mech equations``: one per first integral (name, kind, why)."""
    eom = fold_inputs(eom)          # inputs held at their defaults: trailing parameters
    out = []
    for fi in first_integrals(eom, p):
        line = f"{fi.name} ({fi.kind}): {fi.note}"
        if expressions:
            line += f"\n      {fi.name} = {fi.expression}"
        out.append(line)
    return out


def _combination(w, coords) -> str:
    parts_ = []
    for v, c in zip(w, coords):
        if v == 0:
            continue
        mag = abs(v)
        coef = "" if mag == 1 else (f"{mag:g}*")
        sign = "-" if v < 0 else ("+" if parts_ else "")
        parts_.append(f"{sign}{coef}{c}")
    return "".join(parts_)


def _sym_time_free(eom, pt) -> bool:
    import casadi as ca

    return (not ca.depends_on(pt.L, eom.t) and _is_structural_zero(pt.Qtot))


def _sympy_confirms(eom, dL, Qk) -> str:
    """'symbolic' when dL/dq_k and Q_k reduce to 0 as trig polynomials (sympy), else 'numeric'."""
    import casadi as ca


    f = ca.Function("chk", [eom.q, eom.qd, eom.t, eom.p], [dL, Qk])
    if f.n_instructions() > MAX_PRINT_INSTRUCTIONS:
        return "numeric"
    q, qd, t, p = make_symbols(eom.coords, eom.params)
    a, b = sx_to_sympy([dL, Qk], [eom.q, eom.qd, eom.t, eom.p], [q, qd, [t], p])
    try:
        if trig_normal(a[0, 0], q) == 0 and trig_normal(b[0, 0], q) == 0:
            return "symbolic"
    except Exception:  # sympy could not decide: the numeric check stands
        pass
    return "numeric"


class _Texts:
    """Readable text of SX expressions in the model's names (sympy), made on demand."""

    def __init__(self, eom):
        self.eom = eom
        self.syms = None

    def of(self, sx):
        return lambda: self._text(sx)

    def _text(self, sx) -> str:
        import casadi as ca


        eom = self.eom
        f = ca.Function("txt", [eom.q, eom.qd, eom.t, eom.p], [sx])
        if f.n_instructions() > MAX_PRINT_INSTRUCTIONS:
            return f"(expression with {f.n_instructions()} operations, not printed)"
        if self.syms is None:
            self.syms = make_symbols(eom.coords, eom.params)
        q, qd, t, p = self.syms
        (e,) = sx_to_sympy([sx], [eom.q, eom.qd, eom.t, eom.p], [q, qd, [t], p])
        return text(simplify_small(e[0, 0], q))
