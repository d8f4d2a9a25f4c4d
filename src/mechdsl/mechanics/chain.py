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
GROUP = 8             # links per inlined kernel call (4: 1.2x the instructions, 16: 1.5x the C)
_BASE = {"base": 8}   # mapaccum nests loops of 8 calls (base 4: smaller C, slower; 16: larger C)


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


class _Layout:
    """Which entries of a column of ``size`` travel: zero entries and constant entries do not
    (the receiving kernel knows them), only the others ("rows") are packed."""

    def __init__(self, size: int, rows=(), consts=()):
        self.size = size
        self.rows = tuple(rows)
        self.consts = tuple(consts)          # (row, value)

    @staticmethod
    def of(x: ca.SX) -> "_Layout":
        x = ca.densify(x)
        rows, consts = [], []
        for r in range(x.numel()):
            e = x[r]
            if e.is_zero():
                continue
            if e.is_constant():
                consts.append((r, float(e)))
            else:
                rows.append(r)
        return _Layout(x.numel(), rows, consts)

    def _state(self):
        st = dict(self.consts)
        st.update({r: None for r in self.rows})       # None: not a constant
        return st

    def join(self, o: "_Layout") -> "_Layout":
        """The layout holding both: an entry stays constant only where both have that constant."""
        a, b = self._state(), o._state()
        rows, consts = [], []
        for r in sorted(set(a) | set(b)):
            if r in a and r in b and a[r] is not None and a[r] == b[r]:
                consts.append((r, a[r]))
            else:
                rows.append(r)
        return _Layout(self.size, rows, consts)

    def __eq__(self, o):
        return (self.size, self.rows, self.consts) == (o.size, o.rows, o.consts)

    def __hash__(self):
        return hash((self.size, self.rows, self.consts))

    def symbol(self, name: str):
        """(packed symbol, the full column with zeros and constants in place)."""
        c = ca.SX.sym(name, len(self.rows))
        full = [ca.SX(0)] * self.size
        for r, v in self.consts:
            full[r] = ca.SX(v)
        for j, r in enumerate(self.rows):
            full[r] = c[j]
        return c, (ca.vertcat(*full) if self.size else ca.SX(0, 1))

    def pack(self, x: ca.SX) -> ca.SX:
        x = ca.densify(x)
        return ca.vertcat(*[x[r] for r in self.rows]) if self.rows else ca.SX(0, 1)


def _repack(a: _Layout, b: _Layout) -> ca.Function:
    """Packed in layout a -> packed in layout b (b holds a)."""
    c, full = a.symbol("c")
    return ca.Function("repack", [c], [b.pack(full)])


