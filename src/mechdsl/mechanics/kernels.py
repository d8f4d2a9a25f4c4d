"""Per-link kernels of the looped articulated-body algorithm (see chain.py): the three pass
kernels of a class of identical links, their packed layouts, and the loops that run them.

A kernel is an SX Function (carry, data rows ..., other inputs) -> (carry, other outputs); the
carry is fed back from link to link.  ``run`` applies it along a sequence of links as
``Function.mapaccum`` over groups of GROUP links (one inlined call each) and the remaining
links one by one; pass-to-pass values are flat vectors, link by link.
"""
from __future__ import annotations


import casadi as ca

from . import templates as tpl
from ..model.records import record

NPOSE = 18           # carry of pass 1: vec(R), o, w, v
NART = 33            # carry of pass 2: vec(A), vec(B), vec(C), pn, pf
NACC = 6             # carry of pass 3: aw, av
GROUP = 8             # links per inlined kernel call (4: 1.2x the instructions, 16: 1.5x the C)
BASE = {"base": 8}   # mapaccum nests loops of 8 calls (base 4: smaller C, slower; 16: larger C)


class Layout:
    """Which entries of a column of ``size`` travel: zero entries and constant entries do not
    (the receiving kernel knows them), only the others ("rows") are packed."""

    def __init__(self, size: int, rows=(), consts=()):
        self.size = size
        self.rows = tuple(rows)
        self.consts = tuple(consts)          # (row, value)

    @staticmethod
    def of(x: ca.SX) -> "Layout":
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
        return Layout(x.numel(), rows, consts)

    def _state(self):
        st = dict(self.consts)
        st.update({r: None for r in self.rows})       # None: not a constant
        return st

    def join(self, o: "Layout") -> "Layout":
        """The layout holding both: an entry stays constant only where both have that constant."""
        a, b = self._state(), o._state()
        rows, consts = [], []
        for r in sorted(set(a) | set(b)):
            if r in a and r in b and a[r] is not None and a[r] == b[r]:
                consts.append((r, a[r]))
            else:
                rows.append(r)
        return Layout(self.size, rows, consts)

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


def repack(a: Layout, b: Layout) -> ca.Function:
    """Packed in layout a -> packed in layout b (b holds a)."""
    c, full = a.symbol("c")
    return ca.Function("repack", [c], [b.pack(full)])


class LinkKernels:
    """The three pass kernels of one class of links.  Carries and the values handed from one
    pass to the next travel packed (``Layout``); the joint transform E is computed once, in
    pass 1, and handed on (it holds the trigonometry of a revolute joint)."""

    def __init__(self, form):
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


@record(frozen=False)
class Kernel:
    """A settled kernel: (carry, xi_j for j in ``used``, *others) -> (carry, *others)."""

    f: ca.Function
    carry: Layout                   # of its carry (in and out)
    extra: list                      # layouts of its other outputs
    used: list                       # the data rows it reads


def settle(build, lay_in: Layout, xi, name: str, dense_extra=False) -> Kernel:
    """The kernel whose carry layout is the fixpoint holding lay_in.

    build(layout) -> (carry symbol, other inputs, carry out, other outputs).  Only the data
    rows the kernel reads become inputs; the other outputs are packed unless dense_extra."""
    lay = lay_in
    while True:
        c, ins, carry, extra = build(lay)
        nxt = lay.join(Layout.of(carry))
        if nxt == lay:
            break
        lay = nxt
    if dense_extra:
        extra_lay = [Layout(e.numel(), range(e.numel())) for e in extra]
    else:
        extra_lay = [Layout.of(e) for e in extra]
    outs = [lay.pack(carry)] + [el.pack(e) for el, e in zip(extra_lay, extra)]
    allout = ca.veccat(*outs)
    used = [j for j in range(xi.numel()) if ca.depends_on(allout, xi[j])]
    f = ca.Function(name, [c, *[xi[j] for j in used], *ins], outs)
    return Kernel(f, lay, extra_lay, used)


def row(xall, idx: list):
    """The values xall[idx] as a 1 x len(idx) row: repeated, a (strided) slice, or a gather."""
    n = len(idx)
    if all(i == idx[0] for i in idx):
        return ca.repmat(xall[idx[0]], 1, n)
    step = idx[1] - idx[0] if n > 1 else 1
    if step > 0 and idx == list(range(idx[0], idx[0] + step * n, step)):
        return ca.reshape(xall[idx[0]:idx[0] + step * (n - 1) + 1:step], 1, n)
    return ca.reshape(xall[idx], 1, n)


def stepper(k: Kernel, U: int, shared: tuple) -> ca.Function:
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


def loop(f: ca.Function, n: int) -> ca.Function:
    """f applied n times, its first output fed back as its first input (C: nested loops)."""
    return f.mapaccum(f.name() + "loop", n, 1, BASE) if n > 1 else f


def steps(flat, m: int, n: int, lo: int, hi: int, U: int, reverse: bool):
    """Steps lo..hi-1 of a flat link-by-link vector of n links (m values each; step s is link
    n-1-s when reverse) as the matrix a loop maps over: (U m) x ((hi - lo) / U)."""
    if m == 0:
        return ca.MX(0, (hi - lo) // U)
    if not reverse:
        block = flat[lo * m:hi * m]
    else:
        block = flat[[(n - 1 - s) * m + r for s in range(lo, hi) for r in range(m)]]
    return ca.reshape(block, U * m, (hi - lo) // U)


def run(k: Kernel, n: int, cin, xall, rows: list, ys: list):
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
            args += [row(xall, idx[lo + u:hi:u_]) for idx in vary]
        args += [steps(y, m, n, lo, hi, u_, rev) for (y, rev), m in zip(ys, sizes)]
        res = loop(stepper(k, u_, shared), cnt)(*args)
        carry = res[0][:, cnt - 1]
        outs.append([ca.vec(Y) for Y in res[1:]])
    return carry[:nc], [ca.vertcat(*parts) for parts in zip(*outs)]
