/* mech_hybrid.c: contacts and fixations in co-simulation (MechContactOps).

   The FMU steps itself with the compiled Runge-Kutta loop of mechdsl (crk.c, dopri5 or
   dop853 with scipy's step control), carrying the step size from one communication step to
   the next (crk_run_events_h).  crk.c calls the model through `ode` (mech_cosim.c): the
   generated mech_ode while only the model's constraints are active, else the constrained
   accelerations of the active rows solved here:

       M q'' = bias + A' lam,   A q'' + gamma = 0      (lam > 0: a contact pushes)

   Contacts are the hybrid system of mechdsl.impacts.run, in C: open contacts watch their
   gap (event at gap + offset <= 0), closed (persistent) ones their normal force (event at
   lam <= 0), located by crk_run_events_h on the continuous extension of every step; at an
   event `handle` applies Lagrange's impact equations (one contact in closed form, several
   as the least-distance problem solved by non-negative least squares, or pairwise in the
   "sequential" order), decides which touching contacts are persistent (closed iff their
   force pushes), and projects the state onto the active rows.  Fixations are anchored
   at their time with the impact equations.  The model's constraints drift only by
   round-off and truncation: the state is projected back when the drift passes half the
   bound, at least every projection interval. */
#include <float.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "mech_fmu.h"

#define AT(A, lda, i, j) ((A)[(size_t)(j) * (size_t)(lda) + (size_t)(i)])
#define ARGS(...) ((const double *[16]){__VA_ARGS__})
#define RES(...) ((double *[16]){__VA_ARGS__})


/* ------------------------------------------------------------------ options of the contacts */

typedef struct { double rtol, atol, offset, touch, v_eps, rest_speed; } Opts;

static Opts options(Instance *I) {
  Opts o;
  mech_rtol_atol(I, &o.rtol, &o.atol);
  o.offset = MECH.rules.offset_factor * o.atol;                                  /* ContactRun.offset */
  o.touch = fmax(MECH.rules.touch_factor * o.atol, MECH.rules.touch_floor);        /* ContactRun.touch */
  o.rest_speed = I->real_settings[SET_REST_SPEED];
  o.v_eps = MECH.rules.v_eps_factor * o.rest_speed;                              /* ContactRun.v_eps */
  return o;
}

/* q'' and the multipliers lam of the rows `rows` at the state x (ContactSystem.accel) */
int mech_accel_rows(Instance *I, double t, const double *x, const int *rows, int nr_, double *qdd, double *lam) {
  const int n = MECH.n, NR = MECH.nrows;
  const double *q = x, *qd = x + n;
  double *M = I->work, *L = M + (size_t)n * n, *bias = L + (size_t)n * n, *c = bias + n, *A = c + NR;
  double *ct = A + (size_t)NR * n, *gam = ct + NR, *X = gam + NR, *W = X + (size_t)n * NR, *a0 = W + (size_t)NR * NR;
  double *rr = a0 + n, *Wc = rr + NR;
  if (mech_call(I, &MECH.dyn, ARGS(&t, q, qd, mech_inputs_at(I, t), I->p), RES(M, bias))) return 1;
  if (la_cholesky(n, M, L)) return 2;
  memcpy(a0, bias, sizeof(double) * (size_t)n);
  la_chol_solve(n, L, a0);
  if (nr_ == 0) { memcpy(qdd, a0, sizeof(double) * (size_t)n); return 0; }
  if (mech_call(I, &MECH.cons, ARGS(&t, q, qd, I->p), RES(c, A, ct, gam))) return 1;
  /* sliding friction of closed contacts: M q'' = bias + (A' + B) lam, B the friction per unit
     normal force (ContactSystem.accel); W = A M^-1 (A' + B) is then not symmetric */
  int friction = 0;
  double *Wf = Wc + (size_t)NR * NR;
  for (int j = 0; MECH.fric.f && j < nr_; j++) {
    int i = rows[j] - MECH.m;
    friction |= i >= 0 && i < MECH.k && MECH.fric_col[i] >= 0;
  }
  if (friction && mech_call(I, &MECH.fric, ARGS(&t, q, qd, I->p), RES(Wf))) return 1;
  for (int j = 0; j < nr_; j++) {
    double *col = X + (size_t)j * n;
    int i = rows[j] - MECH.m, fc = friction && i >= 0 && i < MECH.k ? MECH.fric_col[i] : -1;
    for (int l = 0; l < n; l++) col[l] = AT(A, NR, rows[j], l) + (fc >= 0 ? Wf[(size_t)fc * n + l] : 0.0);
    la_chol_solve(n, L, col);
  }
  for (int i = 0; i < nr_; i++) {
    for (int j = 0; j < nr_; j++) AT(W, nr_, i, j) = mech_row_dot(A, NR, n, rows[i], X + (size_t)j * n);
    rr[i] = -(mech_row_dot(A, NR, n, rows[i], a0) + gam[rows[i]]);
  }
  if (friction) {
    double *b = (double *)malloc(sizeof(double) * (size_t)(nr_ + 1));
    if (!b) return 1;
    memcpy(Wc, W, sizeof(double) * (size_t)nr_ * nr_);
    memcpy(b, rr, sizeof(double) * (size_t)nr_);
    int st = la_lu_solve(nr_, Wc, b, I->ipiv);
    if (st) st = la_min_norm(nr_, nr_, W, nr_, rr, b, NULL);
    if (!st) memcpy(rr, b, sizeof(double) * (size_t)nr_);
    free(b);
    if (st) return 3;
  } else if (mech_correction_solve(nr_, W, Wc, rr, I->ipiv)) return 3;
  for (int i = 0; i < n; i++) {
    double v = a0[i];
    for (int j = 0; j < nr_; j++) v += X[(size_t)j * n + i] * rr[j];
    qdd[i] = v;
  }
  if (lam) memcpy(lam, rr, sizeof(double) * (size_t)nr_);
  return 0;
}