class _Kernels:
    """The three pass kernels of one class of links.  Carries and the values handed from one
    pass to the next travel packed (``_Layout``); the joint transform E is computed once, in
    pass 1, and handed on (it holds the trigonometry of a revolute joint)."""

    def __init__(self, form: _Form):
        self.form = form
        self.k = form.k

    def _locals(self):
        return self.form.loc(self.form.xi)

    # pass 1: (pose carry, xi) -> (pose carry, y1 = (pn, pf, cw, cv, vec(E)))
    def pass1(self, lay):
        c, cd = lay.symbol("c")
        Rl, ol, wl, vl = ca.reshape(cd[0:9], 3, 3), cd[9:12], cd[12:15], cd[15:18]
        E, r, Sw, Sv, nu, jw0, jv0, aw0, av0, A, B, C, _ = self._locals()
        R, o, w, v, jw, jv = tpl.kin_step(self.k, False)(E, r, Rl, ol, wl, vl, Sw, Sv, nu, jw0, jv0)
        fn, ff = self.form.force(self.form.xi, ca.vertcat(ca.vec(R), o, w, v))
        pn, pf, cw, cv = tpl.aba_p1()(w, v, A, B, C, fn, ff, jw, jv, aw0, av0)
        return c, [], ca.vertcat(ca.vec(R), o, w, v), [ca.vertcat(pn, pf, cw, cv, ca.vec(E))]

    def _y1(self, lay):
        y1s, y1 = lay.symbol("y1")
        return y1s, y1[0:3], y1[3:6], y1[6:9], y1[9:12], ca.reshape(y1[12:21], 3, 3)

    # pass 2: (articulated carry, xi, y1) -> (articulated carry, y2 = (Uw, Uv, Di, u))
    def pass2(self, lay, lay_y1):
        c, cd = lay.symbol("c")
        y1s, pn, pf, cw, cv, E = self._y1(lay_y1)
        Ac, Bc, Cc = ca.reshape(cd[0:9], 3, 3), ca.reshape(cd[9:18], 3, 3), ca.reshape(cd[18:27], 3, 3)
        _, r, Sw, Sv, _, _, _, _, _, A, B, C, tau = self._locals()
        out = tpl.aba_p2(self.k)(A + Ac, B + Bc, C + Cc, pn + cd[27:30], pf + cd[30:33], cw, cv, Sw, Sv, tau, E, r)
        Ap, Bp, Cp, ppn, ppf, Uw, Uv, Di, u = out
        y2 = ca.vertcat(ca.vec(Uw), ca.vec(Uv), ca.vec(Di), u)
        return c, [y1s], ca.vertcat(ca.vec(Ap), ca.vec(Bp), ca.vec(Cp), ppn, ppf), [y2]

    # pass 3: (acceleration carry, xi, y1, y2) -> (acceleration carry, nu')
    def pass3(self, lay, lay_y1, lay_y2):
        k = self.k
        c, cd = lay.symbol("c")
        y1s, _, _, cw, cv, E = self._y1(lay_y1)
        y2s, y2 = lay_y2.symbol("y2")
        _, r, Sw, Sv, *_ = self._locals()
        Uw, Uv = ca.reshape(y2[0:3 * k], 3, k), ca.reshape(y2[3 * k:6 * k], 3, k)
        Di, u = ca.reshape(y2[6 * k:6 * k + k * k], k, k), y2[6 * k + k * k:]
        nd, aw, av = tpl.aba_p3(k, False)(E, r, cd[0:3], cd[3:6], cw, cv, Uw, Uv, Di, u, Sw, Sv)
        return c, [y1s, y2s], ca.vertcat(aw, av), [nd]


@dataclass
class _Kernel:
    """A settled kernel: (carry, xi_j for j in ``used``, *others) -> (carry, *others)."""

    f: ca.Function
    carry: _Layout                   # of its carry (in and out)
    extra: list                      # layouts of its other outputs
    used: list                       # the data rows it reads


def _settle(build, lay_in: _Layout, xi, name: str, dense_extra=False) -> _Kernel:
    """The kernel whose carry layout is the fixpoint holding lay_in.

    build(layout) -> (carry symbol, other inputs, carry out, other outputs).  Only the data
    rows the kernel reads become inputs; the other outputs are packed unless dense_extra."""
    lay = lay_in
    while True:
        c, ins, carry, extra = build(lay)
        nxt = lay.join(_Layout.of(carry))
        if nxt == lay:
            break
        lay = nxt
    if dense_extra:
        extra_lay = [_Layout(e.numel(), range(e.numel())) for e in extra]
    else:
        extra_lay = [_Layout.of(e) for e in extra]
    outs = [lay.pack(carry)] + [el.pack(e) for el, e in zip(extra_lay, extra)]
    allout = ca.veccat(*outs)
    used = [j for j in range(xi.numel()) if ca.depends_on(allout, xi[j])]
    f = ca.Function(name, [c, *[xi[j] for j in used], *ins], outs)
    return _Kernel(f, lay, extra_lay, used)


@dataclass
class _Segment:
    links: list                      # consecutive link indices, each the parent of the next
    kern: _Kernels
    data: list                       # per link: the model's symbols in the kernel's order
    k1: _Kernel | None = None
    k2: _Kernel | None = None
    k3: _Kernel | None = None

    @property
    def top(self):
        return self.links[0]

    @property
    def bottom(self):
        return self.links[-1]


