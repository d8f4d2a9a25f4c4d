"""The articulated-body algorithm as loops over per-link kernels (issue 16).

The unrolled forward dynamics (``dynamics.aba``) is one SX expression whose generated C grows
linearly with the number of links, and gcc's time faster than linearly (45 s for a 200-link
chain).  Here the same algorithm is cut into per-link *kernels*, one SX Function per pass
(forward: kinematics and bias forces; backward: articulated inertias; forward: accelerations),
and a run of structurally identical links is chained with ``Function.mapaccum``: the C code
then holds each kernel once and calls it in a hierarchy of loops (CasADi nests ``mapaccum``
in base 10), so it grows with log N instead of N.

Identical links: for every link the local inputs of its step (joint transform, motion
subspace, free speeds, prescribed motion, inertia, external force, joint force) are SX in the
model's symbols (q, qd, t, u, p) and, for the external force, in placeholders of the link's
own pose and velocity.  The symbols it reads become the link's *data* (in the order the
expression graph meets them) and are replaced by generic ones; two links are identical when
the resulting local Functions serialize to the same bytes.  So per-link parameter values
(``link[i].m``) are data, while a different joint axis, body shape or a force that reaches
other links (a spring to another body) makes a link different.  A link whose external force
depends on another link's pose is still exact: that pose enters through the model's symbols.

Structural zeros are kept: the carry between links (pose, velocities; articulated inertia and
bias force; accelerations) is a sparse vector whose pattern is the fixpoint of the kernel's
own output pattern, so a planar chain loops over planar kernels.

``plan`` returns None when the looped form would not pay (no run of ``LOOP_MIN`` links) or
does not apply; callers then use the unrolled expression.  ``ChainPlan.ode(eom)`` assembles
the MX Function ``(t, x, u, p) -> xdot`` (or None when the EOM's fields are no longer the
ones the plan was made for).
"""
from __future__ import annotations

from dataclasses import dataclass

import casadi as ca

from . import templates as tpl
from .tree import Tree, z3

LOOP_MIN = 4          # links in a run below which nothing is looped
_NPOSE = 18           # carry of pass 1: vec(R), o, w, v
_NART = 33            # carry of pass 2: vec(A), vec(B), vec(C), pn, pf
_NACC = 6             # carry of pass 3: aw, av
_BASE = {"base": 4}   # mapaccum nests loops of 4 calls: the smallest C measured (2, 4, 10 tried)


class _Placeholders:
    """A Kinematics stand-in whose link poses and velocities are free symbols."""

    def __init__(self, n: int):
        self.R = [ca.SX.sym(f"R{i}", 3, 3) for i in range(n)]
        self.o = [ca.SX.sym(f"o{i}", 3) for i in range(n)]
        self.w = [ca.SX.sym(f"w{i}", 3) for i in range(n)]
        self.v = [ca.SX.sym(f"v{i}", 3) for i in range(n)]

    def flat(self, i: int) -> ca.SX:
        return ca.vertcat(ca.vec(self.R[i]), self.o[i], self.w[i], self.v[i])


_PH = ca.SX.sym("ph", _NPOSE)      # generic pose placeholder of the kernels


@dataclass
class _Form:
    """One link's step in generic symbols: loc(xi) and f(xi, ph), its data and fingerprint."""

    k: int
    data: list                       # the model's SX symbols, in the order of xi
    xi: ca.SX
    loc: ca.Function                 # xi -> (E, r, Sw, Sv, nu, jw0, jv0, aw0, av0, A, B, C, tau)
    force: ca.Function               # (xi, ph) -> (fn, ff)
    key: tuple