/* MechContactOps.accel: q'' with the active rows and the model's multipliers (EOM convention
   M q'' = bias - G' lam: the active model rows' multipliers with the sign turned, 0 for others) */
static int accel(Instance *I, double t, const double *x, double *qdd, double *lam) {
  double *lamr = (double *)calloc((size_t)MECH.nrows + 1, sizeof(double));
  if (!lamr) return 1;
  int st = mech_accel_rows(I, t, x, I->active, I->nactive, qdd, lamr);
  if (!st && lam) {
    for (int i = 0; i < MECH.m; i++) lam[i] = 0.0;
    for (int j = 0; j < I->nactive; j++)
      if (I->active[j] < MECH.m) lam[I->active[j]] = -lamr[j];
  }
  free(lamr);
  return st;
}

/* crk.c's event function: per contact the gap (open) or the normal force (closed) */
static int events(const double **arg, double **res, cint *iw, double *w, int mem) {
  (void)iw; (void)w; (void)mem;
  Instance *I = mech_current;
  const int n = MECH.n, k = MECH.k;
  double t = *arg[0], *e = res[0];
  const double *x = arg[1];
  double *g = I->work + (I->nwork - (size_t)(2 * k) - 8), *lam = g + k;
  if (mech_call(I, &MECH.gap, ARGS(&t, x, I->p), RES(g))) return 1;
  int any = 0;
  for (int i = 0; i < k; i++) { e[i] = g[i]; any |= I->closed[i]; }
  if (any) {
    double *qdd = (double *)malloc(sizeof(double) * (size_t)(n + MECH.nrows + 1));
    if (!qdd) return 1;
    double *lr = qdd + n;
    int st = mech_accel_rows(I, t, x, I->active, I->nactive, qdd, lr);
    for (int j = 0; !st && j < I->nactive; j++) {
      int r = I->active[j] - MECH.m;
      if (r >= 0 && r < k) lam[r] = lr[j];
    }
    free(qdd);
    if (st) return 1;
    for (int i = 0; i < k; i++) if (I->closed[i]) e[i] = lam[i];
  }
  return 0;
}

static int events_work(cint *sz_arg, cint *sz_res, cint *sz_iw, cint *sz_w) {
  *sz_arg = 3; *sz_res = 1; *sz_iw = 0; *sz_w = 0;
  return 0;
}

/* ------------------------------------------------------------------ rows */

/* the rows of `cand` (in order) whose Jacobian rows are independent in the kinetic metric,
   greedily (ContactSystem.independent); their count, or -1 when the model cannot be evaluated */
static int independent(Instance *I, double t, const double *q, const int *cand, int nc, int *out) {
  const int n = MECH.n, NR = MECH.nrows;
  if (nc == 0) return 0;
  Eval E;
  if (mech_eval_new(&E)) return -1;
  double *basis = (double *)malloc(sizeof(double) * (size_t)(n * nc + 2 * n + 1));
  if (!basis || mech_eval_at(I, t, q, NULL, &E, 1, 1)) { free(basis); mech_eval_free(&E); return -1; }
  double *a = basis + (size_t)n * nc, *r = a + n;
  int nb = 0, count = 0;
  for (int s = 0; s < nc; s++) {
    for (int j = 0; j < n; j++) a[j] = AT(E.A, NR, cand[s], j);
    la_lower_solve(n, E.L, a);
    double na = 0.0;
    for (int j = 0; j < n; j++) na += a[j] * a[j];
    na = sqrt(na);
    if (na == 0.0) continue;
    memcpy(r, a, sizeof(double) * (size_t)n);
    for (int b = 0; b < nb; b++) {
      double d = 0.0;
      for (int j = 0; j < n; j++) d += basis[(size_t)b * n + j] * a[j];
      for (int j = 0; j < n; j++) r[j] -= d * basis[(size_t)b * n + j];
    }
    double nr = 0.0;
    for (int j = 0; j < n; j++) nr += r[j] * r[j];
    nr = sqrt(nr);
    if (nr > MECH.rules.rank_tol * na) {
      out[count++] = cand[s];
      for (int j = 0; j < n; j++) basis[(size_t)nb * n + j] = r[j] / nr;
      nb++;
    }
  }
  free(basis); mech_eval_free(&E);
  return count;
}

/* ------------------------------------------------------------------ impacts (impact_map.py) */

/* v orthogonalized against the nb orthonormal columns of basis (n each; twice, for
   accuracy); appended as column nb when its norm is above tol: 1, else 0 */
