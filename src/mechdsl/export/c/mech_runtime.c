/* mech_runtime.c: one FMU instance of a mechdsl model -- its values and inputs (with their
   derivatives in co-simulation), the evaluation of the formulated ODE and the outputs (model
   exchange), directional derivatives, the start values (expressions in the parameters), and
   the calls into the optional units (constraints, contacts: MECH.constraints, MECH.contacts). */
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "mech_fmu.h"

static void *zalloc(size_t n, size_t size) { return calloc(n ? n : 1, size); }

void mech_log(Instance *I, int status, const char *fmt, ...) {
  va_list ap;
  va_start(ap, fmt);
  vsnprintf(I->msg, sizeof I->msg, fmt, ap);
  va_end(ap);
  if (I->log && (I->logging || status >= LOG_WARNING))
    I->log(I->env, status, status >= LOG_ERROR ? "logStatusError" : "logAll", I->msg);
}

static void grow(cint *have, cint want) { if (want > *have) *have = want; }

static const MechFunction *functions(int i) {
  const MechFunction *all[] = {&MECH.ode, &MECH.out, &MECH.jvp, &MECH.start, &MECH.params, &MECH.dyn,
                               &MECH.cons, &MECH.gap, &MECH.e, &MECH.fric};
  return i < (int)(sizeof all / sizeof all[0]) ? all[i] : NULL;
}

Instance *mech_new(const char *name, int kind, void *env, mech_logger log, int logging) {
  const int n = MECH.n, nr = MECH.nrows, k = MECH.k;
  Instance *I = (Instance *)zalloc(1, sizeof(Instance));
  if (!I) return NULL;
  I->name = (char *)zalloc(strlen(name ? name : "") + 1, 1);
  if (I->name) strcpy(I->name, name ? name : "");
  I->kind = kind; I->env = env; I->log = log; I->logging = logging;
  cint a = 8, r = 8, iw = 1, w = 1;
  for (int i = 0; functions(i); i++) {
    const MechFunction *f = functions(i);
    if (!f->f) continue;
    cint sa = 0, sr = 0, si = 0, sw = 0;
    f->work(&sa, &sr, &si, &sw);
    grow(&a, sa); grow(&r, sr); grow(&iw, si); grow(&w, sw);
  }
  I->arg = (const double **)zalloc((size_t)a, sizeof(double *));
  I->res = (double **)zalloc((size_t)r, sizeof(double *));
  I->iw = (cint *)zalloc((size_t)iw, sizeof(cint));
  I->w = (double *)zalloc((size_t)w, sizeof(double));
  I->p = (double *)zalloc((size_t)MECH.np, sizeof(double));
  I->free = (double *)zalloc((size_t)MECH.nfree, sizeof(double));
  I->x = (double *)zalloc((size_t)(2 * n), sizeof(double));
  I->xdot = (double *)zalloc((size_t)(2 * n), sizeof(double));
  I->u = (double *)zalloc((size_t)MECH.nu, sizeof(double));
  I->y = (double *)zalloc((size_t)MECH.nout, sizeof(double));
  I->lam = (double *)zalloc((size_t)MECH.m, sizeof(double));
  I->x_set = (int *)zalloc((size_t)(2 * n), sizeof(int));
  I->closed = (int *)zalloc((size_t)k, sizeof(int));
  I->fix_done = (int *)zalloc((size_t)MECH.nfix, sizeof(int));
  I->active = (int *)zalloc((size_t)nr, sizeof(int));
  I->fix_sel = (int *)zalloc((size_t)nr, sizeof(int));
  I->anchor = (double *)zalloc((size_t)nr, sizeof(double));
  I->e = (double *)zalloc((size_t)k, sizeof(double));
  I->ipiv = (int *)zalloc((size_t)(nr + n), sizeof(int));
  I->recent = (double *)zalloc((size_t)(MECH.rules.zeno_events > 0 ? MECH.rules.zeno_events : 1), sizeof(double));
  I->u_t0 = (double *)zalloc((size_t)MECH.nu, sizeof(double));
  I->u_der = (double *)zalloc((size_t)(MAX_INPUT_ORDER * MECH.nu), sizeof(double));
  I->u_now = (double *)zalloc((size_t)MECH.nu, sizeof(double));
  I->xi = (double *)zalloc((size_t)(2 * n), sizeof(double));
  I->dense = (double *)zalloc((size_t)crk_dense_size(2 * n), sizeof(double));
  /* the hot scratch of mech_accel_rows and the event function (mech_hybrid.c) */
  I->nwork = (size_t)(4 * n * n + 5 * nr * n + 3 * nr * nr + 8 * (n + nr) + 2 * k + 64);
  I->work = (double *)zalloc(I->nwork, sizeof(double));
  if (!I->name || !I->arg || !I->res || !I->iw || !I->w || !I->p || !I->free || !I->x || !I->xdot || !I->u
      || !I->y || !I->lam || !I->x_set || !I->closed || !I->fix_done || !I->active || !I->fix_sel
      || !I->anchor || !I->e || !I->work || !I->ipiv || !I->recent || !I->u_t0 || !I->u_der || !I->u_now
      || !I->xi || !I->dense) {
    mech_free(I);
    return NULL;
  }
  mech_reset(I);
  return I;
}