def _form(lk, nu, tau, fext, ph: _Placeholders) -> _Form:
    I = lk.I
    loc = [lk.E, lk.r, lk.S_w, lk.S_v, nu, lk.known_vw, lk.known_vv, lk.known_aw, lk.known_av, I.A, I.B, I.C, tau]
    loc = [ca.SX(x) for x in loc]
    f = [ca.SX(x) for x in fext.get(lk.index, (z3(), z3()))]
    phi = ph.flat(lk.index)
    own = {phi[j].element_hash() for j in range(_NPOSE)}
    syms = ca.symvar(ca.veccat(*loc, *f))
    data = [s for s in syms if s.element_hash() not in own]
    xi = ca.SX.sym("xi", len(data))
    dv = ca.vertcat(*data) if data else ca.SX(0, 1)
    gen = ca.substitute(loc + f, [dv, phi], [xi, _PH])
    loc_f = ca.Function("loc", [xi], gen[:len(loc)])
    force_f = ca.Function("force", [xi, _PH], gen[len(loc):])
    key = (lk.k, loc_f.serialize(), force_f.serialize())
    return _Form(lk.k, data, xi, loc_f, force_f, key)


def _rows(x: ca.SX) -> tuple:
    """The entries of a column that are not structurally zero."""
    x = ca.densify(x)
    return tuple(r for r in range(x.numel()) if not x[r].is_zero())


def _packed(name: str, rows: tuple, size: int):
    """A symbol holding only the entries ``rows`` of a column of ``size``: (symbol, full column)."""
    c = ca.SX.sym(name, len(rows))
    full = [ca.SX(0)] * size
    for j, r in enumerate(rows):
        full[r] = c[j]
    return c, ca.vertcat(*full) if size else ca.SX(0, 1)


def _pack(x: ca.SX, rows: tuple) -> ca.SX:
    x = ca.densify(x)
    return ca.vertcat(*[x[r] for r in rows]) if rows else ca.SX(0, 1)


def _repack(a: tuple, b: tuple, size: int) -> ca.Function:
    """Packed with rows a -> packed with rows b (a subset of b)."""
    c, full = _packed("c", a, size)
    return ca.Function("repack", [c], [_pack(full, b)])


class _Kernels:
    """The three pass kernels of one class of links.  Carries and the values handed from one
    pass to the next are *packed*: only their structurally nonzero entries travel."""

    def __init__(self, form: _Form):
        self.form = form
        self.k = form.k

    def _locals(self):
        return self.form.loc(self.form.xi)

    # pass 1: (pose carry, xi) -> (pose carry, y1 = (pn, pf, cw, cv))
    def pass1(self, rows):
        c, cd = _packed("c", rows, _NPOSE)
        Rl, ol, wl, vl = ca.reshape(cd[0:9], 3, 3), cd[9:12], cd[12:15], cd[15:18]
        E, r, Sw, Sv, nu, jw0, jv0, aw0, av0, A, B, C, _ = self._locals()
        R, o, w, v, jw, jv = tpl.kin_step(self.k, False)(E, r, Rl, ol, wl, vl, Sw, Sv, nu, jw0, jv0)
        fn, ff = self.form.force(self.form.xi, ca.vertcat(ca.vec(R), o, w, v))
        pn, pf, cw, cv = tpl.aba_p1()(w, v, A, B, C, fn, ff, jw, jv, aw0, av0)
        return c, [], ca.vertcat(ca.vec(R), o, w, v), [ca.vertcat(pn, pf, cw, cv)]

    # pass 2: (articulated carry, xi, y1) -> (articulated carry, y2 = (Uw, Uv, Di, u))
    def pass2(self, rows, rows_y1):
        c, cd = _packed("c", rows, _NART)
        y1s, y1 = _packed("y1", rows_y1, 12)
        Ac, Bc, Cc = ca.reshape(cd[0:9], 3, 3), ca.reshape(cd[9:18], 3, 3), ca.reshape(cd[18:27], 3, 3)
        E, r, Sw, Sv, _, _, _, _, _, A, B, C, tau = self._locals()
        out = tpl.aba_p2(self.k)(A + Ac, B + Bc, C + Cc, y1[0:3] + cd[27:30], y1[3:6] + cd[30:33], y1[6:9],
                                 y1[9:12], Sw, Sv, tau, E, r)
        Ap, Bp, Cp, ppn, ppf, Uw, Uv, Di, u = out
        y2 = ca.vertcat(ca.vec(Uw), ca.vec(Uv), ca.vec(Di), u)
        return c, [y1s], ca.vertcat(ca.vec(Ap), ca.vec(Bp), ca.vec(Cp), ppn, ppf), [y2]

    # pass 3: (acceleration carry, xi, y1, y2) -> (acceleration carry, nu')
    def pass3(self, rows, rows_y1, rows_y2):
        k = self.k
        c, cd = _packed("c", rows, _NACC)
        y1s, y1 = _packed("y1", rows_y1, 12)
        y2s, y2 = _packed("y2", rows_y2, 7 * k + k * k)
        E, r, Sw, Sv, *_ = self._locals()
        Uw, Uv = ca.reshape(y2[0:3 * k], 3, k), ca.reshape(y2[3 * k:6 * k], 3, k)
        Di, u = ca.reshape(y2[6 * k:6 * k + k * k], k, k), y2[6 * k + k * k:]
        nd, aw, av = tpl.aba_p3(k, False)(E, r, cd[0:3], cd[3:6], y1[6:9], y1[9:12], Uw, Uv, Di, u, Sw, Sv)
        return c, [y1s, y2s], ca.vertcat(aw, av), [nd]


