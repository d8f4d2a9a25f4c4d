"""The articulated-body algorithm as loops over per-link kernels (issue 16).

The unrolled forward dynamics (``dynamics.aba``) is one SX expression whose generated C grows
linearly with the number of links, and gcc's time faster than linearly (45 s for a 200-link
chain).  Here the same algorithm is cut into per-link *kernels*, one SX Function per pass
(forward: kinematics and bias forces; backward: articulated inertias; forward: accelerations),
and a run of structurally identical links is chained with ``Function.mapaccum``: the C holds
each kernel once (inlined GROUP times, for GROUP consecutive links per call) and calls it in
loops that CasADi nests in base 8, so the C grows with log N instead of N.

Identical links: for every link the local inputs of its step (joint transform, motion
subspace, free speeds, prescribed motion, inertia, external force, joint force) are SX in the
model's symbols (q, qd, t, u, p) and, for the external force, in placeholders of the link's
own pose and velocity.  The symbols it reads become the link's *data* (in the order the
expression graph meets them) and are replaced by generic ones; two links are identical when
the resulting local Functions serialize to the same bytes.  So per-link parameter values
(``link[i].m``) are data, while a different joint axis, body shape or a force that reaches
other links (a spring to another body) makes a link different.  A link whose external force
depends on another link's pose is still exact: that pose enters through the model's symbols.
A data row that holds one symbol for every link of a run (a shared parameter) rides in the
carry instead of being repeated per link.

Structural zeros and constants are kept: the carry between links (pose, velocities;
articulated inertia and bias force; accelerations) and the values handed from pass to pass
travel *packed* (``Layout``: zero and constant entries stay in the kernels), the carry's
layout being the fixpoint of the kernel's own output, so a planar chain loops over planar
kernels.  The joint transform is computed once, in pass 1 (it holds a revolute joint's
trigonometry), and handed on.

``plan`` returns None when the looped form would not pay (runs of ``LOOP_MIN`` or more links
hold less than half of the links) or does not apply; callers then use the unrolled
expression.  ``ChainPlan.ode(eom)`` assembles the MX Function ``(t, x, u, p) -> xdot`` (or
None when the EOM's fields are no longer the ones the plan was made for).  Cost (benchmarks/chain_kernel.py): about 2x the instructions of
the unrolled C per evaluation and 10-20x the time in the virtual machine, so ``codegen`` uses
it for compiled code of big chains only.
"""
from __future__ import annotations

import casadi as ca

from .kernels import NACC, NART, NPOSE, Kernel, Layout, LinkKernels, repack, run, settle
from .tree import Tree, z3
from ..model.records import record

LOOP_MIN = 4          # links in a run below which nothing is looped

class _Placeholders:
    """A Kinematics stand-in whose link poses and velocities are free symbols."""

    def __init__(self, n: int):
        self.R = [ca.SX.sym(f"R{i}", 3, 3) for i in range(n)]
        self.o = [ca.SX.sym(f"o{i}", 3) for i in range(n)]
        self.w = [ca.SX.sym(f"w{i}", 3) for i in range(n)]
        self.v = [ca.SX.sym(f"v{i}", 3) for i in range(n)]

    def flat(self, i: int) -> ca.SX:
        return ca.vertcat(ca.vec(self.R[i]), self.o[i], self.w[i], self.v[i])


_PH = ca.SX.sym("ph", NPOSE)      # generic pose placeholder of the kernels


@record(frozen=False)
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
    own = {phi[j].element_hash() for j in range(NPOSE)}
    syms = ca.symvar(ca.veccat(*loc, *f))
    data = [s for s in syms if s.element_hash() not in own]
    xi = ca.SX.sym("xi", len(data))
    dv = ca.vertcat(*data) if data else ca.SX(0, 1)
    gen = ca.substitute(loc + f, [dv, phi], [xi, _PH])
    loc_f = ca.Function("loc", [xi], gen[:len(loc)])
    force_f = ca.Function("force", [xi, _PH], gen[len(loc):])
    key = (lk.k, loc_f.serialize(), force_f.serialize())
    return _Form(lk.k, data, xi, loc_f, force_f, key)


@record(frozen=False)
class _Segment:
    links: list                      # consecutive link indices, each the parent of the next
    kern: LinkKernels
    data: list                       # per link: the model's symbols in the kernel's order
    k1: Kernel | None = None
    k2: Kernel | None = None
    k3: Kernel | None = None

    @property
    def top(self):
        return self.links[0]

    @property
    def bottom(self):
        return self.links[-1]