void mech_free(Instance *I) {
  if (!I) return;
  free(I->name); free((void *)I->arg); free(I->res); free(I->iw); free(I->w); free(I->p); free(I->free);
  free(I->x); free(I->xdot); free(I->u); free(I->y); free(I->lam); free(I->x_set); free(I->closed);
  free(I->fix_done); free(I->active); free(I->fix_sel); free(I->anchor); free(I->e); free(I->work);
  free(I->ipiv); free(I->recent); free(I->u_t0); free(I->u_der); free(I->u_now); free(I->xi); free(I->dense);
  free(I);
}

int mech_call(Instance *I, const MechFunction *f, const double **args, double **res) {
  for (int i = 0; i < f->n_in; i++) I->arg[i] = args[i];
  for (int i = 0; i < f->n_out; i++) I->res[i] = res[i];
  return f->f(I->arg, I->res, I->iw, I->w, 0);
}

/* argument and result lists of mech_call (read up to the Function's own counts) */
#define ARGS(...) ((const double *[16]){__VA_ARGS__})
#define RES(...) ((double *[16]){__VA_ARGS__})

static int recompute_parameters(Instance *I) {
  if (!MECH.params.f) return 0;
  double *tmp = (double *)malloc(sizeof(double) * (size_t)(MECH.np + 1));
  if (!tmp) return 1;
  int st = mech_call(I, &MECH.params, ARGS(I->free), RES(tmp));
  if (!st) memcpy(I->p, tmp, sizeof(double) * (size_t)MECH.np);
  free(tmp);
  I->valid = 0;
  return st;
}

/* the start values of the states the importer did not set, from the parameters */
static int refresh_start(Instance *I) {
  const int n = MECH.n;
  double *s = (double *)malloc(sizeof(double) * (size_t)(2 * n + 1));
  if (!s) return 1;
  int st = mech_call(I, &MECH.start, ARGS(I->p), RES(s, s + n));
  if (!st)
    for (int i = 0; i < 2 * n; i++) if (!I->x_set[i]) I->x[i] = s[i];
  free(s);
  I->valid = 0;
  return st;
}