static int append_orthonormal(int n, double *basis, int nb, double *v, double tol) {
  for (int pass = 0; pass < 2; pass++)
    for (int b = 0; b < nb; b++) {
      double s = 0.0;
      for (int j = 0; j < n; j++) s += basis[(size_t)b * n + j] * v[j];
      for (int j = 0; j < n; j++) v[j] -= s * basis[(size_t)b * n + j];
    }
  double nr = 0.0;
  for (int j = 0; j < n; j++) nr += v[j] * v[j];
  nr = sqrt(nr);
  if (!(nr > tol)) return 0;
  for (int j = 0; j < n; j++) basis[(size_t)nb * n + j] = v[j] / nr;
  return 1;
}

/* Lagrange's impact equations: v+ from v- = v with the candidate rows G (kc x n), the
   bilateral rows B (nb x n) held (B v+ + bt = 0); e restitution; 0 ok, 1 contradictory,
   2 the numerics failed.  Dense column-major, n small. */
static int solve_impact(const Eval *E, const double *v, int kc, const double *G, const double *gt, const double *e,
                        int nb, const double *B, const double *bt, double *vplus) {
  const int n = MECH.n;
  size_t need = (size_t)(kc * n + nb * n + 4 * n * n + 6 * n + 6 * kc + (n + 1) * (kc + 1) + 16);
  double *buf = (double *)calloc(need, sizeof(double));
  int *idx = (int *)calloc((size_t)(kc + n + 1), sizeof(int));
  if (!buf || !idx) { free(buf); free(idx); return 2; }
  double *um = buf, *h = um + kc, *Gt = h + kc, *Bt = Gt + (size_t)kc * n, *w0 = Bt + (size_t)nb * n;
  double *N = w0 + n, *f = N + (size_t)n * n, *Em = f + kc, *tmp = Em + (size_t)(n + 1) * (kc + 1);
  double *z = tmp + n, *u = z + n, *wv = u + kc, *zz = wv + kc, *tau = zz + kc;
  int st = 0;
  memcpy(vplus, v, sizeof(double) * (size_t)n);
  for (int i = 0; i < kc; i++) {
    um[i] = gt[i];
    for (int j = 0; j < n; j++) um[i] += AT(G, kc, i, j) * v[j];
    h[i] = -e[i] * fmin(um[i], 0.0);
  }
  if (kc == 1 && nb == 0) {       /* _single: Lambda = max(0, h - u) / W, q'+ = q'- + M^-1 g' Lambda */
    for (int j = 0; j < n; j++) tmp[j] = G[j];
    la_chol_solve(n, E->L, tmp);
    double W = 0.0;
    for (int j = 0; j < n; j++) W += G[j] * tmp[j];
    if (W > 0.0 && isfinite(W)) {
      double lam = fmax(0.0, h[0] - um[0]) / W;
      for (int j = 0; j < n; j++) vplus[j] = v[j] + tmp[j] * lam;
      goto done;
    }
  }
  /* Gt = G L^-T, Bt = B L^-T (rows: L^-1 g_i) */
  for (int i = 0; i < kc; i++) {
    for (int j = 0; j < n; j++) tmp[j] = AT(G, kc, i, j);
    la_lower_solve(n, E->L, tmp);
    for (int j = 0; j < n; j++) AT(Gt, kc, i, j) = tmp[j];
  }
  for (int i = 0; i < nb; i++) {
    for (int j = 0; j < n; j++) tmp[j] = AT(B, nb, i, j);
    la_lower_solve(n, E->L, tmp);
    for (int j = 0; j < n; j++) AT(Bt, nb, i, j) = tmp[j];
  }
  int d = n;
  if (nb) {
    /* w0: the minimum-norm solution of Bt w = -bt - B v; N: an orthonormal basis of Bt's null space
       (the last n - nb columns of the Q of Bt' = Q R: Bt has independent rows) */
    double *rB = (double *)malloc(sizeof(double) * (size_t)(nb + 1));
    if (!rB) { st = 2; goto done; }
    for (int i = 0; i < nb; i++) rB[i] = -bt[i] - mech_row_dot(B, nb, n, i, v);
    if (la_min_norm(nb, n, Bt, nb, rB, w0, NULL)) { free(rB); st = 2; goto done; }
    double res = 0.0, rn = 0.0;
    for (int i = 0; i < nb; i++) { double r = mech_row_dot(Bt, nb, n, i, w0) - rB[i]; res += r * r; rn += rB[i] * rB[i]; }
    if (sqrt(res) > 1e-9 * fmax(1.0, sqrt(rn))) { free(rB); st = 1; goto done; }
    /* null space by Gram-Schmidt of the unit vectors against the rows of Bt */
    double *basis = (double *)malloc(sizeof(double) * (size_t)(n * n + 1));
    if (!basis) { free(rB); st = 2; goto done; }
    int nbasis = 0;
    for (int i = 0; i < nb; i++) {
      for (int j = 0; j < n; j++) tmp[j] = AT(Bt, nb, i, j);
      nbasis += append_orthonormal(n, basis, nbasis, tmp, 1e-12);
    }
    d = 0;
    for (int c = 0; c < n && nbasis < n; c++) {
      for (int j = 0; j < n; j++) tmp[j] = j == c ? 1.0 : 0.0;
      if (append_orthonormal(n, basis, nbasis, tmp, 1e-8)) {
        memcpy(N + (size_t)d * n, basis + (size_t)nbasis * n, sizeof(double) * (size_t)n);
        nbasis++; d++;
      }
    }
    free(basis); free(rB);
  } else {
    for (int j = 0; j < n; j++) for (int i = 0; i < n; i++) N[(size_t)j * n + i] = i == j ? 1.0 : 0.0;
  }
  /* E = Gt N (kc x d), f = h - gt - G v - Gt w0; the least-distance program min |z|, E z >= f */
  int feasible0 = 1;
  double scale = 1.0;
  for (int i = 0; i < kc; i++) {
    f[i] = h[i] - um[i] - mech_row_dot(Gt, kc, n, i, w0);
    if (f[i] > 0.0) feasible0 = 0;
    scale = fmax(scale, fabs(f[i]));
  }
  for (int j = 0; j < d; j++) z[j] = 0.0;
  if (!feasible0) {
    /* Lawson-Hanson: NNLS on [E'; f'/scale] u = e_{d+1}; z = -r[:d] / r[d] scale */
    int rows = d + 1;
    for (int i = 0; i < kc; i++) {
      for (int j = 0; j < d; j++) {
        double s = 0.0;
        for (int l = 0; l < n; l++) s += AT(Gt, kc, i, l) * N[(size_t)j * n + l];
        AT(Em, rows, j, i) = s;
      }
      AT(Em, rows, d, i) = f[i] / scale;
    }
    double *rhs = tau;
    for (int j = 0; j < rows; j++) rhs[j] = j == d ? 1.0 : 0.0;
    double rnorm = 0.0;
    if (la_nnls(rows, kc, Em, rhs, u, &rnorm, wv, zz, idx) == 2) { st = 2; goto done; }
    double *r = (double *)malloc(sizeof(double) * (size_t)(rows + 1));
    if (!r) { st = 2; goto done; }
    for (int j = 0; j < rows; j++) {
      double s = -rhs[j];
      for (int i = 0; i < kc; i++) s += AT(Em, rows, j, i) * u[i];
      r[j] = s;
    }
    double rd = r[d];
    for (int j = 0; j < d; j++) z[j] = -r[j] / rd * scale;
    free(r);
    if (fabs(rd) < 1e-14) { st = 1; goto done; }
  }
  /* w = w0 + N z, v+ = v + L^-T w */
  for (int i = 0; i < n; i++) {
    double s = w0[i];
    for (int j = 0; j < d; j++) s += N[(size_t)j * n + i] * z[j];
    tmp[i] = s;
  }
  la_upper_solve_t(n, E->L, tmp);
  for (int i = 0; i < n; i++) vplus[i] = v[i] + tmp[i];
done:
  free(buf); free(idx);
  return st;
}