_WORLD = Layout(NPOSE, (), ((0, 1.0), (4, 1.0), (8, 1.0)))   # R = 1, o = w = v = 0


class ChainPlan:
    """Segments of the link tree with their kernels; ``ode(eom)`` assembles the looped form."""

    def __init__(self, tree: Tree, segments: list, qdd, post):
        self.tree = tree
        self.segments = segments
        self.qdd = qdd
        self.post = post                 # (nud symbol, q'' in it), or None for the identity
        self.parent = {lk.index: lk.parent for lk in tree.links}
        self._kernels()

    def _kernels(self):
        """Each segment's three kernels, the carry layouts settled pass by pass in the order
        the values flow (a parent's layout is held by its children's).  Segments of one class
        with the same layouts share their kernels (one C function each)."""
        cache: dict = {}

        def kernel(s, which, build, lay, *key):
            k = (id(s.kern), which, lay, *key)
            if k not in cache:
                got = settle(build, lay, s.kern.form.xi, which, dense_extra=which == "aba_acc")
                settled = (id(s.kern), which, got.carry, *key)   # another start may settle alike
                cache[k] = cache.setdefault(settled, got)
            return cache[k]

        out1, out2, out3 = {}, {}, {}
        for s in self.segments:                              # pass 1, top-down
            lam = self.parent[s.top]
            s.k1 = kernel(s, "aba_fwd", s.kern.pass1, out1[lam] if lam >= 0 else _WORLD)
            out1[s.bottom] = s.k1.carry
        for s in reversed(self.segments):                    # pass 2, bottom-up
            lay = Layout(NART)
            for c in out2.pop(s.bottom, []):
                lay = lay.join(c)
            y1 = s.k1.extra[0]
            s.k2 = kernel(s, "aba_bwd", lambda la, s=s, y1=y1: s.kern.pass2(la, y1), lay, y1)
            lam = self.parent[s.top]
            if lam >= 0:
                out2.setdefault(lam, []).append(s.k2.carry)
        for s in self.segments:                              # pass 3, top-down
            lam = self.parent[s.top]
            y1, y2 = s.k1.extra[0], s.k2.extra[0]
            s.k3 = kernel(s, "aba_acc", lambda la, s=s, y1=y1, y2=y2: s.kern.pass3(la, y1, y2),
                          out3[lam] if lam >= 0 else Layout(NACC), y1, y2)
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

        def into(val, have: Layout, want: Layout):
            return val if have == want else repack(have, want)(val)

        for s in segs:                                   # pass 1, top-down
            lam = self.parent[s.top]
            if lam >= 0:
                cin = into(pose[lam], seg_of[lam].k1.carry, s.k1.carry)
            else:
                cin = into(ca.MX(0, 1), _WORLD, s.k1.carry)
            pose[s.bottom], (y1[id(s)],) = run(s.k1, len(s.links), cin, xall,
                                                self._indices(index, s, s.k1.used), [])
        for s in reversed(segs):                         # pass 2, bottom-up
            cin = ca.MX.zeros(len(s.k2.carry.rows), 1)
            for val, lay in art.pop(s.bottom, []):
                cin = cin + into(val, lay, s.k2.carry)
            top, (y2[id(s)],) = run(s.k2, len(s.links), cin, xall, self._indices(index, s, s.k2.used, reverse=True),
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
                cin = into(ca.MX(0, 1), Layout(NACC), s.k3.carry)
            acc[s.bottom], (nd,) = run(s.k3, len(s.links), cin, xall, self._indices(index, s, s.k3.used),
                                        [(y1[id(s)], False), (y2[id(s)], True)])
            if s.kern.k:
                parts.append(nd)
        return ca.vertcat(*parts) if parts else ca.MX(0, 1)


def plan(tree: Tree, fext_of, tau, qdd, qdd_of) -> ChainPlan | None:
    """The looped form of the ABA over ``tree``, or None unless runs of at least LOOP_MIN
    identical links hold at least half of the links.

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
        kern = kernels.setdefault(fm.key, LinkKernels(fm))
        segments.append(_Segment([lk.index], kern, [fm.data]))
    looped = sum(len(s.links) for s in segments if len(s.links) >= LOOP_MIN)
    if 2 * looped < len(links):      # mostly other links: the unrolled expression is smaller
        return None
    nud = ca.SX.sym("nud", len(tree.dofs))
    expr = qdd_of(nud)
    post = None if _same(expr, nud) else (nud, expr)
    return ChainPlan(tree, segments, qdd, post)


def _same(a, b) -> bool:
    return a.shape == b.shape and all(ca.is_equal(a[i], b[i]) for i in range(a.numel()))
