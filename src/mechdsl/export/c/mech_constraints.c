/* mech_constraints.c: constrained models (and those with contacts or fixations, whose rows
   join the model's): the M-orthogonal projection onto the active rows (ContactSystem.project:
   Newton steps in the kinetic metric on the positions, then one solve for the speeds), the
   drift of the model's constraints, and the consistent start (the algorithm of
   mechdsl.dae.init: Gauss-Newton with minimum-norm steps in the mass metric on the
   coordinates whose start values are not fixed, then one least-squares solve for the speeds).

   FMU-specific, named here: the problem a run integrates holds the constraints at the
   acceleration level (the index-1 ODE of Model.casadi()); the FMU keeps the drift bounded
   itself, in model exchange by asking for an event when the drift passes half the bound and
   projecting there (me_step_done, me_event_update), in co-simulation by checking after the
   stepper's steps (check_drift), as the DAE back end's "projection" formulation does.  The
   consistent start runs in the FMU because the importer may set start values and parameters. */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "mech_fmu.h"

#define AT(A, lda, i, j) ((A)[(size_t)(j) * (size_t)(lda) + (size_t)(i)])
#define ARGS(...) ((const double *[16]){__VA_ARGS__})
#define RES(...) ((double *[16]){__VA_ARGS__})

/* ------------------------------------------------------------------ evaluations */

void mech_eval_free(Eval *E) { free(E->M); memset(E, 0, sizeof *E); }

int mech_eval_new(Eval *E) {
  const int n = MECH.n, nr = MECH.nrows;
  memset(E, 0, sizeof *E);
  E->M = (double *)calloc((size_t)(3 * n * n + 2 * n + 3 * nr + nr * n + 8), sizeof(double));
  if (!E->M) return 1;
  E->L = E->M + (size_t)n * n; E->bias = E->L + (size_t)n * n; E->c = E->bias + n; E->A = E->c + nr;
  E->ct = E->A + (size_t)nr * n; E->gam = E->ct + nr; E->zero = E->gam + nr;
  return 0;
}

/* dyn (and its Cholesky factor) and cons at (t, q, qd); the anchors of fixed points subtracted */
int mech_eval_at(Instance *I, double t, const double *q, const double *qd, Eval *E, int dyn, int cons) {
  const int nr = MECH.nrows;
  if (!qd) qd = E->zero;
  if (dyn) {
    if (mech_call(I, &MECH.dyn, ARGS(&t, q, qd, mech_inputs_at(I, t), I->p), RES(E->M, E->bias))) return 1;
    if (la_cholesky(MECH.n, E->M, E->L)) return 2;
  }
  if (cons && nr) {
    if (mech_call(I, &MECH.cons, ARGS(&t, q, qd, I->p), RES(E->c, E->A, E->ct, E->gam))) return 1;
    for (int r = MECH.m + MECH.k; r < nr; r++) E->c[r] -= I->anchor[r];
  }
  return 0;
}

double mech_row_dot(const double *A, int nr, int n, int r, const double *v) {
  double s = 0.0;
  for (int j = 0; j < n; j++) s += AT(A, nr, r, j) * v[j];
  return s;
}

/* x = W^-1 b for the (symmetric positive semidefinite) Schur complement W (nr x nr):
   Cholesky, else elimination with pivoting, else the minimum-norm solution */
int mech_correction_solve(int nr, const double *W, double *Wc, double *b, int *piv) {
  if (!la_cholesky(nr, W, Wc)) { la_chol_solve(nr, Wc, b); return 0; }
  double *bb = (double *)malloc(sizeof(double) * (size_t)(2 * nr + 1));
  if (!bb) return 1;
  memcpy(Wc, W, sizeof(double) * (size_t)nr * nr);
  memcpy(bb, b, sizeof(double) * (size_t)nr);
  int st = la_lu_solve(nr, Wc, bb, piv);
  if (st) st = la_min_norm(nr, nr, W, nr, b, bb, NULL);
  if (!st) memcpy(b, bb, sizeof(double) * (size_t)nr);
  free(bb);
  return st;
}