/* ------------------------------------------------------------------ the hybrid logic (run.py) */

static int contact_row(int i) { return MECH.m + i; }

/* the bilateral rows: the model's constraints and the anchored rows of fixations */
static int bilateral(Instance *I, int *out) {
  int c = 0;
  for (int r = 0; r < MECH.m; r++) out[c++] = r;
  for (int r = MECH.m + MECH.k; r < MECH.nrows; r++) if (I->fix_sel[r]) out[c++] = r;
  return c;
}

static void count_event(Instance *I) { I->stats[STAT_EVENTS] += 1; }

static int zeno(Instance *I, double t) {
  int limit = 200 * (MECH.k + MECH.nfix + 1);
  if (fabs(t - I->burst_time) <= 1e-12 * fmax(1.0, fabs(t))) I->burst_count++;
  else { I->burst_time = t; I->burst_count = 1; }
  if (I->burst_count > limit) {
    mech_log(I, LOG_ERROR, "events do not settle at one instant: %ld events at t = %.12g; contacts may be contradictory",
             I->burst_count, t);
    return 1;
  }
  if (I->stats[STAT_EVENTS] > I->int_settings[SET_MAX_EVENTS]) {
    mech_log(I, LOG_ERROR, "more than %d events (Zeno behaviour? raise mechdsl.rest_speed or mechdsl.max_events)",
             I->int_settings[SET_MAX_EVENTS]);
    return 1;
  }
  I->recent[I->irecent] = t;
  const int zn = MECH.rules.zeno_events;
  I->irecent = (I->irecent + 1) % zn;
  if (I->nrecent < zn) I->nrecent++;
  double span = I->stop_defined ? I->t_stop - I->t_start : 0.0;
  if (I->nrecent == zn && span > 0 && t - I->recent[I->irecent] < MECH.rules.zeno_span * span) {
    mech_log(I, LOG_ERROR, "events accumulate (Zeno behaviour): the last %d events fell within %.3g s; raise "
             "mechdsl.rest_speed for the scale of this model's speeds", zn, t - I->recent[I->irecent]);
    return 1;
  }
  return 0;
}

/* Run._select: the active rows (bilateral, closed contacts) that are independent; closed
   contacts whose row is dependent are opened */
