/* mech_fmu.h: the runtime of an FMU exported by mechdsl (mechdsl.export).

   The model is compiled from CasADi-generated C (model.c: the Functions of
   mechdsl/export/functions.py) and a generated table (model_data.c: sizes, defaults, value
   references, the tolerance rules, the optional units it uses).  The runtime is the same for
   every model:
     mech_runtime.c      instance, values, inputs, model-exchange evaluation, directional derivatives
     mech_cosim.c        co-simulation stepping with crk.c (dense output between calls)
     mech_state.c        FMU state: get, set, serialize
     mech_constraints.c  constrained models: projection, drift, consistent start  (MechConstraintOps)
     mech_hybrid.c       contacts and fixations: events, impacts, the hybrid step (MechContactOps)
     mech_linalg.c       small dense linear algebra (with the two units above)
   An FMU holds only the units its model uses (model_data.c points to their tables); fmi2.c and
   fmi3.c put the FMI 2.0 and 3.0 interfaces on it.  Nothing here needs Python, CasADi or
   mechdsl at run time. */
#ifndef MECH_FMU_H
#define MECH_FMU_H

#include <stddef.h>

typedef long long cint;   /* casadi_int of the generated code */
typedef int (*mech_fn)(const double **arg, double **res, cint *iw, double *w, int mem);
typedef int (*mech_work_fn)(cint *sz_arg, cint *sz_res, cint *sz_iw, cint *sz_w);

typedef struct { mech_fn f; mech_work_fn work; int n_in, n_out; } MechFunction;   /* f NULL: absent */

/* integer settings and statistics, in the order of their value references */
enum { SET_RTOL, SET_ATOL, SET_REST_SPEED, SET_DRIFT_BOUND, SET_PROJECTION_INTERVAL, N_REAL_SETTINGS };
enum { SET_METHOD, SET_IMPACT_ORDER, SET_MAX_STEPS, SET_MAX_EVENTS, N_INT_SETTINGS };
enum { STAT_STEPS, STAT_REJECTED, STAT_RHS, STAT_EVENTS, STAT_PROJECTIONS, N_STATS };

/* The tolerance rules, generated from the simulation layer's own (mechdsl/export/problem.py
   rules): a model's unused rules are 0 */
typedef struct {
  double drift_factor, drift_floor;   /* DAE drift bound max(f atol, floor) (DaeOptions.bound) */
  double offset_factor;               /* contact event offset f atol (ContactRun.offset) */
  double touch_factor, touch_floor;   /* contacts touching: gap <= max(f atol, floor) (ContactRun.touch) */
  double v_eps_factor;                /* normal speeds below f rest_speed are neither approach nor separation */
  double init_tol;                    /* consistent start: feasibility (mechdsl.dae.init) */
  double rank_tol;                    /* independent rows (mechdsl.impacts.contact_system.RANK_TOL) */
  int zeno_events; double zeno_span;  /* Zeno guard of the event loop (ZENO_EVENTS, ZENO_SPAN) */
} MechRules;

struct Instance;

/* mech_constraints.c: models with constraints, contacts or fixations */
typedef struct {
  int (*consistent_start)(struct Instance *I);                 /* dae.init's algorithm on the start values */
  int (*me_step_done)(struct Instance *I, int *enter_event);   /* model exchange: a step done (drift check) */
  int (*me_event_update)(struct Instance *I, int *changed);    /* model exchange: project when drifted */
  int (*check_drift)(struct Instance *I, double t, double *x, int *projected);   /* co-simulation */
} MechConstraintOps;

/* mech_hybrid.c: models with contacts or fixations */
typedef struct {
  int (*start)(struct Instance *I);                            /* fixations due, impacts, contacts at the start */
  int (*step)(struct Instance *I, double t_end);               /* advance to t_end, events inside */
  int (*accel)(struct Instance *I, double t, const double *x, double *qdd, double *lam);   /* with the active rows */
  /* model exchange: per contact the gap (open) or the normal force (closed), plus the event offset */
  int (*indicators)(struct Instance *I, double t, const double *x, double *e);
  int (*me_step_done)(struct Instance *I, int *enter_event);   /* drift of the active rows */
  int (*me_event)(struct Instance *I, int *changed, int *next_defined, double *next_time);  /* impacts, fixations */
} MechContactOps;