def _settle(build, rows_in: tuple, xi, name: str, dense_extra=False):
    """The kernel whose carry pattern is the fixpoint containing rows_in.

    build(rows) -> (carry symbol, other inputs, carry out, other outputs); returns
    (Function (carry, xi, *other inputs) -> (carry, *other outputs), carry rows, rows of the
    other outputs).  The other outputs are packed too unless dense_extra."""
    rows = tuple(rows_in)
    while True:
        c, ins, carry, extra = build(rows)
        out = _rows(carry)
        if set(out) <= set(rows):
            break
        rows = tuple(sorted(set(rows) | set(out)))
    extra_rows = [tuple(range(e.numel())) if dense_extra else _rows(e) for e in extra]
    outs = [_pack(carry, rows)] + [_pack(e, r) for e, r in zip(extra, extra_rows)]
    return ca.Function(name, [c, xi, *ins], outs), rows, extra_rows


@dataclass
class _Segment:
    links: list                      # consecutive link indices, each the parent of the next
    kern: _Kernels
    data: list                       # per link: the model's symbols in the kernel's order
    f1: ca.Function | None = None
    f2: ca.Function | None = None
    f3: ca.Function | None = None

    @property
    def top(self):
        return self.links[0]

    @property
    def bottom(self):
        return self.links[-1]


_WORLD = (0, 4, 8)         # the world's pose carry: R = 1 (packed: its diagonal), o = w = v = 0