/* dq = M^-1 A_R' (A_R M^-1 A_R')^-1 b for the rows R (the M-orthogonal correction) */
static int correction(Instance *I, const Eval *E, const int *R, int nr_, const double *b, double *dq) {
  const int n = MECH.n, NR = MECH.nrows;
  double *X = (double *)malloc(sizeof(double) * (size_t)(n * nr_ + 2 * nr_ * nr_ + nr_ + 1));
  if (!X) return 1;
  double *W = X + (size_t)n * nr_, *Wc = W + (size_t)nr_ * nr_, *z = Wc + (size_t)nr_ * nr_;
  for (int j = 0; j < nr_; j++) {
    for (int i = 0; i < n; i++) X[(size_t)j * n + i] = AT(E->A, NR, R[j], i);
    la_chol_solve(n, E->L, X + (size_t)j * n);
  }
  for (int i = 0; i < nr_; i++) {
    for (int j = 0; j < nr_; j++) AT(W, nr_, i, j) = mech_row_dot(E->A, NR, n, R[i], X + (size_t)j * n);
    z[i] = b[i];
  }
  int st = mech_correction_solve(nr_, W, Wc, z, I->ipiv);
  for (int i = 0; !st && i < n; i++) {
    double v = 0.0;
    for (int j = 0; j < nr_; j++) v += X[(size_t)j * n + i] * z[j];
    dq[i] = v;
  }
  free(X);
  return st;
}

/* ContactSystem.project: positions onto the rows (Newton steps in the kinetic metric), the
   one-sided rows only where they penetrate below -one_sided_tol, then the speeds */
int mech_project(Instance *I, double t, double *q, double *qd, const int *rows, int nr_, double tol,
                 const int *one_sided, int no, double one_sided_tol) {
  const int n = MECH.n;
  Eval E;
  if (mech_eval_new(&E)) return 1;
  int *use = (int *)malloc(sizeof(int) * (size_t)(nr_ + no + 1));
  double *b = (double *)malloc(sizeof(double) * (size_t)(nr_ + no + n + 1));
  int st = !use || !b;
  double *dq = b ? b + nr_ + no : NULL;
  for (int it = 0; !st && it < 8; it++) {
    if ((st = mech_eval_at(I, t, q, qd, &E, 0, 1))) break;
    int nu = 0;
    double worst = 0.0;
    for (int j = 0; j < nr_; j++) use[nu++] = rows[j];
    for (int j = 0; j < no; j++) if (E.c[one_sided[j]] < -one_sided_tol) use[nu++] = one_sided[j];
    for (int j = 0; j < nu; j++) worst = fmax(worst, fabs(E.c[use[j]]));
    if (nu == 0 || worst <= tol) break;
    if (!isfinite(worst)) { st = 2; break; }
    if ((st = mech_eval_at(I, t, q, qd, &E, 1, 0))) break;
    for (int j = 0; j < nu; j++) b[j] = E.c[use[j]];
    if ((st = correction(I, &E, use, nu, b, dq))) break;
    for (int i = 0; i < n; i++) q[i] -= dq[i];
  }
  if (!st && nr_) {
    st = mech_eval_at(I, t, q, qd, &E, 1, 1);
    for (int j = 0; !st && j < nr_; j++) b[j] = mech_row_dot(E.A, MECH.nrows, n, rows[j], qd) + E.ct[rows[j]];
    if (!st) st = correction(I, &E, rows, nr_, b, dq);
    for (int i = 0; !st && i < n; i++) qd[i] -= dq[i];
  }
  free(use); free(b); mech_eval_free(&E);
  I->valid = 0;
  return st;
}

/* ------------------------------------------------------------------ drift and projection */

/* (max |g|, max |G q' + g_t|) over every model constraint at the current state */
static int drift(Instance *I, double *dq, double *dv) {
  const int n = MECH.n, nr = MECH.nrows, m = MECH.m;
  *dq = *dv = 0.0;
  if (!m) return 0;
  double *c = (double *)malloc(sizeof(double) * (size_t)(3 * nr + nr * n + 1));
  if (!c) return 1;
  double *A = c + nr, *ct = A + (size_t)nr * n, *gam = ct + nr;
  double tt = I->t;
  int st = mech_call(I, &MECH.cons, ARGS(&tt, I->x, I->x + n, I->p), RES(c, A, ct, gam));
  for (int i = 0; !st && i < m; i++) {
    double v = ct[i];
    for (int j = 0; j < n; j++) v += A[(size_t)j * nr + i] * I->x[n + j];
    *dq = fmax(*dq, fabs(c[i]));
    *dv = fmax(*dv, fabs(v));
    if (!isfinite(c[i]) || !isfinite(v)) st = 2;
  }
  free(c);
  return st;
}

static int project_model(Instance *I, double tol) {
  const int n = MECH.n;
  int st = mech_project(I, I->t, I->x, I->x + n, MECH.base_rows, MECH.nbase, tol, NULL, 0, 0.0);
  I->valid = 0;
  if (st) mech_log(I, LOG_ERROR, "projection onto the constraints failed at t = %.17g", I->t);
  else I->stats[STAT_PROJECTIONS] += 1;
  return st;
}

