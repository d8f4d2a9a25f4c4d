/* mech_fmu.h: the runtime of an FMU exported by mechdsl (mechdsl.export).

   The model is compiled from CasADi-generated C (model.c: the Functions of
   mechdsl/export/functions.py) and a generated table (model_data.c: sizes, defaults, value
   references).  This runtime (mech_runtime.c: instance, values, model exchange, start;
   mech_hybrid.c: co-simulation stepping with crk.c, constraints, contacts, impacts;
   mech_linalg.c: small dense linear algebra) is the same for every model; fmi2.c and
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
} MechModel;

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

#define ZENO_EVENTS 500      /* impacts/run.py: this many events within ZENO_SPAN of the run: Zeno */
#define ZENO_SPAN 1e-6

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
  int *x_set;                   /* 2n: start value given by the importer */
  double real_settings[N_REAL_SETTINGS];
  int int_settings[N_INT_SETTINGS];
  double stats[N_STATS];
  int valid;                    /* xdot, lam and y are those of the current (t, x, u, p) */
  int started;                  /* initialization done (ExitInitializationMode) */
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
int mech_outputs(Instance *I);
int mech_directional(Instance *I, const unsigned *unknowns, size_t nu, const unsigned *knowns, size_t nk,
                     const double *seed, double *out);
void mech_rtol_atol(Instance *I, double *rtol, double *atol);
double mech_drift_bound(Instance *I);
int mech_drift(Instance *I, double *dq, double *dv);
int mech_project_model(Instance *I, double tol);
int mech_consistent_start(Instance *I);
int mech_me_step_done(Instance *I, int *enter_event);     /* model exchange: a completed step (drift check) */
int mech_me_event_update(Instance *I, int *states_changed);   /* model exchange: project when drifted */
int mech_cs_step(Instance *I, double t, double h);        /* co-simulation: checks, then mech_do_step */

/* mech_hybrid.c */
int mech_hybrid_start(Instance *I);        /* co-simulation: fixations due, impacts and contacts at the start */
int mech_do_step(Instance *I, double t_end);   /* co-simulation: advance to t_end (LOG_OK / LOG_DISCARD / LOG_ERROR) */
int mech_accel_rows(Instance *I, double t, const double *x, const int *rows, int nr, double *qdd, double *lam);
int mech_independent(Instance *I, double t, const double *q, const int *cand, int nc, int *out);
int mech_project(Instance *I, double t, double *q, double *qd, const int *rows, int nr, double tol,
                 const int *one_sided, int no, double one_sided_tol);
void mech_lambda_model(Instance *I, const double *lamr);   /* I->lam from the active rows' multipliers */

/* mech_linalg.c (column-major) */
int la_cholesky(int n, const double *A, double *L);
void la_chol_solve(int n, const double *L, double *b);
void la_lower_solve(int n, const double *L, double *b);
void la_upper_solve_t(int n, const double *L, double *b);
int la_lu_solve(int n, double *A, double *b, int *piv);
int la_min_norm(int m, int n, const double *A, int lda, const double *b, double *x, double *work);
int la_nnls(int m, int n, double *A, double *b, double *x, double *rnorm, double *w, double *zz, int *index);

#endif