void mech_reset(Instance *I) {
  memcpy(I->p, MECH.p_default, sizeof(double) * (size_t)MECH.np);
  for (int j = 0; j < MECH.nfree; j++) I->free[j] = MECH.p_default[MECH.free_index[j]];
  memcpy(I->u, MECH.u_default, sizeof(double) * (size_t)MECH.nu);
  memset(I->u_t0, 0, sizeof(double) * (size_t)MECH.nu);
  memset(I->u_der, 0, sizeof(double) * (size_t)(MAX_INPUT_ORDER * MECH.nu));
  I->u_moving = 0;
  I->ti = 0.0; I->ahead = I->fi_ok = 0;
  memset(I->x_set, 0, sizeof(int) * (size_t)(2 * MECH.n));
  memcpy(I->real_settings, MECH.real_settings, sizeof I->real_settings);
  memcpy(I->int_settings, MECH.int_settings, sizeof I->int_settings);
  memset(I->stats, 0, sizeof I->stats);
  memset(I->closed, 0, sizeof(int) * (size_t)MECH.k);
  memset(I->fix_done, 0, sizeof(int) * (size_t)MECH.nfix);
  memset(I->fix_sel, 0, sizeof(int) * (size_t)MECH.nrows);
  memset(I->anchor, 0, sizeof(double) * (size_t)MECH.nrows);
  I->nactive = 0; I->use_base = 1;
  I->t = I->t_start = 0.0; I->t_stop = 0.0; I->tolerance = 0.0;
  I->tolerance_defined = I->stop_defined = 0;
  I->h_next = 0.0; I->last_ok_time = 0.0; I->next_projection = 0.0;
  I->burst_count = 0; I->burst_time = NAN; I->nrecent = I->irecent = 0;
  I->valid = 0; I->started = 0;
  I->mode = MODE_INSTANTIATED;
  refresh_start(I);
}

/* ------------------------------------------------------------------ inputs */

const double *mech_inputs_at(Instance *I, double t) {
  if (!I->u_moving) return I->u;
  const int nu = MECH.nu;
  for (int i = 0; i < nu; i++) {
    double v = I->u[i], dt = t - I->u_t0[i], term = 1.0;
    for (int k = 0; k < MAX_INPUT_ORDER; k++) {
      term *= dt / (double)(k + 1);
      v += I->u_der[k * nu + i] * term;
    }
    I->u_now[i] = v;
  }
  return I->u_now;
}

static void refresh_moving(Instance *I) {
  I->u_moving = 0;
  for (int j = 0; j < MAX_INPUT_ORDER * MECH.nu; j++) I->u_moving |= I->u_der[j] != 0.0;
}

/* input i restarts at the current time with value v and no derivatives */
static void set_input(Instance *I, int i, double v) {
  int moving = 0;
  for (int k = 0; k < MAX_INPUT_ORDER; k++) { moving |= I->u_der[k * MECH.nu + i] != 0.0; I->u_der[k * MECH.nu + i] = 0.0; }
  if (v == I->u[i] && !moving) return;
  I->u[i] = v; I->u_t0[i] = I->t;
  refresh_moving(I);
  I->valid = 0;
  mech_rewind(I);
}

/* co-simulation (FMI 2 fmi2SetRealInputDerivatives): the order-th derivative of input vr at
   the current time; the input's polynomial is re-based at the current time first */
int mech_set_input_derivative(Instance *I, unsigned vr, int order, double v) {
  const int nu = MECH.nu;
  if (!(vr >= VR_U && vr < VR_Y)) { mech_log(I, LOG_ERROR, "value reference %u is not an input", vr); return 1; }
  if (order < 1 || order > MAX_INPUT_ORDER) {
    mech_log(I, LOG_ERROR, "input derivatives of order %d are not supported (1 to %d)", order, MAX_INPUT_ORDER);
    return 1;
  }
  if (!isfinite(v)) { mech_log(I, LOG_ERROR, "an input derivative must be finite (got %g)", v); return 1; }
  int i = (int)(vr - VR_U);
  if (I->u_t0[i] != I->t) {        /* re-base: the value now, the derivatives of the old polynomial dropped */
    I->u[i] = mech_inputs_at(I, I->t)[i];
    for (int k = 0; k < MAX_INPUT_ORDER; k++) I->u_der[k * nu + i] = 0.0;
    I->u_t0[i] = I->t;
  }
  I->u_der[(order - 1) * nu + i] = v;
  refresh_moving(I);
  I->valid = 0;
  mech_rewind(I);
  return 0;
}