static int me_step_done(Instance *I, int *enter_event) {
  double dq, dv, bound = mech_drift_bound(I);
  if (drift(I, &dq, &dv)) return 1;
  *enter_event = dq > 0.5 * bound || dv > 0.5 * bound;
  return 0;
}

static int me_event_update(Instance *I, int *states_changed) {
  double dq, dv, bound = mech_drift_bound(I);
  if (drift(I, &dq, &dv)) return 1;
  if (dq > 0.5 * bound || dv > 0.5 * bound) {      /* positions, then speeds, back onto the constraints */
    if (project_model(I, 1e-3 * bound)) return 1;
    *states_changed = 1;
  }
  return 0;
}

/* co-simulation: the drift of the active rows at (t, x); past half the bound x is projected
   back (open contacts only where they penetrate) and *projected says so */
int mech_active_drift(Instance *I, double t, const double *x, double *worst) {
  const int n = MECH.n;
  *worst = 0.0;
  if (I->nactive == 0) return 0;
  Eval E;
  if (mech_eval_new(&E)) return 1;
  int st = mech_eval_at(I, t, x, x + n, &E, 0, 1);
  for (int j = 0; !st && j < I->nactive; j++) {
    int r = I->active[j];
    *worst = fmax(*worst, fabs(E.c[r]));
    *worst = fmax(*worst, fabs(mech_row_dot(E.A, MECH.nrows, n, r, x + n) + E.ct[r]));
  }
  mech_eval_free(&E);
  return st;
}

static int check_drift(Instance *I, double t, double *x, int *projected) {
  const int n = MECH.n;
  *projected = 0;
  if (I->nactive == 0) return 0;
  double worst = 0.0, bound = mech_drift_bound(I), rtol, atol;
  mech_rtol_atol(I, &rtol, &atol);
  int st = mech_active_drift(I, t, x, &worst);
  if (!st && !(worst <= 0.5 * bound)) {
    int *open = (int *)calloc((size_t)MECH.k + 1, sizeof(int)), no = 0;
    if (!open) return 1;
    for (int i = 0; i < MECH.k; i++) if (!I->closed[i]) open[no++] = MECH.m + i;
    st = mech_project(I, t, x, x + n, I->active, I->nactive, 1e-3 * bound, open, no,
                      0.5 * MECH.rules.offset_factor * atol);
    free(open);
    I->stats[STAT_PROJECTIONS] += 1;
    *projected = 1;
    if (st) mech_log(I, LOG_ERROR, "projection onto the constraints failed at t = %.12g", t);
  }
  return st;
}

/* ------------------------------------------------------------------ consistent start */

static double row_distance(const double *A, int nr, int n, int i, double r) {
  double s = 0.0;
  for (int j = 0; j < n; j++) s += A[(size_t)j * nr + i] * A[(size_t)j * nr + i];
  return s > 0 ? fabs(r) / sqrt(s) : fabs(r);
}

/* dae.init._initialize, in C: positions by Gauss-Newton with minimum-norm steps in the mass
   metric and backtracking, then the speeds by one minimum-norm solve; start values the
   importer set count as fixed (as --set start values do in mech simulate) */