class ChainPlan:
    """Segments of the link tree with their kernels; ``ode(eom)`` assembles the looped form."""

    def __init__(self, tree: Tree, segments: list, qdd, post):
        self.tree = tree
        self.segments = segments
        self.qdd = qdd
        self.post = post                 # (nud symbol, q'' in it), or None for the identity
        self.parent = {lk.index: lk.parent for lk in tree.links}
        self._kernels()

    @property
    def longest(self) -> int:
        return max(len(s.links) for s in self.segments)

    def _kernels(self):
        """Each segment's three kernels, the carry patterns settled pass by pass in the order
        the values flow (a parent's pattern is part of its children's)."""
        out1, out2, out3 = {}, {}, {}
        for s in self.segments:                              # pass 1, top-down
            lam = self.parent[s.top]
            s.in1 = out1[lam] if lam >= 0 else _WORLD
            s.f1, out1[s.bottom], (s.y1,) = _settle(s.kern.pass1, s.in1, s.kern.form.xi, "aba_fwd")
            s.c1 = out1[s.bottom]
        for s in reversed(self.segments):                    # pass 2, bottom-up
            s.in2 = tuple(sorted(set().union(*out2.pop(s.bottom, [()]))))
            s.f2, c2, (s.y2,) = _settle(lambda r, s=s: s.kern.pass2(r, s.y1), s.in2, s.kern.form.xi, "aba_bwd")
            s.c2 = c2
            lam = self.parent[s.top]
            if lam >= 0:
                out2.setdefault(lam, []).append(c2)
        for s in self.segments:                              # pass 3, top-down
            lam = self.parent[s.top]
            s.in3 = out3[lam] if lam >= 0 else ()
            s.f3, out3[s.bottom], _ = _settle(lambda r, s=s: s.kern.pass3(r, s.y1, s.y2), s.in3, s.kern.form.xi,
                                              "aba_acc", dense_extra=True)
            s.c3 = out3[s.bottom]

    def ode(self, eom) -> ca.Function | None:
        """(t, x, u, p) -> xdot with the loops, or None if ``eom`` is not what the plan was made for."""
        if eom.__dict__.get("qdd") is not self.qdd:
            return None
        n = eom.n
        sx_all = [eom.t, eom.q, eom.qd, eom.u_sym, eom.p]
        index = {}
        pos = 0
        for v in sx_all:
            for j in range(v.numel()):
                index[v[j].element_hash()] = pos + j
            pos += v.numel()
        t = ca.MX.sym("t")
        x = ca.MX.sym("x", 2 * n)
        u = ca.MX.sym("u", eom.u_sym.numel())
        p = ca.MX.sym("p", eom.p.numel())
        xall = ca.vertcat(t, x, u, p)
        try:
            nud = self._nud(xall, index)
        except KeyError:           # a data symbol that is not one of the EOM's inputs
            return None
        if self.post is None:
            qdd = nud
        else:
            sym, expr = self.post
            try:
                post = ca.Function("post", [ca.vertcat(*sx_all), sym], [expr])
            except RuntimeError:
                return None
            qdd = post(xall, nud)
        return ca.Function("ode", [t, x, u, p], [ca.vertcat(x[n:], qdd)], ["t", "x", "u", "p"], ["xdot"])

    @staticmethod
    def _data(xall, index, seg):
        """The data of a segment as an m x n MX matrix (one column per link), gathered row by
        row: a symbol shared by every link is repeated, a run of consecutive inputs is a slice;
        only other rows need an index table (so the C size does not grow with n)."""
        n, m = len(seg.links), len(seg.data[0])
        if m == 0:
            return ca.MX(0, n)
        cols = []
        for j in range(m):
            idx = [index[col[j].element_hash()] for col in seg.data]
            if all(i == idx[0] for i in idx):
                cols.append(ca.repmat(xall[idx[0]], n, 1))
            elif idx == list(range(idx[0], idx[0] + n)):
                cols.append(xall[idx[0]:idx[0] + n])
            else:
                cols.append(xall[idx])
        return ca.horzcat(*cols).T

    @staticmethod
    def _flip(n):
        """The n x n exchange matrix: X @ J reverses the columns of X."""
        return ca.DM(ca.Sparsity.triplet(n, n, list(range(n)), list(reversed(range(n)))), 1.0)

    def _nud(self, xall, index):
        segs = self.segments
        seg_of = {s.bottom: s for s in segs}
        data, y1, y2, pose, acc, art = {}, {}, {}, {}, {}, {}

        def carry(val, rows, want, size):      # a packed carry into a kernel's (larger) pattern
            return val if rows == want else _repack(rows, want, size)(val)

        for s in segs:                                   # pass 1, top-down
            lam = self.parent[s.top]
            if lam >= 0:
                cin = carry(pose[lam], seg_of[lam].c1, s.c1, _NPOSE)
            else:
                cin = carry(ca.MX(ca.DM.ones(len(_WORLD), 1)), _WORLD, s.c1, _NPOSE)
            nl = len(s.links)
            data[id(s)] = D = self._data(xall, index, s)
            C, y1[id(s)] = _loop(s.f1, nl)(cin, D)
            pose[s.bottom] = C[:, nl - 1]
        for s in reversed(segs):                         # pass 2, bottom-up: columns reversed
            nl = len(s.links)
            cin = ca.MX.zeros(len(s.c2), 1)
            for val, rows in art.pop(s.bottom, []):
                cin = cin + carry(val, rows, s.c2, _NART)
            if nl > 1:
                J = self._flip(nl)
                C, Y = _loop(s.f2, nl)(cin, ca.mtimes(data[id(s)], J), ca.mtimes(y1[id(s)], J))
                y2[id(s)] = ca.mtimes(Y, J)
            else:
                C, y2[id(s)] = s.f2(cin, data[id(s)], y1[id(s)])
            lam = self.parent[s.top]
            if lam >= 0:
                art.setdefault(lam, []).append((C[:, nl - 1], s.c2))
        parts = []
        for s in segs:                                   # pass 3, top-down
            lam = self.parent[s.top]
            cin = carry(acc[lam], seg_of[lam].c3, s.c3, _NACC) if lam >= 0 else ca.MX.zeros(len(s.c3), 1)
            nl = len(s.links)
            C, Y = _loop(s.f3, nl)(cin, data[id(s)], y1[id(s)], y2[id(s)])
            acc[s.bottom] = C[:, nl - 1]
            if s.kern.k:
                parts.append(ca.vec(Y))
        return ca.vertcat(*parts) if parts else ca.MX(0, 1)