void mech_rewind(Instance *I) {
  if (I->kind != KIND_CS || !I->started) return;
  I->ti = I->t;
  memcpy(I->xi, I->x, sizeof(double) * (size_t)(2 * MECH.n));
  I->ahead = I->fi_ok = 0;
}

static int free_slot(unsigned i) {
  for (int j = 0; j < MECH.nfree; j++) if (MECH.free_index[j] == (int)i) return j;
  return -1;
}

int mech_set_real(Instance *I, unsigned vr, double v) {
  const int n = MECH.n;
  int before_init = I->mode == MODE_INSTANTIATED || I->mode == MODE_INIT;
  if (vr < VR_X) {
    int j = free_slot(vr - VR_P);
    if (j < 0) {
      mech_log(I, LOG_ERROR, "%s is a calculated parameter: set the parameters it is computed from", MECH.param_names[vr - VR_P]);
      return 1;
    }
    if (!before_init && I->free[j] == v) return 0;
    I->free[j] = v;
    if (recompute_parameters(I)) return 1;
    if (before_init) return refresh_start(I);
    mech_rewind(I);
    return 0;
  }
  if (vr < VR_QDD) {
    unsigned i = vr - VR_X;
    if (!before_init) { mech_log(I, LOG_ERROR, "a state is set only before initialization ends"); return 1; }
    if (MECH.start_calculated[i]) {
      mech_log(I, LOG_ERROR, "the start value of %s%s%s is calculated from the parameters (initial = \"calculated\"); "
               "set those parameters instead", i < (unsigned)n ? "" : "der(", MECH.coords[i % (unsigned)n],
               i < (unsigned)n ? "" : ")");
      return 1;
    }
    I->x[i] = v; I->x_set[i] = 1; I->valid = 0;
    return 0;
  }
  if (vr < VR_U) { mech_log(I, LOG_ERROR, "a state derivative cannot be set"); return 1; }
  if (vr < VR_Y) { set_input(I, (int)(vr - VR_U), v); return 0; }
  if (vr < VR_RSET) { mech_log(I, LOG_ERROR, "an output cannot be set"); return 1; }
  if (vr < VR_STAT) {
    if (!before_init) { mech_log(I, LOG_ERROR, "solver settings are fixed parameters: set them before initialization ends"); return 1; }
    if (!(v >= 0.0) || !isfinite(v)) { mech_log(I, LOG_ERROR, "a solver setting must be a finite number >= 0 (got %g)", v); return 1; }
    I->real_settings[vr - VR_RSET] = v;
    return 0;
  }
  mech_log(I, LOG_ERROR, "value reference %u is not a settable Real", vr);
  return 1;
}

int mech_get_real(Instance *I, unsigned vr, double *v) {
  const int n = MECH.n;
  if (vr < VR_X) { *v = I->p[vr]; return 0; }
  if (vr < VR_QDD) {
    if (!I->started && refresh_start(I)) return 1;
    *v = I->x[vr - VR_X];
    return 0;
  }
  if (vr < VR_U) {
    if (mech_evaluate(I)) return 1;
    *v = I->xdot[n + (int)(vr - VR_QDD)];
    return 0;
  }
  if (vr < VR_Y) { *v = mech_inputs_at(I, I->t)[vr - VR_U]; return 0; }
  if (vr < VR_RSET) {
    if (mech_outputs(I)) return 1;
    *v = I->y[vr - VR_Y];
    return 0;
  }
  if (vr < VR_STAT) { *v = I->real_settings[vr - VR_RSET]; return 0; }
  if (vr < VR_ISET) { *v = I->stats[vr - VR_STAT]; return 0; }
  mech_log(I, LOG_ERROR, "value reference %u is not a Real", vr);
  return 1;
}

