/* mech_crk.c: crk.c's entry points in the form the FMU runtime calls them.

   crk.c (mechdsl/simulation/backends/crk.c) reaches the model through Fun records (a function
   and its work sizes), so that one library serves every model of `mech simulate`; the FMU's
   right-hand side and event function have CasADi's calling convention (`ode`, mech_cosim.c;
   the contacts' event function, mech_hybrid.c).  These wrappers make the Fun records and call
   the Fun entries: crk_run_dense and crk_run_events_h as mech_fmu.h declares them. */
#include "mech_fmu.h"

typedef struct Fun {             /* crk.c's Fun (the same layout) */
  int (*eval)(const void *ctx, const double **arg, double **res, cint *iw, double *w);
  const void *ctx; void (*init)(const void *ctx, double *w);
  cint sz_arg, sz_res, sz_iw, sz_w;
} Fun;

void crk_fun_casadi(Fun *out, void *fn, void *work);
int crk_fun_run_dense(const Fun *ode, int method, cint nx, const double *grid, cint ngrid, const double *x0,
                      const double *u, const double *p, double rtol, double atol, double hmin, cint max_steps,
                      double *X, double *stats, volatile cint *ctl, double *xfail, double *h_io,
                      double t_limit, const double *f0, double *dense);
int crk_fun_run_events_h(const Fun *ode, int method, cint nx, const double *grid, cint ngrid, const double *x0,
                         const double *u, const double *p, double rtol, double atol, double hmin, cint max_steps,
                         double *X, double *stats, volatile cint *ctl, double *xfail,
                         const Fun *gap, cint k, double offset, int samples, const double *gp,
                         const Fun *imp, const double *rest, const double *limits, double *buf, cint cap,
                         double *h_io);
int ode(const double **arg, double **res, cint *iw, double *w, int mem);
int ode_work(cint *sz_arg, cint *sz_res, cint *sz_iw, cint *sz_w);

int crk_run_dense(int method, cint nx, const double *grid, cint ngrid, const double *x0, const double *u,
                  const double *p, double rtol, double atol, double hmin, cint max_steps,
                  double *X, double *stats, volatile cint *ctl, double *xfail, double *h_io,
                  double t_limit, const double *f0, double *dense) {
  Fun f;
  crk_fun_casadi(&f, (void *)ode, (void *)ode_work);
  return crk_fun_run_dense(&f, method, nx, grid, ngrid, x0, u, p, rtol, atol, hmin, max_steps, X, stats, ctl, xfail,
                           h_io, t_limit, f0, dense);
}

/* limits (with imp): rest_speed, v_eps, touch, rest band (crk.c's impacts in the loop) */
int crk_run_events_h(int method, cint nx, const double *grid, cint ngrid, const double *x0, const double *u,
                     const double *p, double rtol, double atol, double hmin, cint max_steps,
                     double *X, double *stats, volatile cint *ctl, double *xfail,
                     void *gap, void *gap_work, cint k, double offset, int samples, const double *gp,
                     void *imp, void *imp_work, const double *rest, const double *limits, double *buf, cint cap,
                     double *h_io) {
  Fun f, g, i;
  crk_fun_casadi(&f, (void *)ode, (void *)ode_work);
  crk_fun_casadi(&g, gap, gap_work);
  if (imp) crk_fun_casadi(&i, imp, imp_work);
  return crk_fun_run_events_h(&f, method, nx, grid, ngrid, x0, u, p, rtol, atol, hmin, max_steps, X, stats, ctl, xfail,
                              &g, k, offset, samples, gp, imp ? &i : NULL, rest, limits, buf, cap, h_io);
}