_WORLD = _Layout(_NPOSE, (), ((0, 1.0), (4, 1.0), (8, 1.0)))   # R = 1, o = w = v = 0


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
        """Each segment's three kernels, the carry layouts settled pass by pass in the order
        the values flow (a parent's layout is held by its children's)."""
        out1, out2, out3 = {}, {}, {}
        for s in self.segments:                              # pass 1, top-down
            lam = self.parent[s.top]
            xi = s.kern.form.xi
            s.k1 = _settle(s.kern.pass1, out1[lam] if lam >= 0 else _WORLD, xi, "aba_fwd")
            out1[s.bottom] = s.k1.carry
        for s in reversed(self.segments):                    # pass 2, bottom-up
            lay = _Layout(_NART)
            for c in out2.pop(s.bottom, []):
                lay = lay.join(c)
            s.k2 = _settle(lambda la, s=s: s.kern.pass2(la, s.k1.extra[0]), lay, s.kern.form.xi, "aba_bwd")
            lam = self.parent[s.top]
            if lam >= 0:
                out2.setdefault(lam, []).append(s.k2.carry)
        for s in self.segments:                              # pass 3, top-down
            lam = self.parent[s.top]
            s.k3 = _settle(lambda la, s=s: s.kern.pass3(la, s.k1.extra[0], s.k2.extra[0]),
                           out3[lam] if lam >= 0 else _Layout(_NACC), s.kern.form.xi, "aba_acc", dense_extra=True)
            out3[s.bottom] = s.k3.carry

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
    def _indices(index, seg, used, reverse=False):
        """Per data row in ``used``: the positions in (t, x, u, p) of its value for each link."""
        out = []
        for j in used:
            idx = [index[col[j].element_hash()] for col in seg.data]
            out.append(idx[::-1] if reverse else idx)
        return out

    def _nud(self, xall, index):
        """Three passes over the segments.  Values handed from pass to pass are flat vectors,
        link by link in the order the pass produced them (pass 2 runs bottom-up)."""
        segs = self.segments
        seg_of = {s.bottom: s for s in segs}
        y1, y2, pose, acc, art = {}, {}, {}, {}, {}

        def into(val, have: _Layout, want: _Layout):
            return val if have == want else _repack(have, want)(val)

        for s in segs:                                   # pass 1, top-down
            lam = self.parent[s.top]
            if lam >= 0:
                cin = into(pose[lam], seg_of[lam].k1.carry, s.k1.carry)
            else:
                cin = into(ca.MX(0, 1), _WORLD, s.k1.carry)
            pose[s.bottom], (y1[id(s)],) = _run(s.k1, len(s.links), cin, xall,
                                                self._indices(index, s, s.k1.used), [])
        for s in reversed(segs):                         # pass 2, bottom-up
            cin = ca.MX.zeros(len(s.k2.carry.rows), 1)
            for val, lay in art.pop(s.bottom, []):
                cin = cin + into(val, lay, s.k2.carry)
            top, (y2[id(s)],) = _run(s.k2, len(s.links), cin, xall, self._indices(index, s, s.k2.used, reverse=True),
                                     [(y1[id(s)], True)])
            lam = self.parent[s.top]
            if lam >= 0:
                art.setdefault(lam, []).append((top, s.k2.carry))
        parts = []
        for s in segs:                                   # pass 3, top-down
            lam = self.parent[s.top]
            if lam >= 0:
                cin = into(acc[lam], seg_of[lam].k3.carry, s.k3.carry)
            else:
                cin = into(ca.MX(0, 1), _Layout(_NACC), s.k3.carry)
            acc[s.bottom], (nd,) = _run(s.k3, len(s.links), cin, xall, self._indices(index, s, s.k3.used),
                                        [(y1[id(s)], False), (y2[id(s)], True)])
            if s.kern.k:
                parts.append(nd)
        return ca.vertcat(*parts) if parts else ca.MX(0, 1)


def _row(xall, idx: list):
    """The values xall[idx] as a 1 x len(idx) row: repeated, a (strided) slice, or a gather."""
    n = len(idx)
    if all(i == idx[0] for i in idx):
        return ca.repmat(xall[idx[0]], 1, n)
    step = idx[1] - idx[0] if n > 1 else 1
    if step > 0 and idx == list(range(idx[0], idx[0] + step * n, step)):
        return ca.reshape(xall[idx[0]:idx[0] + step * (n - 1) + 1:step], 1, n)
    return ca.reshape(xall[idx], 1, n)


