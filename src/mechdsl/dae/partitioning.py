"""Coordinate partitioning ("partitioning"): an ODE in independent coordinates only.

q is split into independent coordinates u (n - m of them) and dependent ones v (m).  The
integrator (CVODES) carries only (u, u'); whenever it needs the right-hand side it

  1. solves g(u, v, t) = 0 for v by Newton's method (a CasADi rootfinder inside the RHS,
     warm-started from the quadratic Taylor prediction v_k + v'_k tau + v''_k tau^2 / 2 from
     the start of the sub-segment; a Newton solve that does not converge is an error of
     the RHS, which CVODES answers with a smaller step),
  2. solves G_v v' = -(G_u u' + g_t) for v',
  3. computes q'' from the augmented system and returns (u', u''_u).

So the state stays on both constraint manifolds up to the Newton tolerance, by
construction.  The partition is chosen where it is well conditioned: the m columns of the
scaled Jacobian S G D picked first by a QR factorization with column pivoting are the
dependent coordinates.  After each segment the condition number of the scaled G_v is
checked after every sub-segment (sigma_max(S G D) / sigma_min of the dependent block);
when it has grown by more than ``repartition_cond`` (default 10) over its value when
chosen, or a Newton solve failed, a new partition is chosen (and recorded as an event).  One integrator is built per partition and cached.

Sub-segments.  The warm start is only good near the sub-segment start, so the stepper
cuts each segment into sub-segments whose length adapts to the Newton contraction rate
theta = |dv_2| / |dv_1| of two Newton steps from the prediction at the sub-segment end:
theta is about proportional to tau^3, and the next length is chosen for theta ~ 0.05.
A sub-segment is redone 4 times shorter when theta > 0.3, when the dependent coordinates
end far from the prediction (a jump to another assembly branch), or when the condition
of G_v overshot three times the re-partition level.
"""
from __future__ import annotations

import numpy as np

from ..integrators import make_integrator
from .constrained_system import scale_jacobian
from .dof import dependent_columns
from .segments import StepError, Stepper, build_timer, call_integrator, integrator_options, ode_plugin


THETA_TARGET = 0.05   # aimed-for Newton contraction of the warm start at a sub-segment end
THETA_REJECT = 0.3    # above this the sub-segment is redone shorter (branch-jump risk)
SWITCH_EARLY = 0.7    # re-partition at this fraction of repartition_cond
CONT_STEPS = 4        # steps of the continuation check of the dependent coordinates per sub-segment
CONT_NEWTON = 8       # Newton iterations per continuation step


def _partition_cond(system, q, t, dep) -> float:
    """sigma_max(S G D) / sigma_min((S G D)_v): how much worse the block G_v is than G."""
    Gs = scale_jacobian(system.G(q, t), system.M(q, t))
    s_all = np.linalg.svd(Gs, compute_uv=False)
    s_v = np.linalg.svd(Gs[:, list(dep)], compute_uv=False)
    return float(s_all[0] / s_v[-1]) if s_v[-1] > 0 else float("inf")