def _loop(f: ca.Function, n: int) -> ca.Function:
    """f applied n times, its first output fed back as its first input (C: nested loops)."""
    return f.mapaccum(f.name() + "_loop", n, 1, _BASE)


def plan(tree: Tree, fext_of, tau, qdd, qdd_of) -> ChainPlan | None:
    """The looped form of the ABA over ``tree``, or None when no run of LOOP_MIN identical links.

    fext_of(kin) -> {link: (n, f)}: the external forces on a kinematics object; tau: the joint
    forces (SX, one per speed); qdd: the unrolled q'' the plan reproduces; qdd_of(nud) -> q''."""
    links = tree.links
    if len(links) < LOOP_MIN:
        return None
    order = [d for lk in links for d in lk.dofs]
    if order != list(range(len(tree.dofs))):
        return None
    ph = _Placeholders(len(links))
    fext = fext_of(ph)
    nu = [d.nu for d in tree.dofs]
    forms = []
    for lk in links:
        nul = ca.vertcat(*[nu[k] for k in lk.dofs]) if lk.dofs else ca.SX(0, 1)
        taul = ca.vertcat(*[tau[k] for k in lk.dofs]) if lk.dofs else ca.SX(0, 1)
        forms.append(_form(lk, nul, taul, fext, ph))
    children = tree.children()
    segments: list[_Segment] = []
    kernels: dict = {}
    for lk, fm in zip(links, forms):
        s = segments[-1] if segments else None
        if (s is not None and lk.parent == s.bottom and len(children[s.bottom]) == 1
                and forms[s.bottom].key == fm.key):
            s.links.append(lk.index)
            s.data.append(fm.data)
            continue
        kern = kernels.setdefault(fm.key, _Kernels(fm))
        segments.append(_Segment([lk.index], kern, [fm.data]))
    if max(len(s.links) for s in segments) < LOOP_MIN:
        return None
    nud = ca.SX.sym("nud", len(tree.dofs))
    expr = qdd_of(nud)
    post = None if _same(expr, nud) else (nud, expr)
    return ChainPlan(tree, segments, qdd, post)


def _same(a, b) -> bool:
    return a.shape == b.shape and all(ca.is_equal(a[i], b[i]) for i in range(a.numel()))