static int select_rows(Instance *I, double t, const double *q) {
  const int NR = MECH.nrows;
  int *cand = (int *)malloc(sizeof(int) * (size_t)(2 * NR + 1));
  if (!cand) return 1;
  int *sel = cand + NR;
  int nc = bilateral(I, cand);
  for (int i = 0; i < MECH.k; i++) if (I->closed[i]) cand[nc++] = contact_row(i);
  int ns = independent(I, t, q, cand, nc, sel);
  if (ns < 0) { free(cand); return 1; }
  for (int i = 0; i < MECH.k; i++) {
    if (!I->closed[i]) continue;
    int found = 0;
    for (int s = 0; s < ns; s++) found |= sel[s] == contact_row(i);
    if (!found) I->closed[i] = 0;
  }
  I->nactive = 0;
  int only_model = 1;
  for (int s = 0; s < ns; s++) { I->active[I->nactive++] = sel[s]; only_model &= sel[s] < MECH.m; }
  I->use_base = only_model;
  I->valid = 0;
  free(cand);
  return 0;
}

static double e_eff(Instance *I, int i, double u, const Opts *o) {
  double e = I->e[i];
  return e * fabs(fmin(u, 0.0)) < o->rest_speed ? 0.0 : e;
}

/* rows R of A (NR x n) and ct into G (nr x n) and gt */
static void take_rows(const Eval *E, const int *R, int nr_, double *G, double *gt) {
  const int n = MECH.n, NR = MECH.nrows;
  for (int i = 0; i < nr_; i++) {
    for (int j = 0; j < n; j++) AT(G, nr_, i, j) = AT(E->A, NR, R[i], j);
    gt[i] = E->ct[R[i]];
  }
}

/* Run.impact: the impact of the touching contacts `cands` (simultaneous or sequential) */
static int impact(Instance *I, double t, const double *q, double *qd, const int *cands, int kc, const Opts *o) {
  const int n = MECH.n, NR = MECH.nrows;
  Eval E;
  if (mech_eval_new(&E)) return 2;
  size_t need = (size_t)(2 * NR * n + 4 * NR + 2 * n + 8);
  double *buf = (double *)calloc(need, sizeof(double));
  int *ib = (int *)calloc((size_t)(3 * NR + 1), sizeof(int));
  int st = !buf || !ib ? 2 : mech_eval_at(I, t, q, qd, &E, 1, 1);
  if (st) { free(buf); free(ib); mech_eval_free(&E); return 2; }
  double *G = buf, *gt = G + (size_t)NR * n, *ee = gt + NR, *B = ee + NR, *bt = B + (size_t)NR * n, *v = bt + NR;
  int *brows = ib, *sel = ib + NR, *rows = sel + NR;
  int nbc = bilateral(I, brows);
  int nb = independent(I, t, q, brows, nbc, sel);
  if (nb < 0) { st = 2; goto done; }
  take_rows(&E, sel, nb, B, bt);
  for (int j = 0; j < kc; j++) rows[j] = contact_row(cands[j]);
  if (I->int_settings[SET_IMPACT_ORDER] == 1) {       /* sequential: the fastest approach first */
    int limit = 100 * (kc + 1);
    for (int it = 0; it < limit; it++) {
      int jmin = -1;
      double umin = 0.0;
      for (int j = 0; j < kc; j++) {
        double uj = mech_row_dot(E.A, NR, n, rows[j], qd) + E.ct[rows[j]];
        if (jmin < 0 || uj < umin) { jmin = j; umin = uj; }
      }
      if (umin >= -o->v_eps) goto done;
      double e1 = e_eff(I, cands[jmin], umin, o);
      take_rows(&E, rows + jmin, 1, G, gt);
      memcpy(v, qd, sizeof(double) * (size_t)n);
      if ((st = solve_impact(&E, v, 1, G, gt, &e1, nb, B, bt, qd))) goto done;
      count_event(I);
    }
  }
  /* simultaneous (also when pairwise impacts did not settle) */
  take_rows(&E, rows, kc, G, gt);
  for (int j = 0; j < kc; j++) ee[j] = e_eff(I, cands[j], mech_row_dot(G, kc, n, j, qd) + gt[j], o);
  memcpy(v, qd, sizeof(double) * (size_t)n);
  st = solve_impact(&E, v, kc, G, gt, ee, nb, B, bt, qd);
  if (!st) count_event(I);
done:
  free(buf); free(ib); mech_eval_free(&E);
  I->valid = 0;
  return st;
}

/* Run.settle: touching contacts close when at rest, separating ones open; closed ones whose
   force does not push are released, the worst first */