int mech_set_int(Instance *I, unsigned vr, int v) {
  if (vr >= VR_ISET && vr < VR_INT) {
    if (I->mode != MODE_INSTANTIATED && I->mode != MODE_INIT) {
      mech_log(I, LOG_ERROR, "solver settings are fixed parameters: set them before initialization ends");
      return 1;
    }
    int i = (int)(vr - VR_ISET);
    if ((i == SET_METHOD && (v < 1 || v > 2)) || (i == SET_IMPACT_ORDER && (v < 0 || v > 1)) || v < 0) {
      mech_log(I, LOG_ERROR, "invalid value %d for an integer solver setting (method: 1 dopri5, 2 dop853; "
               "impact order: 0 simultaneous, 1 sequential; counts >= 0)", v);
      return 1;
    }
    I->int_settings[i] = v;
    return 0;
  }
  mech_log(I, LOG_ERROR, "value reference %u is not a settable Integer", vr);
  return 1;
}

int mech_get_int(Instance *I, unsigned vr, int *v) {
  if (vr >= VR_ISET && vr < VR_INT) { *v = I->int_settings[vr - VR_ISET]; return 0; }
  if (vr >= VR_INT && vr < VR_END) { *v = (int)MECH.int_values[vr - VR_INT]; return 0; }
  mech_log(I, LOG_ERROR, "value reference %u is not an Integer", vr);
  return 1;
}

void mech_rtol_atol(Instance *I, double *rtol, double *atol) {
  double r = I->real_settings[SET_RTOL], a = I->real_settings[SET_ATOL];
  if (I->tolerance_defined && I->tolerance > 0 && r > 0) {   /* the importer's tolerance: rtol, atol in proportion */
    a *= I->tolerance / r;
    r = I->tolerance;
  }
  *rtol = r; *atol = a;
}

double mech_drift_bound(Instance *I) {
  double b = I->real_settings[SET_DRIFT_BOUND];
  if (b > 0) return b;
  double rtol, atol;
  mech_rtol_atol(I, &rtol, &atol);
  if (I->kind == KIND_ME) atol = I->tolerance_defined && I->tolerance > 0 ? I->tolerance : atol;
  return fmax(MECH.rules.drift_factor * atol, MECH.rules.drift_floor);      /* DaeOptions.bound */
}

int mech_enter_init(Instance *I) {
  I->mode = MODE_INIT;
  return refresh_start(I);
}

int mech_exit_init(Instance *I) {
  if (refresh_start(I)) return 1;
  if (MECH.k && mech_call(I, &MECH.e, ARGS(I->p), RES(I->e))) {
    mech_log(I, LOG_ERROR, "the coefficients of restitution cannot be evaluated");
    return 1;
  }
  for (int i = 0; i < MECH.k; i++)
    if (!(I->e[i] >= 0.0 && I->e[i] <= 1.0)) {
      mech_log(I, LOG_ERROR, "coefficient of restitution of '%s' must be in [0, 1] (got %g)", MECH.rows[MECH.m + i], I->e[i]);
      return 1;
    }
  if (MECH.m && MECH.constraints->consistent_start(I)) return 1;
  I->started = 1;
  I->valid = 0;
  I->last_ok_time = I->t;
  if (I->kind == KIND_CS && mech_cs_start(I)) return 1;
  if (I->kind == KIND_ME && MECH.contacts) {       /* impacts, contacts and fixations at the start */
    mech_current = I;
    int st = MECH.contacts->start(I);
    mech_current = NULL;
    I->valid = 0;
    if (st) return 1;
  }
  return 0;
}