class PartitioningStepper(Stepper):
    def __init__(self, system, opts):
        super().__init__(system=system, opts=opts, name="partitioning")
        self.dep: tuple[int, ...] = ()
        self.ind: tuple[int, ...] = ()
        self.cond0 = 1.0
        self._cache: dict = {}
        self.events: list = []
        self.stats["repartitions"] = 0
        self.stats["subsegments"] = 0
        self._pieces = self._build_pieces()
        self.h_sub = None
        self._r_prev = None
        self._cond_now = 1.0

    # -- partitions -------------------------------------------------------------------------
    def _build_pieces(self):
        import casadi as ca

        S = self.system.sym
        geo = ca.Function("geometry", [S["q"], S["t"], S["p"]], [S["g"], S["G"], S["gt"]])
        q, qd, t, p = (ca.MX.sym(k, *S[k].shape) for k in ("q", "qd", "t", "p"))
        g, G, gt = geo(q, t, p)
        qdd, _ = self.system.fn["accel"](q, qd, t, p, 0, 0)
        return ca.Function("pieces", [q, qd, t, p], [g, G, gt, qdd])

    def choose_partition(self, q, t, reason: str = "start") -> None:
        Gs = scale_jacobian(self.system.G(q, t), self.system.M(q, t))
        dep = dependent_columns(Gs)
        old = self.dep
        self.dep = dep
        self.ind = tuple(i for i in range(self.system.n) if i not in dep)
        self.cond0 = max(_partition_cond(self.system, q, t, dep), 1.0)
        if old and old != dep:
            self.stats["repartitions"] += 1
        coords = self.system.eom.coords
        if old != dep:
            self.events.append({"time": float(t), "kind": "partition", "contact": "-", "reason": reason,
                                "independent": [coords[i] for i in self.ind],
                                "dependent": [coords[i] for i in self.dep], "cond": self.cond0})

    def _integrator(self):
        key = self.dep
        if key not in self._cache:
            with build_timer(self.stats):
                self._cache[key] = self._make_integrator()
        return self._cache[key]

    def _make_integrator(self):
        import casadi as ca

        sysm = self.system
        S = sysm.sym
        n, m = sysm.n, sysm.m
        k = n - m
        dep, ind = list(self.dep), list(self.ind)
        # Newton solve of g(u, v, t) = 0 for v
        vs = ca.SX.sym("v", m)
        us = ca.SX.sym("u", k)
        ts = ca.SX.sym("t")
        qs = ca.SX.zeros(n, 1)
        for j, i in enumerate(dep):
            qs[i] = vs[j]
        for j, i in enumerate(ind):
            qs[i] = us[j]
        g_uv = ca.substitute(S["g"], ca.vertcat(S["q"], S["t"]), ca.vertcat(qs, ts))
        tol = 1e-4 * self.opts.bound
        rf = ca.rootfinder("dependent", "newton", {"x": vs, "p": ca.vertcat(us, ts, S["p"]), "g": g_uv},
                           {"abstol": tol, "abstolStep": 1e-15, "max_iter": 30, "error_on_fail": True})
        # right-hand side in MX (the rootfinder is an implicit function)
        u = ca.MX.sym("u", k)
        ud = ca.MX.sym("ud", k)
        s = ca.MX.sym("s")
        p = ca.MX.sym("p", S["p"].numel())
        t0 = ca.MX.sym("t0")
        h = ca.MX.sym("h")
        vk = ca.MX.sym("vk", m)
        vdk = ca.MX.sym("vdk", m)
        vddk = ca.MX.sym("vddk", m)
        t = t0 + s * h
        tau = s * h
        v = rf(vk + vdk * tau + 0.5 * vddk * tau**2, ca.vertcat(u, t, p))
        q = _assemble(n, ind, dep, u, v)
        _, G, gt, _ = self._pieces(q, ca.MX.zeros(n), t, p)
        Gu = G[:, ind]
        Gv = G[:, dep]
        vd = -ca.solve(Gv, ca.mtimes(Gu, ud) + gt)
        qd = _assemble(n, ind, dep, ud, vd)
        _, _, _, qdd = self._pieces(q, qd, t, p)
        udd = ca.vertcat(*[qdd[i] for i in ind]) if k else ca.MX.zeros(0, 1)
        dae = {"x": ca.vertcat(u, ud), "t": s, "p": ca.vertcat(p, t0, h, vk, vdk, vddk),
               "ode": h * ca.vertcat(ud, udd)}
        plugin = ode_plugin(self.opts)          # the method asked for (metadata names it)
        F = make_integrator("partitioned", plugin, dae, 0.0, 1.0, integrator_options(self.opts, plugin))
        recover = ca.Function("recover", [u, ud, s, p, t0, h, vk, vdk, vddk], [q, qd])
        return F, recover

    # -- stepping ---------------------------------------------------------------------------
    def reset(self, t, q, qd) -> None:
        super().reset(t, q, qd)
        if not self.dep:
            self.choose_partition(q, t)

    def advance(self, times, monitor=None):
        times = np.atleast_1d(np.asarray(times, float))
        mon = np.ones(len(times), bool) if monitor is None else np.asarray(monitor, bool)
        at: dict[float, tuple[np.ndarray, np.ndarray]] = {}
        for t1 in times[mon]:
            outs = [float(t) for t in times[~mon] if self.t < t < t1]
            self._advance_to(float(t1), outs, at)
            at[float(t1)] = (self.q.copy(), self.qd.copy())
        Q = np.array([at[float(t)][0] for t in times])
        QD = np.array([at[float(t)][1] for t in times])
        return times, Q, QD

    def _advance_to(self, t1: float, outs=(), at=None) -> None:
        """Integrate to t1 in adaptive sub-segments (see the module docstring).  The states at
        the output times ``outs`` (before t1) go into ``at``: each is integrated from the start
        of the accepted sub-segment containing it, on the side, so output times never cut a
        sub-segment and do not change the run."""
        if self.h_sub is None:
            rho = self.system.spectral_radius(self.q, self.qd, self.t)
            self.h_sub = 0.1 / rho if rho > 0 else t1 - self.t
        fails = 0
        h_min = 1e-12 * max(abs(t1), 1.0)
        while self.t < t1:
            h = min(self.h_sub, t1 - self.t)
            if t1 - (self.t + h) < h_min:
                h = t1 - self.t
            if h < h_min:
                raise StepError("sub-segments shrank below the time resolution: no partition of the "
                                "coordinates stays well conditioned here")
            saved = (self.t, self.q.copy(), self.qd.copy())
            try:
                theta = self._sub_advance(self.t + h)
                cond = _partition_cond(self.system, self.q, self.t, self.dep)
                if theta > THETA_REJECT or cond > 3 * self.opts.repartition_cond * self.cond0:
                    self.reset(*saved)
                    raise StepError(f"sub-segment rejected (Newton contraction {theta:.2g}, "
                                    f"condition of G_v {cond:.3g})")
            except StepError:
                fails += 1
                self.stats["rejected_subsegments"] = self.stats.get("rejected_subsegments", 0) + 1
                self.h_sub = h / 4
                if fails > 12:
                    raise
                continue
            fails = 0
            self.stats["subsegments"] += 1
            inside = [t for t in outs if saved[0] < t <= self.t]
            if inside:
                end = (self.t, self.q.copy(), self.qd.copy())
                for t_o in inside:
                    self.reset(*saved)
                    self._sub_advance(t_o)
                    at[t_o] = (self.q.copy(), self.qd.copy())
                self.reset(*end)
            factor = min(3.0, max(0.2, (THETA_TARGET / theta) ** (1 / 3) if theta > 0 else 3.0))
            truncated = h < self.h_sub
            if not (truncated and factor >= 1):      # a cut-short last piece says little about growth
                self.h_sub = h * factor
            self._check_partition()
            self._limit_by_conditioning(h)

    def _sub_advance(self, t1: float) -> float:
        sysm = self.system
        h = t1 - self.t
        ind, dep = list(self.ind), list(self.dep)
        F, recover = self._integrator()
        qdd, _ = sysm.accel(self.q, self.qd, self.t)
        vk, vdk, vddk = self.q[dep], self.qd[dep], qdd[dep]
        pvec = np.concatenate([sysm.p, [self.t, h], vk, vdk, vddk])
        r = call_integrator(F, x0=np.concatenate([self.q[ind], self.qd[ind]]), p=pvec)
        self._count(F)
        x = np.array(r["xf"], float).ravel()
        k = len(ind)
        if not np.all(np.isfinite(x)):
            raise StepError("the state became non-finite (Newton solve for the dependent coordinates failed)")
        q, qd = recover(x[:k], x[k:], 1.0, sysm.p, self.t, h, vk, vdk, vddk)
        q = np.array(q, float).ravel()
        qd = np.array(qd, float).ravel()
        if not (np.all(np.isfinite(q)) and np.all(np.isfinite(qd))) or \
                np.max(np.abs(sysm.g(q, t1)), initial=0.0) > self.opts.bound:
            raise StepError("Newton solve for the dependent coordinates failed")
        v_pred = vk + vdk * h + 0.5 * vddk * h * h
        miss, moved = np.linalg.norm(q[dep] - v_pred), np.linalg.norm(q[dep] - vk)
        if miss > 0.5 * moved + 1e-10 * (1 + np.linalg.norm(vk)):
            # Newton found a root far from the prediction: possibly another assembly branch
            raise StepError("the dependent coordinates left the predicted branch")
        self._check_continuation(q, qd, t1)
        theta = self._contraction(q, t1, v_pred)
        self.t, self.q, self.qd = float(t1), q, qd
        return theta

    def _check_continuation(self, q1, qd1, t1: float) -> None:
        """The dependent coordinates at the sub-segment end must be the continuation of those
        at its start (another root of g(u, v) = 0 is another assembly branch: measured on the
        Cartesian pendulum, y -> -y over one long sub-segment put the mass over the top with
        5.8 J more energy, and the run reported success).

        Two checks.  (1) det(G_v) keeps its sign: along a continuous branch on which G_v stays
        regular it cannot change sign.  (2) v is followed from the start along the cubic
        Hermite path of (u, u') in CONT_STEPS steps, each a tangent prediction and Newton
        iterations that must contract; the point reached must be the recovered one."""
        sysm, dep, ind = self.system, list(self.dep), list(self.ind)
        t0, q0, qd0 = self.t, self.q, self.qd
        G0, G1 = sysm.geometry(q0, t0)[1], sysm.geometry(q1, t1)[1]
        s0, s1 = np.linalg.slogdet(G0[:, dep])[0], np.linalg.slogdet(G1[:, dep])[0]
        if s0 * s1 <= 0:
            raise StepError("the dependent coordinates changed assembly branch (det G_v changed sign)")
        h = t1 - t0
        u0, u1, ud0, ud1 = q0[ind], q1[ind], qd0[ind] * h, qd1[ind] * h
        tol = 1e-3 * self.opts.bound
        qq = q0.copy()
        v = q0[dep].copy()
        vs = qd0[dep] * h              # dv/ds at the start (s = (t - t0) / h)
        for j in range(1, CONT_STEPS + 1):
            s = j / CONT_STEPS
            ds = 1.0 / CONT_STEPS
            h00, h10, h01, h11 = 2 * s**3 - 3 * s**2 + 1, s**3 - 2 * s**2 + s, -2 * s**3 + 3 * s**2, s**3 - s**2
            qq[ind] = h00 * u0 + h10 * ud0 + h01 * u1 + h11 * ud1
            qq[dep] = v + vs * ds
            t = t0 + s * h
            last = np.inf
            for _it in range(CONT_NEWTON):
                r, G, _ = sysm.geometry(qq, t)
                try:
                    dv = -np.linalg.solve(G[:, dep], r)
                except np.linalg.LinAlgError:
                    raise StepError("the dependent coordinates cannot be continued: G_v is singular") from None
                step = float(np.linalg.norm(dv))
                if not np.isfinite(step) or step > 0.5 * last:
                    raise StepError("the dependent coordinates cannot be continued (Newton does not contract)")
                qq[dep] += dv
                last = step
                if step <= tol * (1 + float(np.linalg.norm(qq[dep]))):
                    break
            else:
                raise StepError("the dependent coordinates cannot be continued (Newton iteration limit)")
            dh00, dh10, dh01, dh11 = 6 * s**2 - 6 * s, 3 * s**2 - 4 * s + 1, -6 * s**2 + 6 * s, 3 * s**2 - 2 * s
            us = dh00 * u0 + dh10 * ud0 + dh01 * u1 + dh11 * ud1
            _, G, gt = sysm.geometry(qq, t)
            try:
                vs = -np.linalg.solve(G[:, dep], G[:, ind] @ us + h * gt)
            except np.linalg.LinAlgError:
                raise StepError("the dependent coordinates cannot be continued: G_v is singular") from None
            v = qq[dep].copy()
        gap = float(np.linalg.norm(v - q1[dep]))
        if gap > 1e3 * tol * (1 + float(np.linalg.norm(v))):
            raise StepError(f"the dependent coordinates are not the continuation of the start values "
                            f"(off by {gap:.3g}): another assembly branch")

    def _contraction(self, q, t, v_pred) -> float:
        """theta = |dv_2| / |dv_1| of two Newton steps from the prediction v_pred at (u(t), t)."""
        dep = list(self.dep)
        qq = q.copy()
        qq[dep] = v_pred
        steps = []
        for _ in range(2):
            G = self.system.G(qq, t)[:, dep]
            try:
                dv = -np.linalg.solve(G, self.system.g(qq, t))
            except np.linalg.LinAlgError:
                return 1.0
            steps.append(np.linalg.norm(dv))
            qq[dep] += dv
        if steps[0] <= 1e-13 * (1 + np.linalg.norm(v_pred)):
            return 0.0
        return float(steps[1] / steps[0])

    def _limit_by_conditioning(self, h: float) -> None:
        """Shorten the next sub-segment when 1/cond(G_v) heads for the re-partition level, so
        the switch happens near that level instead of long after it (and long before G_v
        becomes singular).  The trend is taken from the last sub-segment, or, right after a
        (re-)partition, from the state moved on along q' for one sub-segment."""
        r = 1.0 / self._cond_now
        r_switch = 1.0 / (self.opts.repartition_cond * self.cond0)
        prev = self._r_prev
        self._r_prev = r
        if prev is None or h <= 0:
            h = self.h_sub
            prev = r
            r = 1.0 / _partition_cond(self.system, self.q + h * self.qd, self.t + h, self.dep)
            if r >= prev:
                return
            slope = (r - prev) / h
            r = prev
        elif r >= prev:
            return
        else:
            slope = (r - prev) / h
        tau = (r - r_switch) / -slope
        self.h_sub = min(self.h_sub, max(0.5 * tau, 1e-6 * h))

    def _check_partition(self) -> None:
        c = _partition_cond(self.system, self.q, self.t, self.dep)
        self._cond_now = c
        self.stats["max_partition_cond"] = max(self.stats.get("max_partition_cond", 0.0), c)
        # switch a little before the level the sub-segment limiter aims at (which it only
        # approaches, halving its distance each time)
        if c > SWITCH_EARLY * self.opts.repartition_cond * self.cond0:
            self.choose_partition(self.q, self.t, reason=f"condition number of G_v grew to {c:.3g}")
            self._cond_now = self.cond0
            self._r_prev = None

    def recover_from_failure(self) -> bool:
        """After a failed segment: try another partition (True if it changed)."""
        old = self.dep
        self.choose_partition(self.q, self.t, reason="Newton solve failed")
        return self.dep != old


def _assemble(n, ind, dep, a, b):
    import casadi as ca

    parts = [None] * n
    for j, i in enumerate(ind):
        parts[i] = a[j]
    for j, i in enumerate(dep):
        parts[i] = b[j]
    return ca.vertcat(*parts)