static int settle(Instance *I, double t, const double *q, const double *qd, const Opts *o) {
  const int n = MECH.n, k = MECH.k, NR = MECH.nrows;
  Eval E;
  if (mech_eval_new(&E)) return 1;
  double *buf = (double *)calloc((size_t)(3 * k + 4 * n + NR + 8), sizeof(double));
  int *before = (int *)calloc((size_t)(k + 1), sizeof(int));
  if (!buf || !before) { free(buf); free(before); mech_eval_free(&E); return 1; }
  double *gap = buf, *u = gap + k, *a0 = u + k, *lr = a0 + n, *x = lr + NR, *qdd = x + 2 * n;
  int st = (k && mech_call(I, &MECH.gap, ARGS(&t, q, I->p), RES(gap))) || mech_eval_at(I, t, q, qd, &E, 1, 1);
  for (int i = 0; !st && i < k; i++) u[i] = mech_row_dot(E.A, NR, n, contact_row(i), qd) + E.ct[contact_row(i)];
  memcpy(before, I->closed, sizeof(int) * (size_t)k);
  for (int i = 0; !st && i < k; i++) {
    if (!I->closed[i] && gap[i] <= o->touch && fabs(u[i]) <= o->v_eps) I->closed[i] = 1;
    else if (I->closed[i] && u[i] > o->v_eps) I->closed[i] = 0;
  }
  memcpy(x, q, sizeof(double) * (size_t)n);
  memcpy(x + n, qd, sizeof(double) * (size_t)n);
  for (int it = 0; !st && it < k + 1; it++) {
    if ((st = select_rows(I, t, q))) break;
    int any = 0;
    for (int i = 0; i < k; i++) any |= I->closed[i];
    if (!any) break;
    memcpy(a0, E.bias, sizeof(double) * (size_t)n);
    la_chol_solve(n, E.L, a0);
    if ((st = mech_accel_rows(I, t, x, I->active, I->nactive, qdd, lr))) break;
    int worst = -1;
    double wacc = 0.0;
    for (int i = 0; i < k; i++) {
      if (!I->closed[i]) continue;
      int r = contact_row(i), pos = -1;
      for (int j = 0; j < I->nactive; j++) if (I->active[j] == r) pos = j;
      double lam = pos >= 0 ? lr[pos] : 0.0;
      double *col = (double *)malloc(sizeof(double) * (size_t)n);
      if (!col) { st = 1; break; }
      for (int j = 0; j < n; j++) col[j] = AT(E.A, NR, r, j);
      la_chol_solve(n, E.L, col);
      double W = mech_row_dot(E.A, NR, n, r, col), afree = mech_row_dot(E.A, NR, n, r, a0) + E.gam[r];
      free(col);
      double a = lam * W - MECH.acc_tol * fmax(1.0, fabs(afree));
      if (worst < 0 || a < wacc) { worst = i; wacc = a; }
    }
    if (st || worst < 0 || wacc > 0) break;
    I->closed[worst] = 0;
  }
  if (!st) st = select_rows(I, t, q);
  for (int i = 0; !st && i < k; i++) if (I->closed[i] != before[i]) count_event(I);
  free(buf); free(before); mech_eval_free(&E);
  return st;
}

/* Run.handle: impacts, closing and releasing at t; the state projected onto the active rows */
static int handle(Instance *I, double t, double *q, double *qd) {
  const int n = MECH.n, k = MECH.k, NR = MECH.nrows;
  Opts o = options(I);
  Eval E;
  if (mech_eval_new(&E)) return 1;
  double *gap = (double *)calloc((size_t)(2 * k + 1), sizeof(double));
  int *cands = (int *)calloc((size_t)(2 * k + 1), sizeof(int));
  int st = !gap || !cands;
  if (!st && k) st = mech_call(I, &MECH.gap, ARGS(&t, q, I->p), RES(gap)) || mech_eval_at(I, t, q, qd, &E, 0, 1);
  int kc = 0, approach = 0;
  for (int i = 0; !st && i < k; i++) {
    if (I->closed[i] || gap[i] <= o.touch) {
      cands[kc++] = i;
      double u = mech_row_dot(E.A, NR, n, contact_row(i), qd) + E.ct[contact_row(i)];
      approach |= u < -o.v_eps;
    }
  }
  if (!st && approach) {
    st = impact(I, t, q, qd, cands, kc, &o);
    if (st == 1) mech_log(I, LOG_ERROR, "impact at t = %.12g could not be resolved: the contact conditions after it are contradictory", t);
  }
  if (!st) st = select_rows(I, t, q);
  if (!st) st = settle(I, t, q, qd, &o);
  if (!st) {
    int no = 0;
    for (int i = 0; i < k; i++) if (!I->closed[i]) cands[no++] = contact_row(i);
    st = mech_project(I, t, q, qd, I->active, I->nactive, 1e-3 * o.offset, cands, no, 0.5 * o.offset);
    I->stats[STAT_PROJECTIONS] += 1;
  }
  free(gap); free(cands); mech_eval_free(&E);
  I->valid = 0;
  return st;
}