static int consistent_start(Instance *I) {
  const int n = MECH.n, nr = MECH.nrows, m = MECH.m;
  const size_t need = (size_t)(6 * nr + 3 * nr * n + 2 * n * n + 8 * n + 16);
  double *buf = (double *)calloc(need, sizeof(double));
  int *freeq = (int *)calloc((size_t)(2 * n + 1), sizeof(int));
  if (!buf || !freeq) { free(buf); free(freeq); return 1; }
  double *c = buf, *A = c + nr, *ct = A + (size_t)nr * n, *gam = ct + nr, *M = gam + nr, *bias = M + (size_t)n * n;
  double *d = bias + n, *trial = d + n, *step = trial + n, *y = step + n, *rhs = y + n, *Af = rhs + nr;
  double *c2 = Af + (size_t)nr * n, *A2 = c2 + nr;
  int *freev = freeq + n, nf = 0, nv = 0, st = 0;
  double t = I->t, *q = I->x, *qd = I->x + n;
  for (int i = 0; i < n; i++) {
    if (!MECH.fixed_q[i] && !I->x_set[i]) freeq[nf++] = i;
    if (!MECH.fixed_qd[i] && !I->x_set[n + i]) freev[nv++] = i;
  }
#define CONS(qq, cc, AA) mech_call(I, &MECH.cons, ARGS(&t, qq, qd, I->p), RES(cc, AA, ct, gam))
  if ((st = CONS(q, c, A))) goto fail;
  double scale = 1.0, gnorm;
  for (int i = 0; i < n; i++) scale = fmax(scale, 1.0 + fabs(q[i]));
  if (nf) {
    if ((st = mech_call(I, &MECH.dyn, ARGS(&t, q, qd, mech_inputs_at(I, t), I->p), RES(M, bias)))) goto fail;
    for (int i = 0; i < n; i++) d[i] = 1.0 / sqrt(fmax(fabs(M[(size_t)i * n + i]), 1e-300));
    for (int it = 1; it <= 50; it++) {
      double worst = 0.0;
      for (int i = 0; i < m; i++) worst = fmax(worst, row_distance(A, nr, n, i, c[i]));
      if (worst <= 1e-3 * MECH.rules.init_tol * scale) break;
      for (int j = 0; j < nf; j++)
        for (int i = 0; i < m; i++) Af[(size_t)j * m + i] = A[(size_t)freeq[j] * nr + i] * d[freeq[j]];
      for (int i = 0; i < m; i++) rhs[i] = -c[i];
      if ((st = la_min_norm(m, nf, Af, m, rhs, y, NULL))) goto fail;
      gnorm = 0.0;
      for (int i = 0; i < m; i++) gnorm += c[i] * c[i];
      double lam = 1.0, tn = 0.0;
      int ok = 0;
      for (;;) {
        memcpy(trial, q, sizeof(double) * (size_t)n);
        for (int j = 0; j < nf; j++) trial[freeq[j]] += lam * d[freeq[j]] * y[j];
        ok = !CONS(trial, c2, A2);
        tn = 0.0;
        for (int i = 0; ok && i < m; i++) { tn += c2[i] * c2[i]; if (!isfinite(c2[i])) ok = 0; }
        for (size_t i = 0; ok && i < (size_t)nr * n; i++) if (!isfinite(A2[i])) ok = 0;
        if ((ok && tn < gnorm) || lam < 1e-4) break;
        lam *= 0.5;
      }
      if (!ok) break;
      double moved = 0.0;
      for (int j = 0; j < nf; j++) moved = fmax(moved, fabs(lam * d[freeq[j]] * y[j]));
      memcpy(q, trial, sizeof(double) * (size_t)n);
      memcpy(c, c2, sizeof(double) * (size_t)nr);
      memcpy(A, A2, sizeof(double) * (size_t)nr * n);
      if (moved <= 1e-15 * scale) break;
    }
  }
  if ((st = CONS(q, c, A))) goto fail;
  for (int i = 0; i < m; i++)
    if (row_distance(A, nr, n, i, c[i]) > MECH.rules.init_tol * scale) {
      mech_log(I, LOG_ERROR, "the start values cannot satisfy the constraint '%s' (residual %.3g)%s", MECH.rows[i], c[i],
               nf ? "" : ": every coordinate in it has a fixed start value");
      st = 3;
      goto fail;
    }
  if (nv) {
    if ((st = mech_call(I, &MECH.dyn, ARGS(&t, q, qd, mech_inputs_at(I, t), I->p), RES(M, bias)))) goto fail;
    for (int i = 0; i < n; i++) d[i] = 1.0 / sqrt(fmax(fabs(M[(size_t)i * n + i]), 1e-300));
    for (int i = 0; i < m; i++) {
      double r = ct[i];
      for (int j = 0; j < n; j++) r += A[(size_t)j * nr + i] * qd[j];
      rhs[i] = -r;
    }
    for (int j = 0; j < nv; j++)
      for (int i = 0; i < m; i++) Af[(size_t)j * m + i] = A[(size_t)freev[j] * nr + i] * d[freev[j]];
    if ((st = la_min_norm(m, nv, Af, m, rhs, y, NULL))) goto fail;
    for (int j = 0; j < nv; j++) qd[freev[j]] += d[freev[j]] * y[j];
  }
  {
    double vscale = 1.0;
    for (int i = 0; i < n; i++) vscale = fmax(vscale, 1.0 + fabs(qd[i]));
    for (int i = 0; i < m; i++) {
      double r = ct[i];
      for (int j = 0; j < n; j++) r += A[(size_t)j * nr + i] * qd[j];
      if (row_distance(A, nr, n, i, r) > MECH.rules.init_tol * vscale * 1e2) {
        mech_log(I, LOG_ERROR, "the start speeds violate the velocity form of the constraint '%s' (G q' + g_t = %.3g)",
                 MECH.rows[i], r);
        st = 3;
        goto fail;
      }
    }
  }
#undef CONS
  free(buf); free(freeq);
  I->valid = 0;
  return 0;
fail:
  if (st != 3) mech_log(I, LOG_ERROR, "consistent initialization failed (the constraints cannot be evaluated)");
  free(buf); free(freeq);
  return 1;
}


const MechConstraintOps mech_constraint_ops = {consistent_start, me_step_done, me_event_update, check_drift};
