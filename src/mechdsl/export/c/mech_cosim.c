/* mech_cosim.c: co-simulation stepping of an exported mechdsl model.

   The FMU steps itself with the compiled Runge-Kutta loop of mech simulate (crk.c, dopri5 or
   dop853 with scipy's step control).  crk.c calls the model through the CasADi signature
   `ode`; here `ode` is a dispatcher: the generated mech_ode (the problem's ODE: minimal
   coordinates, or the index-1 ODE of the model's constraints) while only the model's own
   constraints are active, else the constrained accelerations of the active rows (contacts:
   mech_hybrid.c), with the inputs at the stage's time when the importer gave their derivatives.

   Dense output between calls (models without contacts).  A communication step does not end an
   integrator step: the stepper's last step may end past the communication point (up to the
   stop time, or a drift check of a constrained model), the state at the communication point is
   interpolated on its continuous extension (crk_run_dense), and the next communication points
   inside that step are interpolated without stepping.  So the FMU takes the steps of one long
   run of mech simulate, whatever the communication step.  The kept step is dropped (the
   stepper restarts at the communication point) when an input or a parameter changes
   (mech_rewind): FMI allows stepping past a communication point only while the inputs stay as
   they are.  Models with contacts end each communication step on an integrator step (an event
   may lie past the communication point; mech_hybrid.c). */
#include <float.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "mech_fmu.h"

_Thread_local Instance *mech_current;     /* the instance crk.c is stepping (see `ode`) */

/* ------------------------------------------------------------------ crk.c's right-hand side */

int ode(const double **arg, double **res, cint *iw, double *w, int mem) {
  Instance *I = mech_current;
  if (I && I->u_moving) arg[2] = mech_inputs_at(I, *arg[0]);
  if (!I || I->use_base) {
    res[1] = NULL;
    return MECH.ode.f(arg, res, iw, w, mem);
  }
  const int n = MECH.n;
  memcpy(res[0], arg[1] + n, sizeof(double) * (size_t)n);
  return MECH.contacts->accel(I, *arg[0], arg[1], res[0] + n, NULL);
}

int ode_work(cint *sz_arg, cint *sz_res, cint *sz_iw, cint *sz_w) {
  MECH.ode.work(sz_arg, sz_res, sz_iw, sz_w);
  if (*sz_arg < 4) *sz_arg = 4;
  if (*sz_res < 2) *sz_res = 2;
  return 0;
}
int ode_checkout(void) { return 0; }
void ode_release(int mem) { (void)mem; }
void ode_incref(void) {}
void ode_decref(void) {}

const char *mech_crk_message(int status) {
  switch (status) {
    case 1: return "more than mechdsl.max_steps steps in one communication step";
    case 2: return "error control needs a step below the minimum step";
    case 3: return "the required step size is less than the spacing between numbers";
    case 4: return "non-finite state";
    case 6: return "out of memory in the stepping loop";
    case 7: return "the right-hand side returned an error (non-finite or failed evaluation)";
    case 8: return "unknown method";
    default: return "the stepping loop failed";
  }
}

/* ------------------------------------------------------------------ start and steps */

int mech_cs_start(Instance *I) {
  const int nx = 2 * MECH.n;
  int st = 0;
  I->next_projection = I->t + I->real_settings[SET_PROJECTION_INTERVAL];
  I->h_next = 0.0;
  mech_current = I;
  if (MECH.contacts) st = MECH.contacts->start(I);
  else if (MECH.m) {                  /* the rows the problem's ODE holds */
    for (int j = 0; j < MECH.nbase; j++) I->active[j] = MECH.base_rows[j];
    I->nactive = MECH.nbase;
    I->use_base = 1;
  }
  mech_current = NULL;
  I->ti = I->t;
  memcpy(I->xi, I->x, sizeof(double) * (size_t)nx);
  I->ahead = I->fi_ok = 0;
  I->valid = 0;
  return st;
}

int mech_stepper_begin(Instance *I, double t_end, MechStepper *S) {
  const int nx = 2 * MECH.n;
  memset(S, 0, sizeof *S);
  mech_rtol_atol(I, &S->rtol, &S->atol);
  S->method = I->int_settings[SET_METHOD] == 1 ? 0 : 1;
  S->max_steps = I->int_settings[SET_MAX_STEPS] > 0 ? I->int_settings[SET_MAX_STEPS] : 100000;
  S->interval = I->real_settings[SET_PROJECTION_INTERVAL];
  S->tiny = 4 * DBL_EPSILON * fmax(1.0, fabs(t_end));
  S->X = (double *)malloc(sizeof(double) * (size_t)(3 * nx + 1));
  if (!S->X) { mech_log(I, LOG_ERROR, "out of memory"); return LOG_ERROR; }
  S->xfail = S->X + 2 * nx;
  return LOG_OK;
}