def _stepper(k: _Kernel, U: int, shared: tuple) -> ca.Function:
    """U consecutive steps of kernel k as one SX Function (inlined: one call per U links).

    The data rows at positions ``shared`` (of k.used) hold one value for every link: they ride
    in the carry (passed through unchanged) instead of being repeated per link.  Signature:
    (carry + shared, varying rows per step ..., other inputs stacked) -> (carry + shared,
    other outputs stacked)."""
    f = k.f
    nd = len(k.used)
    c = ca.SX.sym("c", f.size1_in(0))
    sh = ca.SX.sym("s", len(shared))
    data = [[sh[shared.index(j)] if j in shared else ca.SX.sym(f"d{u}_{j}") for j in range(nd)] for u in range(U)]
    varying = [data[u][j] for u in range(U) for j in range(nd) if j not in shared]
    ins = [ca.SX.sym(f"i{i}", U * f.size1_in(1 + nd + i)) for i in range(f.n_in() - 1 - nd)]
    outs = [[] for _ in range(f.n_out() - 1)]
    cur = c
    for u in range(U):
        args = [cur, *data[u]]
        for i, x in enumerate(ins):
            m = f.size1_in(1 + nd + i)
            args.append(x[u * m:(u + 1) * m])
        res = f(*args)
        cur = res[0]
        for o, r in zip(outs, res[1:]):
            o.append(r)
    return ca.Function(f"{f.name()}_x{U}", [ca.vertcat(c, sh), *varying, *ins],
                       [ca.vertcat(cur, sh), *[ca.vertcat(*o) for o in outs]])


def _loop(f: ca.Function, n: int) -> ca.Function:
    """f applied n times, its first output fed back as its first input (C: nested loops)."""
    return f.mapaccum(f.name() + "_loop", n, 1, _BASE) if n > 1 else f


def _steps(flat, m: int, n: int, lo: int, hi: int, U: int, reverse: bool):
    """Steps lo..hi-1 of a flat link-by-link vector of n links (m values each; step s is link
    n-1-s when reverse) as the matrix a loop maps over: (U m) x ((hi - lo) / U)."""
    if m == 0:
        return ca.MX(0, (hi - lo) // U)
    if not reverse:
        block = flat[lo * m:hi * m]
    else:
        block = flat[[(n - 1 - s) * m + r for s in range(lo, hi) for r in range(m)]]
    return ca.reshape(block, U * m, (hi - lo) // U)


def _run(k: _Kernel, n: int, cin, xall, rows: list, ys: list):
    """Kernel k over a sequence of n links, from carry cin: (last carry, [outputs flat, step by
    step]).  rows: per data row of k, its index into xall for every step; ys: per other input,
    (flat vector of a pass's outputs, whether its steps run in reverse to this one's).  Groups
    of GROUP links run as one inlined call in a loop, the remaining n mod GROUP one by one."""
    f = k.f
    nd = len(k.used)
    sizes = [f.size1_in(1 + nd + i) for i in range(len(ys))]
    shared = tuple(j for j, idx in enumerate(rows) if all(i == idx[0] for i in idx))
    vary = [idx for j, idx in enumerate(rows) if j not in shared]
    nc = f.size1_in(0)
    carry = ca.vertcat(cin, *[xall[rows[j][0]] for j in shared])
    U = GROUP if n >= 2 * GROUP else 1
    G = n // U
    outs = []
    spans = [(0, G * U, U)] if U > 1 else []
    if n - G * U or U == 1:
        spans.append((G * U if U > 1 else 0, n, 1))
    for lo, hi, u_ in spans:
        cnt = (hi - lo) // u_
        args = [carry]
        for u in range(u_):
            args += [_row(xall, idx[lo + u:hi:u_]) for idx in vary]
        args += [_steps(y, m, n, lo, hi, u_, rev) for (y, rev), m in zip(ys, sizes)]
        res = _loop(_stepper(k, u_, shared), cnt)(*args)
        carry = res[0][:, cnt - 1]
        outs.append([ca.vec(Y) for Y in res[1:]])
    return carry[:nc], [ca.vertcat(*parts) for parts in zip(*outs)]


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