typedef struct {
  const char *name;            /* model name (messages) */
  const char *token;           /* the GUID / instantiation token */
  int has_me, has_cs;          /* interfaces exported */
  int n, nu, np, nfree, m, k, nfix, nrows, nout, nint;
  const int *free_index;       /* nfree: position in p of each free parameter */
  const double *p_default;     /* np */
  const double *u_default;     /* nu */
  const int *start_calculated; /* 2n: the start value is an expression in the parameters */
  const int *fixed_q, *fixed_qd;   /* n: start values held by consistent initialization */
  const double *fix_time;      /* nfix */
  const int *base_rows; int nbase;   /* the constraints mech_ode holds */
  const double *int_values;    /* nint: Integer (structural) parameters, constants */
  double real_settings[N_REAL_SETTINGS];
  int int_settings[N_INT_SETTINGS];
  double acc_tol;              /* contact accelerations below this count as zero */
  int samples;                 /* event function samples per step */
  const char *const *param_names;   /* np parameter names */
  const char *const *coords;   /* n coordinate names */
  const char *const *rows;     /* nrows constraint row names (constraints, contacts, fixations) */
  const int *fric_col;         /* k: column of mech_fric of each contact's sliding friction, -1 without */
  MechFunction ode, out, jvp, start, params, dyn, cons, gap, e, fric;
  MechRules rules;
  const MechConstraintOps *constraints;   /* NULL: no constraint rows */
  const MechContactOps *contacts;         /* NULL: no contacts or fixations */
} MechModel;

extern const MechConstraintOps mech_constraint_ops;   /* mech_constraints.c */
extern const MechContactOps mech_contact_ops;         /* mech_hybrid.c */

extern const MechModel MECH;

/* value references: contiguous ranges, in this order */
#define VR_P 0u
#define VR_X ((unsigned)MECH.np)
#define VR_QDD (VR_X + 2u * (unsigned)MECH.n)
#define VR_U (VR_QDD + (unsigned)MECH.n)
#define VR_Y (VR_U + (unsigned)MECH.nu)
#define VR_RSET (VR_Y + (unsigned)MECH.nout)
#define VR_STAT (VR_RSET + N_REAL_SETTINGS)
#define VR_ISET (VR_STAT + N_STATS)
#define VR_INT (VR_ISET + N_INT_SETTINGS)
#define VR_END (VR_INT + (unsigned)MECH.nint)

#define MAX_INPUT_ORDER 3    /* co-simulation: input derivatives up to this order (FMI 2 canInterpolateInputs) */

enum { MODE_INSTANTIATED, MODE_INIT, MODE_CONTINUOUS, MODE_EVENT, MODE_STEP, MODE_TERMINATED, MODE_ERROR };
enum { KIND_ME = 0, KIND_CS = 1 };
enum { LOG_OK = 0, LOG_WARNING = 1, LOG_DISCARD = 2, LOG_ERROR = 3 };

typedef void (*mech_logger)(void *env, int status, const char *category, const char *message);

typedef struct Instance {
  char *name;
  int kind, mode, logging;
  void *env;
  mech_logger log;
  double t, t_start, t_stop, tolerance;
  int tolerance_defined, stop_defined;
  /* values */
  double *p, *free, *x, *u, *y, *lam, *xdot;
  double *u_t0, *u_der;         /* nu; nu x MAX_INPUT_ORDER: input i is u[i] + sum_k u_der[k][i] (t - u_t0[i])^k / k! */
  int u_moving;                 /* some input has derivatives */
  double *u_now;                /* nu: the inputs at the time asked (scratch) */
  int *x_set;                   /* 2n: start value given by the importer */
  double real_settings[N_REAL_SETTINGS];
  int int_settings[N_INT_SETTINGS];
  double stats[N_STATS];
  int valid;                    /* xdot, lam and y are those of the current (t, x, u, p) */
  int started;                  /* initialization done (ExitInitializationMode) */
  /* co-simulation: the reported state (t, x) is interpolated on the stepper's last step, which
     ends at (ti, xi) >= t; `ahead`: that step (dense) is kept; `fi_ok`: its f(ti, xi) is valid */
  double ti, *xi, *dense;
  int ahead, fi_ok;
  /* co-simulation and contacts */
  double h_next, last_ok_time, next_projection;
  int *closed, *fix_done, *active, nactive, use_base, *fix_sel, *ipiv;
  double *anchor, *e;           /* nrows anchors (fixations); k restitution coefficients */
  long burst_count; double burst_time, *recent; int nrecent, irecent;
  /* CasADi call buffers (the largest of every Function) */
  const double **arg; double **res; cint *iw; double *w;
  /* scratch */
  double *work; size_t nwork;
  char msg[1024];
} Instance;

/* crk.c (mechdsl/simulation/backends/crk.c): the compiled stepping loop of mech simulate */
int crk_run_dense(int method, cint nx, const double *grid, cint ngrid, const double *x0, const double *u,
                  const double *p, double rtol, double atol, double hmin, cint max_steps,
                  double *X, double *stats, volatile cint *ctl, double *xfail, double *h_io,
                  double t_limit, const double *f0, double *dense);
int crk_run_events_h(int method, cint nx, const double *grid, cint ngrid, const double *x0, const double *u,
                     const double *p, double rtol, double atol, double hmin, cint max_steps,
                     double *X, double *stats, volatile cint *ctl, double *xfail,
                     void *gap, void *gap_work, cint k, double offset, int samples, const double *gp,
                     void *imp, void *imp_work, const double *rest, const double *limits, double *buf, cint cap,
                     double *h_io);