void mech_stepper_call(MechStepper *S, double t0, double t1) {
  S->grid[0] = t0; S->grid[1] = t1;
  S->ctl[0] = S->ctl[1] = 0;
  memset(S->stats, 0, sizeof S->stats);
}

void mech_stepper_count(Instance *I, const MechStepper *S) {
  I->stats[STAT_STEPS] += S->stats[0];
  I->stats[STAT_RHS] += S->stats[1];
  I->stats[STAT_REJECTED] += S->stats[2];
}

void mech_stepper_end(MechStepper *S) { free(S->X); S->X = NULL; }

/* models without contacts: the stepper's steps run past t_end (dense output, above) */
static int dense_step(Instance *I, double t_end) {
  const int nx = 2 * MECH.n;
  MechStepper S;
  if (mech_stepper_begin(I, t_end, &S)) return LOG_ERROR;
  const double tiny = S.tiny, interval = S.interval;
  int result = LOG_OK;
  while (I->ti < t_end - tiny) {
    double limit = I->stop_defined && I->t_stop > I->ti + tiny ? I->t_stop : INFINITY;
    if (I->nactive > 0 && interval > 0 && I->next_projection > I->ti + tiny) limit = fmin(limit, I->next_projection);
    mech_stepper_call(&S, I->ti, fmin(t_end, limit));
    int st = crk_run_dense(S.method, nx, S.grid, 2, I->xi, I->u, I->p, S.rtol, S.atol, 0.0, S.max_steps, S.X, S.stats,
                           S.ctl, S.xfail, &I->h_next, limit, I->fi_ok ? crk_dense_rhs(I->dense, nx) : NULL, I->dense);
    mech_stepper_count(I, &S);
    if (st != CRK_OK) {
      mech_log(I, LOG_DISCARD, "the step from t = %.12g to %.12g failed at t = %.12g: %s (rtol %g, atol %g)", I->t,
               t_end, S.stats[3], mech_crk_message(st), S.rtol, S.atol);
      I->ahead = I->fi_ok = 0;          /* the kept step may be overwritten: restart from (ti, xi) */
      result = LOG_DISCARD;
      break;
    }
    I->ti = I->dense[3];
    memcpy(I->xi, crk_dense_state(I->dense, nx), sizeof(double) * (size_t)nx);
    I->ahead = I->fi_ok = 1;
    if (I->nactive > 0) {            /* the drift at the step's end, projected past half the bound */
      int projected = 0;
      if (MECH.constraints->check_drift(I, I->ti, I->xi, &projected)) { result = LOG_ERROR; break; }
      if (projected) I->fi_ok = 0;
      if (interval > 0) while (I->next_projection <= I->ti + tiny) I->next_projection += interval;
    }
  }
  mech_stepper_end(&S);
  if (result != LOG_OK) return result;
  if (I->ahead && t_end < I->ti - tiny) crk_dense_eval(I->dense, nx, t_end, I->x);
  else memcpy(I->x, I->xi, sizeof(double) * (size_t)nx);
  I->t = t_end;
  I->valid = 0;
  return LOG_OK;
}

int mech_cs_step(Instance *I, double t, double h) {
  if (!(h >= 0.0)) {
    mech_log(I, LOG_ERROR, "the communication step size must be >= 0 (got %g)", h);
    return LOG_ERROR;
  }
  if (t > I->t + 1e-9 * (1.0 + fabs(I->t)) || t < I->t - 1e-9 * (1.0 + fabs(I->t))) {
    mech_log(I, LOG_ERROR, "a step from t = %.17g, but the FMU is at t = %.17g", t, I->t);
    return LOG_ERROR;
  }
  I->msg[0] = 0;
  mech_current = I;
  int result;
  if (MECH.contacts) {
    result = MECH.contacts->step(I, t + h);
    I->ti = I->t;
    memcpy(I->xi, I->x, sizeof(double) * (size_t)(2 * MECH.n));
  } else {
    result = dense_step(I, t + h);
  }
  mech_current = NULL;
  if (result == LOG_OK) I->last_ok_time = I->t;
  return result;
}