/* Run.fixate: fixation j anchors its point where it is; the velocity jump from the impact equations */
static int fixate(Instance *I, double t, double *q, double *qd, int j) {
  const int n = MECH.n, NR = MECH.nrows, k = MECH.k;
  Opts o = options(I);
  int r0 = MECH.m + k + 3 * j;
  Eval E;
  if (mech_eval_new(&E)) return 1;
  int *ib = (int *)calloc((size_t)(4 * NR + k + 1), sizeof(int));
  double *buf = (double *)calloc((size_t)(2 * NR * n + 3 * NR + n + k + 8), sizeof(double));
  int st = !ib || !buf;
  if (!st) st = mech_eval_at(I, t, q, qd, &E, 0, 1);
  if (!st) for (int r = r0; r < r0 + 3; r++) I->anchor[r] = E.c[r] + I->anchor[r];   /* raw position */
  int *base = ib, *sel = base + NR, *brows = sel + NR, *cands = brows + NR;
  double *B = buf, *bt = B + (size_t)NR * n, *G = bt + NR, *gt = G + (size_t)NR * n, *ee = gt + NR, *v = ee + NR;
  double *gap = v + n;
  int nbase = 0, ns = 0, nb = 0, kc = 0;
  if (!st) {
    nbase = bilateral(I, base);
    for (int r = r0; r < r0 + 3; r++) base[nbase++] = r;
    ns = independent(I, t, q, base, nbase, sel);
    if (ns < 0) st = 1;
  }
  if (!st) {
    for (int s = 0; s < ns; s++) if (sel[s] >= r0 && sel[s] < r0 + 3) I->fix_sel[sel[s]] = 1;
    I->fix_done[j] = 1;
    for (int s = 0; s < ns; s++) brows[nb++] = sel[s];
    st = mech_eval_at(I, t, q, qd, &E, 1, 1) || (k && mech_call(I, &MECH.gap, ARGS(&t, q, I->p), RES(gap)));
  }
  if (!st) {
    take_rows(&E, brows, nb, B, bt);
    for (int i = 0; i < k; i++) if (I->closed[i] || gap[i] <= o.touch) cands[kc++] = contact_row(i);
    take_rows(&E, cands, kc, G, gt);
    for (int i = 0; i < kc; i++) ee[i] = e_eff(I, cands[i] - MECH.m, mech_row_dot(G, kc, n, i, qd) + gt[i], &o);
    memcpy(v, qd, sizeof(double) * (size_t)n);
    st = solve_impact(&E, v, kc, G, gt, ee, nb, B, bt, qd);
    if (st) mech_log(I, LOG_ERROR, "the fixation '%s' could not be applied at t = %.12g", MECH.rows[r0], t);
    else count_event(I);
  }
  free(ib); free(buf); mech_eval_free(&E);
  I->valid = 0;
  if (st) return st;
  return handle(I, t, q, qd);
}

/* ------------------------------------------------------------------ co-simulation */

/* MechContactOps.start: fixations due, then impacts and contacts at the start state */
static int start(Instance *I) {
  const int n = MECH.n;
  double t = I->t, *q = I->x, *qd = I->x + n;
  Opts o = options(I);
  int st = 0;
  for (int j = 0; !st && j < MECH.nfix; j++)
    if (MECH.fix_time[j] <= t) st = fixate(I, t, q, qd, j);
  if (!st && MECH.k) {
    double *gap = (double *)calloc((size_t)MECH.k, sizeof(double));
    st = !gap || mech_call(I, &MECH.gap, ARGS(&t, q, I->p), RES(gap));
    for (int i = 0; !st && i < MECH.k; i++)
      if (gap[i] < -o.touch) {
        mech_log(I, LOG_ERROR, "the start state penetrates contact '%s' (gap %.6g)", MECH.rows[MECH.m + i], gap[i]);
        st = 1;
      }
    free(gap);
    if (!st) st = handle(I, t, q, qd);
  } else if (!st && MECH.nrows) {
    st = select_rows(I, t, q);
  }
  if (st && !I->msg[0]) mech_log(I, LOG_ERROR, "the start state could not be prepared (contacts, fixations)");
  return st;
}

/* MechContactOps.step: advance to t_end, each stretch between events one call of crk.c
   (contacts: with event location), events handled as mechdsl.impacts does; the steps end at
   the communication points (an event may lie past one) */
static int step(Instance *I, double t_end) {
  const int n = MECH.n, nx = 2 * n;
  MechStepper S;
  if (mech_stepper_begin(I, t_end, &S)) return LOG_ERROR;
  const double tiny = S.tiny, interval = S.interval, rtol = S.rtol, atol = S.atol;
  const int method = S.method;
  const cint max_steps = S.max_steps;
  double *X = S.X, *xfail = S.xfail, *grid = S.grid, *stats = S.stats;
  cint *ctl = S.ctl;
  int result = LOG_OK, at_start = 0;
  while (I->t < t_end - tiny) {
    double t_stop = t_end;
    for (int j = 0; j < MECH.nfix; j++)
      if (!I->fix_done[j] && MECH.fix_time[j] > I->t && MECH.fix_time[j] < t_stop) t_stop = MECH.fix_time[j];
    if (I->nactive > 0 && interval > 0 && I->next_projection > I->t + tiny && I->next_projection < t_stop)
      t_stop = I->next_projection;
    mech_stepper_call(&S, I->t, t_stop);
    int st;
    if (MECH.k)
      st = crk_run_events_h(method, nx, grid, 2, I->x, I->u, I->p, rtol, atol, 0.0, max_steps, X, stats, ctl, xfail,
                            (void *)events, (void *)events_work, MECH.k, options(I).offset, MECH.samples, I->p,
                            NULL, NULL, NULL, NULL, NULL, 0, &I->h_next);
    else
      st = crk_run_dense(method, nx, grid, 2, I->x, I->u, I->p, rtol, atol, 0.0, max_steps, X, stats, ctl, xfail,
                         &I->h_next, 0.0, NULL, NULL);
    mech_stepper_count(I, &S);
    I->valid = 0;
    if (st == CRK_OK) {
      I->t = t_stop;
      memcpy(I->x, X + nx, sizeof(double) * (size_t)nx);
      at_start = 0;
    } else if (st == CRK_EVENT || st == CRK_EVENT_AT_START) {
      if (st == CRK_EVENT) {
        I->t = stats[3];
        memcpy(I->x, xfail, sizeof(double) * (size_t)nx);
        at_start = 0;
      } else if (at_start++) {
        mech_log(I, LOG_ERROR, "an event at t = %.12g persists after it was handled", I->t);
        result = LOG_ERROR; break;
      }
      if (zeno(I, I->t) || handle(I, I->t, I->x, I->x + n)) {
        if (!I->msg[0]) mech_log(I, LOG_ERROR, "the event at t = %.12g could not be handled", I->t);
        result = LOG_ERROR; break;
      }
      I->h_next = 0.0;            /* a new segment, started as mechdsl.impacts starts one */
      continue;
    } else {
      mech_log(I, LOG_DISCARD, "the step from t = %.12g to %.12g failed: %s (rtol %g, atol %g)", I->t, t_end,
               mech_crk_message(st), rtol, atol);
      result = LOG_DISCARD; break;
    }
    for (int j = 0; j < MECH.nfix; j++)
      if (!I->fix_done[j] && MECH.fix_time[j] <= I->t + tiny) {
        if (zeno(I, I->t) || fixate(I, I->t, I->x, I->x + n, j)) { result = LOG_ERROR; break; }
        I->h_next = 0.0;
      }
    if (result != LOG_OK) break;
    if (I->nactive > 0 && (I->t >= I->next_projection - tiny || I->t >= t_end - tiny)) {
      int projected = 0;
      if (MECH.constraints->check_drift(I, I->t, I->x, &projected)) { result = LOG_ERROR; break; }
      if (interval > 0) while (I->next_projection <= I->t + tiny) I->next_projection += interval;
    }
  }
  mech_stepper_end(&S);
  I->valid = 0;
  return result;
}