cint crk_dense_size(cint nx);
const double *crk_dense_state(const double *dense, cint nx);
const double *crk_dense_rhs(const double *dense, cint nx);
void crk_dense_eval(const double *dense, cint nx, double tt, double *out);
enum { CRK_OK = 0, CRK_EVENT = 9, CRK_EVENT_AT_START = 10 };

/* mech_runtime.c */
Instance *mech_new(const char *name, int kind, void *env, mech_logger log, int logging);
void mech_free(Instance *I);
void mech_reset(Instance *I);
void mech_log(Instance *I, int status, const char *fmt, ...);
int mech_call(Instance *I, const MechFunction *f, const double **args, double **res);
int mech_set_real(Instance *I, unsigned vr, double v);
int mech_get_real(Instance *I, unsigned vr, double *v);
int mech_set_int(Instance *I, unsigned vr, int v);
int mech_get_int(Instance *I, unsigned vr, int *v);
int mech_enter_init(Instance *I);
int mech_exit_init(Instance *I);
int mech_evaluate(Instance *I);            /* xdot, lam, y at (t, x, u, p) */
const double *mech_inputs_at(Instance *I, double t);    /* u at t (input derivatives applied) */
int mech_set_input_derivative(Instance *I, unsigned vr, int order, double v);
void mech_rewind(Instance *I);             /* co-simulation: the stepper restarts at (t, x) */
int mech_outputs(Instance *I);
int mech_directional(Instance *I, const unsigned *unknowns, size_t nu, const unsigned *knowns, size_t nk,
                     const double *seed, double *out);
void mech_rtol_atol(Instance *I, double *rtol, double *atol);
double mech_drift_bound(Instance *I);
int mech_me_step_done(Instance *I, int *enter_event);     /* model exchange: a completed step (drift check) */
int mech_me_event_update(Instance *I, int *states_changed, int *next_defined, double *next_time);  /* model exchange: events, projection */
int mech_me_indicators(Instance *I, double *e, size_t ni);   /* model exchange: the event indicators (MECH.k) */
int mech_active_drift(Instance *I, double t, const double *x, double *worst);   /* max residual of the active rows */

/* mech_cosim.c */
typedef struct {                 /* one co-simulation step's stepper settings and crk.c buffers */
  double rtol, atol, interval, tiny;
  int method;
  cint max_steps;
  double *X, *xfail, grid[2], stats[8];
  cint ctl[2];
} MechStepper;
int mech_stepper_begin(Instance *I, double t_end, MechStepper *S);   /* LOG_OK, or LOG_ERROR (memory) */
void mech_stepper_call(MechStepper *S, double t0, double t1);       /* grid, controls and stats of one crk.c call */
void mech_stepper_count(Instance *I, const MechStepper *S);         /* its statistics into the instance's */
void mech_stepper_end(MechStepper *S);
extern _Thread_local Instance *mech_current;   /* the instance crk.c is stepping (its `ode`) */
int mech_cs_start(Instance *I);            /* co-simulation: at the end of initialization */
int mech_cs_step(Instance *I, double t, double h);        /* co-simulation: advance (LOG_OK / LOG_DISCARD / LOG_ERROR) */
const char *mech_crk_message(int status);

/* mech_state.c (0: done; else logged) */
int mech_state_get(Instance *I, void **state);      /* a snapshot into *state (reused when it fits, else replaced) */
int mech_state_set(Instance *I, const void *state);
void mech_state_free(void **state);
size_t mech_state_size(const void *state);
int mech_state_serialize(Instance *I, const void *state, void *bytes, size_t size);
int mech_state_deserialize(Instance *I, const void *bytes, size_t size, void **state);   /* *state replaced */

/* mech_constraints.c (with mech_linalg.c) */
typedef struct { double *M, *bias, *L, *c, *A, *ct, *gam, *zero; } Eval;   /* dyn and cons at a state */
int mech_eval_new(Eval *E);
void mech_eval_free(Eval *E);
int mech_eval_at(Instance *I, double t, const double *q, const double *qd, Eval *E, int dyn, int cons);
double mech_row_dot(const double *A, int nr, int n, int r, const double *v);   /* row r of A (nr x n) . v */
int mech_project(Instance *I, double t, double *q, double *qd, const int *rows, int nr, double tol,
                 const int *one_sided, int no, double one_sided_tol);
int mech_correction_solve(int nr, const double *W, double *Wc, double *b, int *piv);   /* symmetric W x = b */

/* mech_hybrid.c */
int mech_accel_rows(Instance *I, double t, const double *x, const int *rows, int nr, double *qdd, double *lam);

/* mech_linalg.c (column-major) */
int la_cholesky(int n, const double *A, double *L);
void la_chol_solve(int n, const double *L, double *b);
void la_lower_solve(int n, const double *L, double *b);
void la_upper_solve_t(int n, const double *L, double *b);
int la_lu_solve(int n, double *A, double *b, int *piv);
int la_min_norm(int m, int n, const double *A, int lda, const double *b, double *x, double *work);
int la_nnls(int m, int n, double *A, double *b, double *x, double *rnorm, double *w, double *zz, int *index);

#endif