int mech_evaluate(Instance *I) {
  if (I->valid) return 0;
  if (!I->started && refresh_start(I)) return 1;
  const int n = MECH.n;
  int st;
  if ((I->kind == KIND_CS || MECH.contacts) && !I->use_base) {
    memcpy(I->xdot, I->x + n, sizeof(double) * (size_t)n);
    st = MECH.contacts->accel(I, I->t, I->x, I->xdot + n, I->lam);
  } else {
    double tt = I->t;
    st = mech_call(I, &MECH.ode, ARGS(&tt, I->x, mech_inputs_at(I, tt), I->p), RES(I->xdot, I->lam));
  }
  for (int i = 0; !st && i < 2 * n; i++) if (!isfinite(I->xdot[i])) st = 2;
  if (st) {
    mech_log(I, LOG_ERROR, "the equations of motion cannot be evaluated at t = %.17g (%s)", I->t,
             st == 2 ? "non-finite accelerations: a singular mass matrix or constraint Jacobian?" : "evaluation failed");
    return 1;
  }
  I->valid = 1;
  return 0;
}

int mech_outputs(Instance *I) {
  if (MECH.nout == 0) return 0;
  if (mech_evaluate(I)) return 1;
  double tt = I->t;
  return mech_call(I, &MECH.out, ARGS(&tt, I->x, mech_inputs_at(I, tt), I->p, I->lam), RES(I->y));
}

int mech_directional(Instance *I, const unsigned *unknowns, size_t nun, const unsigned *knowns, size_t nk,
                     const double *seed, double *out) {
  const int n = MECH.n;
  double *dx = (double *)zalloc((size_t)(4 * n + 2 * MECH.nu + MECH.nout + 1), sizeof(double));
  if (!dx) return 1;
  double *du = dx + 2 * n, *dxdot = du + MECH.nu, *dy = dxdot + 2 * n;
  int st = 0;
  for (size_t j = 0; j < nk && !st; j++) {
    unsigned vr = knowns[j];
    if (vr >= VR_X && vr < VR_QDD) dx[vr - VR_X] += seed[j];
    else if (vr >= VR_U && vr < VR_Y) du[vr - VR_U] += seed[j];
    else { mech_log(I, LOG_ERROR, "directional derivatives: value reference %u is not a state or an input", vr); st = 1; }
  }
  if (!st && !I->started) st = refresh_start(I);
  if (!st) {
    double tt = I->t;
    st = mech_call(I, &MECH.jvp, ARGS(&tt, I->x, mech_inputs_at(I, tt), I->p, dx, du), RES(dxdot, dy));
  }
  for (size_t i = 0; i < nun && !st; i++) {
    unsigned vr = unknowns[i];
    if (vr >= VR_X + (unsigned)n && vr < VR_QDD) out[i] = dxdot[vr - VR_X - (unsigned)n];   /* der(q) = q' */
    else if (vr >= VR_QDD && vr < VR_U) out[i] = dxdot[n + (int)(vr - VR_QDD)];
    else if (vr >= VR_Y && vr < VR_RSET) out[i] = dy[vr - VR_Y];
    else { mech_log(I, LOG_ERROR, "directional derivatives: value reference %u is not a derivative or an output", vr); st = 1; }
  }
  free(dx);
  return st;
}

/* ----------------------------------------------------------------- model exchange of constrained models */

int mech_me_step_done(Instance *I, int *enter_event) {
  *enter_event = 0;
  I->stats[STAT_STEPS] += 1;
  if (MECH.contacts) return MECH.contacts->me_step_done(I, enter_event);
  return MECH.m ? MECH.constraints->me_step_done(I, enter_event) : 0;
}

int mech_me_event_update(Instance *I, int *states_changed, int *next_defined, double *next_time) {
  *states_changed = *next_defined = 0;
  *next_time = 0.0;
  if (MECH.contacts) return MECH.contacts->me_event(I, states_changed, next_defined, next_time);
  return MECH.m ? MECH.constraints->me_event_update(I, states_changed) : 0;
}

int mech_me_indicators(Instance *I, double *e, size_t ni) {
  if (ni == 0) return 0;
  if (mech_evaluate(I)) return 1;                 /* started, and the equations can be evaluated */
  return MECH.contacts->indicators(I, I->t, I->x, e);
}