/* ------------------------------------------------------------------ model exchange */

/* MechContactOps.indicators: per contact, crk.c's event function: a closed contact's normal
   force plus the offset (zero where it ceases to push); an open contact's gap while it closes
   (zero where it touches: the importer's integrator locates the impact itself, as crk.c
   refines its root to the gap's), plus the offset while it opens, so that a contact left a
   hair inside by the impact's projection does not cross zero again on its way out (the jump
   of the offset happens where the gap's rate changes sign, away from zero when it flies) */
static int me_indicators(Instance *I, double t, const double *x, double *e) {
  const int n = MECH.n, k = MECH.k;
  Instance *prev = mech_current;
  mech_current = I;
  const double *arg[3] = {&t, x, I->p};
  double *res[1] = {e};
  int st = events(arg, res, NULL, NULL, 0);
  mech_current = prev;
  double off = options(I).offset;
  Eval E;
  int open = 0;
  for (int i = 0; i < k; i++) open |= !I->closed[i];
  if (st || !open) {
    for (int i = 0; !st && i < k; i++) e[i] += off;
    return st;
  }
  if (mech_eval_new(&E)) return 1;
  st = mech_eval_at(I, t, x, x + n, &E, 0, 1);
  for (int i = 0; !st && i < k; i++) {
    double u = mech_row_dot(E.A, MECH.nrows, n, contact_row(i), x + n) + E.ct[contact_row(i)];
    if (I->closed[i] || u >= 0.0) e[i] += off;
  }
  mech_eval_free(&E);
  return st;
}

/* MechContactOps.me_step_done: an event when the active rows drifted past half the bound */
static int me_step_done(Instance *I, int *enter_event) {
  double worst = 0.0;
  *enter_event = 0;
  if (mech_active_drift(I, I->t, I->x, &worst)) return 1;
  *enter_event = !(worst <= 0.5 * mech_drift_bound(I));
  return 0;
}

/* MechContactOps.me_event: at an event of the importer (a crossed indicator, a fixation's
   time, a drift past the bound), what `step` does at crk.c's events: fixations due, then
   impacts, closing and releasing (handle), then the projection of the active rows */
static int me_event(Instance *I, int *changed, int *next_defined, double *next_time) {
  const int n = MECH.n, k = MECH.k;
  double t = I->t, *q = I->x, *qd = I->x + n;
  const double tiny = 1e-12 * fmax(1.0, fabs(t));
  int st = 0;
  mech_current = I;
  for (int j = 0; !st && j < MECH.nfix; j++)
    if (!I->fix_done[j] && MECH.fix_time[j] <= t + tiny) {
      st = zeno(I, t) || fixate(I, t, q, qd, j);
      *changed = 1;
    }
  if (!st && k) {
    double *e = (double *)calloc((size_t)k, sizeof(double));
    st = !e || me_indicators(I, t, I->x, e);
    int due = 0;
    for (int i = 0; !st && i < k; i++) due |= !(e[i] > 0.0);
    free(e);
    if (!st && due) {
      st = zeno(I, t) || handle(I, t, q, qd);
      *changed = 1;
    }
  }
  if (!st && I->nactive > 0) {
    int projected = 0;
    st = MECH.constraints->check_drift(I, t, I->x, &projected);
    *changed |= projected;
  }
  mech_current = NULL;
  if (st && !I->msg[0]) mech_log(I, LOG_ERROR, "the event at t = %.12g could not be handled", t);
  *next_defined = 0;
  for (int j = 0; j < MECH.nfix; j++)
    if (!I->fix_done[j] && MECH.fix_time[j] > t + tiny && (!*next_defined || MECH.fix_time[j] < *next_time)) {
      *next_time = MECH.fix_time[j];
      *next_defined = 1;
    }
  I->valid = 0;
  return st;
}

const MechContactOps mech_contact_ops = {start, step, accel, me_indicators, me_step_done, me_event};
