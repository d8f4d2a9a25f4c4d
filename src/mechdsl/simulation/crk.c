/* crk.c: a compiled explicit Runge-Kutta loop for mechdsl (mechdsl.simulation.crk).

   Linked with the CasADi-generated C of a model's right-hand side `ode(t, x, u, p) -> xdot`
   into one shared library, so a whole run is one C call.  Two methods, both with the step-size
   control, initial step, error norms and dense output of scipy.integrate's RK45 and DOP853
   (Hairer, Norsett, Wanner, Solving ODEs I, II.4-II.6; coefficients copied from scipy 1.17,
   scipy/integrate/_ivp/rk.py and dop853_coefficients.py, BSD licence), so that for the same
   right-hand side both take the same steps as scipy up to round-off:

     method 0 "dopri5": Dormand-Prince 5(4), FSAL, 4th-order continuous extension;
     method 1 "dop853": Dormand-Prince 8(5,3), FSAL, 7th-order continuous extension (3 extra
                        stages, evaluated only for steps that pass an output time).

   Output: the states on the increasing output grid (row-major, ngrid x nx), filled from the
   continuous extension of each step that passes an output time.  Nothing is printed; the
   progress word ctl[0] (output rows written) is updated as the run goes, a nonzero ctl[1]
   stops the run (status CRK_CANCELLED).  Reentrant: all state is local, the model's CasADi
   memory is checked out per call. */
#include <math.h>
#include <stdlib.h>
#include <string.h>

typedef long long cint;   /* casadi_int of the generated code */

extern int ode(const double **arg, double **res, cint *iw, double *w, int mem);
extern int ode_work(cint *sz_arg, cint *sz_res, cint *sz_iw, cint *sz_w);
extern int ode_checkout(void);
extern void ode_release(int mem);
extern void ode_incref(void);
extern void ode_decref(void);

enum { CRK_OK = 0, CRK_MAX_STEPS = 1, CRK_HMIN = 2, CRK_TOO_SMALL = 3, CRK_NONFINITE = 4,
       CRK_CANCELLED = 5, CRK_NOMEM = 6, CRK_RHS_ERROR = 7, CRK_BAD_METHOD = 8 };

static const double P5_A[6 * 5] = {
    0.0, 0.0, 0.0,
    0.0, 0.0, 0.2,
    0.0, 0.0, 0.0,
    0.0, 0.075, 0.225,
    0.0, 0.0, 0.0,
    0.9777777777777777, -3.7333333333333334, 3.5555555555555554,
    0.0, 0.0, 2.9525986892242035,
    -11.595793324188385, 9.822892851699436, -0.2908093278463649,
    0.0, 2.8462752525252526, -10.757575757575758,
    8.906422717743473, 0.2784090909090909, -0.2735313036020583};
static const double P5_B[6] = {
    0.09114583333333333, 0.0, 0.44923629829290207,
    0.6510416666666666, -0.322376179245283, 0.13095238095238096};
static const double P5_C[6] = {
    0.0, 0.2, 0.3,
    0.8, 0.8888888888888888, 1.0};
static const double P5_E[7] = {
    -0.0012326388888888888, 0.0, 0.0042527702905061394,
    -0.03697916666666667, 0.05086379716981132, -0.0419047619047619,
    0.025};
static const double P5_P[7 * 4] = {
    1.0, -2.8535800653862835, 3.0717434641059005,
    -1.1270175653862835, 0.0, 0.0,
    0.0, 0.0, 0.0,
    4.023133379230305, -6.249321565289, 2.675424484351598,
    0.0, -3.7324019615885042, 10.068970589843675,
    -5.685526961588504, 0.0, 2.5548038301849423,
    -6.399112377351017, 3.5219323679207912, 0.0,
    -1.3744241142186024, 3.272657752246729, -1.7672812570757455,
    0.0, 1.3824689317781436, -3.764937863556287,
    2.382468931778144};
static const double P8_A[16 * 16] = {
    0.0, 0.0, 0.0,
    0.0, 0.0, 0.0,
    0.0, 0.0, 0.0,
    0.0, 0.0, 0.0,
    0.0, 0.0, 0.0,
    0.0, 0.05260015195876773, 0.0,
    0.0, 0.0, 0.0,
    0.0, 0.0, 0.0,
    0.0, 0.0, 0.0,
    0.0, 0.0, 0.0,
    0.0, 0.0, 0.0197250569845379,
    0.0591751709536137, 0.0, 0.0,
    0.0, 0.0, 0.0,
    0.0, 0.0, 0.0,
    0.0, 0.0, 0.0,
    0.0, 0.0, 0.0,
    0.02958758547680685, 0.0, 0.08876275643042054,
    0.0, 0.0, 0.0,
    0.0, 0.0, 0.0,
    0.0, 0.0, 0.0,
    0.0, 0.0, 0.0,
    0.0, 0.2413651341592667, 0.0,
    -0.8845494793282861, 0.924834003261792, 0.0,
    0.0, 0.0, 0.0,
    0.0, 0.0, 0.0,
    0.0, 0.0, 0.0,
    0.0, 0.0, 0.037037037037037035,
    0.0, 0.0, 0.17082860872947386,
    0.12546768756682242, 0.0, 0.0,
    0.0, 0.0, 0.0,
    0.0, 0.0, 0.0,
    0.0, 0.0, 0.0,
    0.037109375, 0.0, 0.0,
    0.17025221101954405, 0.06021653898045596, -0.017578125,
    0.0, 0.0, 0.0,
    0.0, 0.0, 0.0,
    0.0, 0.0, 0.0,
    0.0, 0.03709200011850479, 0.0,
    0.0, 0.17038392571223998, 0.10726203044637328,
    -0.015319437748624402, 0.008273789163814023, 0.0,
    0.0, 0.0, 0.0,
    0.0, 0.0, 0.0,
    0.0, 0.0, 0.6241109587160757,
    0.0, 0.0, -3.3608926294469414,
    -0.868219346841726, 27.59209969944671, 20.154067550477894,
    -43.48988418106996, 0.0, 0.0,
    0.0, 0.0, 0.0,
    0.0, 0.0, 0.0,
    0.47766253643826434, 0.0, 0.0,
    -2.4881146199716677, -0.590290826836843, 21.230051448181193,
    15.279233632882423, -33.28821096898486, -0.020331201708508627,
    0.0, 0.0, 0.0,
    0.0, 0.0, 0.0,
    0.0, -0.9371424300859873, 0.0,
    0.0, 5.186372428844064, 1.0914373489967295,
    -8.149787010746927, -18.52006565999696, 22.739487099350505,
    2.4936055526796523, -3.0467644718982196, 0.0,
    0.0, 0.0, 0.0,
    0.0, 0.0, 2.273310147516538,
    0.0, 0.0, -10.53449546673725,
    -2.0008720582248625, -17.9589318631188, 27.94888452941996,
    -2.8589982771350235, -8.87285693353063, 12.360567175794303,
    0.6433927460157636, 0.0, 0.0,
    0.0, 0.0, 0.0,
    0.054293734116568765, 0.0, 0.0,
    0.0, 0.0, 4.450312892752409,
    1.8915178993145003, -5.801203960010585, 0.3111643669578199,
    -0.1521609496625161, 0.20136540080403034, 0.04471061572777259,
    0.0, 0.0, 0.0,
    0.0, 0.056167502283047954, 0.0,
    0.0, 0.0, 0.0,
    0.0, 0.25350021021662483, -0.2462390374708025,
    -0.12419142326381637, 0.15329179827876568, 0.00820105229563469,
    0.007567897660545699, -0.008298, 0.0,
    0.0, 0.0, 0.03183464816350214,
    0.0, 0.0, 0.0,
    0.0, 0.028300909672366776, 0.053541988307438566,
    -0.05492374857139099, 0.0, 0.0,
    -0.00010834732869724932, 0.0003825710908356584, -0.00034046500868740456,
    0.1413124436746325, 0.0, 0.0,
    -0.42889630158379194, 0.0, 0.0,
    0.0, 0.0, -4.697621415361164,
    7.683421196062599, 4.06898981839711, 0.3567271874552811,
    0.0, 0.0, 0.0,
    -0.0013990241651590145, 2.9475147891527724, -9.15095847217987,
    0.0};
static const double P8_B[12] = {
    0.054293734116568765, 0.0, 0.0,
    0.0, 0.0, 4.450312892752409,
    1.8915178993145003, -5.801203960010585, 0.3111643669578199,
    -0.1521609496625161, 0.20136540080403034, 0.04471061572777259};
static const double P8_C[16] = {
    0.0, 0.05260015195876773, 0.0789002279381516,
    0.1183503419072274, 0.2816496580927726, 0.3333333333333333,
    0.25, 0.3076923076923077, 0.6512820512820513,
    0.6, 0.8571428571428571, 1.0,
    1.0, 0.1, 0.2,
    0.7777777777777778};
static const double P8_E3[13] = {
    -0.18980075407240762, 0.0, 0.0,
    0.0, 0.0, 4.450312892752409,
    1.8915178993145003, -5.801203960010585, -0.4226823213237919,
    -0.1521609496625161, 0.20136540080403034, 0.02265179219836082,
    0.0};
static const double P8_E5[13] = {
    0.01312004499419488, 0.0, 0.0,
    0.0, 0.0, -1.2251564463762044,
    -0.4957589496572502, 1.6643771824549864, -0.35032884874997366,
    0.3341791187130175, 0.08192320648511571, -0.022355307863886294,
    0.0};
static const double P8_D[4 * 16] = {
    -8.428938276109013, 0.0, 0.0,
    0.0, 0.0, 0.5667149535193777,
    -3.0689499459498917, 2.38466765651207, 2.117034582445028,
    -0.871391583777973, 2.2404374302607883, 0.6315787787694688,
    -0.08899033645133331, 18.148505520854727, -9.194632392478356,
    -4.436036387594894, 10.427508642579134, 0.0,
    0.0, 0.0, 0.0,
    242.28349177525817, 165.20045171727028, -374.5467547226902,
    -22.113666853125306, 7.733432668472264, -30.674084731089398,
    -9.332130526430229, 15.697238121770845, -31.139403219565178,
    -9.35292435884448, 35.81684148639408, 19.985053242002433,
    0.0, 0.0, 0.0,
    0.0, -387.0373087493518, -189.17813819516758,
    527.8081592054236, -11.57390253995963, 6.8812326946963,
    -1.0006050966910838, 0.7777137798053443, -2.778205752353508,
    -60.19669523126412, 84.32040550667716, 11.99229113618279,
    -25.69393346270375, 0.0, 0.0,
    0.0, 0.0, -154.18974869023643,
    -231.5293791760455, 357.6391179106141, 93.40532418362432,
    -37.45832313645163, 104.0996495089623, 29.8402934266605,
    -43.53345659001114, 96.32455395918828, -39.17726167561544,
    -149.72683625798564};

#define SAFETY 0.9
#define MIN_FACTOR 0.2
#define MAX_FACTOR 10.0

typedef struct {
  const double **arg; double **res; cint *iw; double *w; int mem;
  double t; const double *u, *p; cint nfev;
} Rhs;

static int rhs(Rhs *r, double t, const double *x, double *f) {
  r->t = t;
  r->arg[0] = &r->t; r->arg[1] = x; r->arg[2] = r->u; r->arg[3] = r->p;
  r->res[0] = f;
  r->nfev++;
  return ode(r->arg, r->res, r->iw, r->w, r->mem);
}

typedef struct {
  int stages;           /* stages of one step, without the FSAL stage */
  int extended;         /* stages including the dense-output ones */
  const double *A; int lda;
  const double *B, *C;
  int err_order;        /* order of the error estimator */
} Tableau;

static double rms(const double *v, const double *scale, cint n) {
  double s = 0.0;
  for (cint i = 0; i < n; i++) { double e = v[i] / scale[i]; s += e * e; }
  return sqrt(s / (double)n);
}

/* y + h * sum_{j<s} a[j] K_j into out (scipy: dy = (K[:s].T @ a[:s]) * h) */
static void combine(const double *y, const double *K, const double *a, int s, double h, cint n, double *out) {
  for (cint i = 0; i < n; i++) {
    double d = 0.0;
    for (int j = 0; j < s; j++) d += K[(cint)j * n + i] * a[j];
    out[i] = y[i] + d * h;
  }
}

static double error_norm(int method, const double *K, double h, const double *scale, cint n) {
  if (method == 0) {
    double s = 0.0;
    for (cint i = 0; i < n; i++) {
      double e = 0.0;
      for (int j = 0; j < 7; j++) e += K[(cint)j * n + i] * P5_E[j];
      e = e * h / scale[i];
      s += e * e;
    }
    return sqrt(s / (double)n);
  }
  double s5 = 0.0, s3 = 0.0;
  for (cint i = 0; i < n; i++) {
    double e5 = 0.0, e3 = 0.0;
    for (int j = 0; j < 13; j++) { e5 += K[(cint)j * n + i] * P8_E5[j]; e3 += K[(cint)j * n + i] * P8_E3[j]; }
    e5 /= scale[i]; e3 /= scale[i];
    s5 += e5 * e5; s3 += e3 * e3;
  }
  if (s5 == 0.0 && s3 == 0.0) return 0.0;
  return fabs(h) * s5 / sqrt((s5 + 0.01 * s3) * (double)n);
}

int crk_run(int method, cint nx, const double *grid, cint ngrid, const double *x0, const double *u,
            const double *p, double rtol, double atol, double hmin, cint max_steps,
            double *X, double *stats, volatile cint *ctl, double *xfail) {
  Tableau tab;
  if (method == 0) { Tableau t = {6, 7, P5_A, 5, P5_B, P5_C, 4}; tab = t; }
  else if (method == 1) { Tableau t = {12, 16, P8_A, 16, P8_B, P8_C, 7}; tab = t; }
  else return CRK_BAD_METHOD;
  const cint n = nx;
  const int S = tab.stages;
  cint sz_arg = 0, sz_res = 0, sz_iw = 0, sz_w = 0;
  ode_work(&sz_arg, &sz_res, &sz_iw, &sz_w);
  if (sz_arg < 4) sz_arg = 4;
  if (sz_res < 1) sz_res = 1;
  Rhs r;
  r.arg = (const double **)calloc((size_t)sz_arg, sizeof(double *));
  r.res = (double **)calloc((size_t)sz_res, sizeof(double *));
  r.iw = (cint *)calloc((size_t)(sz_iw > 0 ? sz_iw : 1), sizeof(cint));
  r.w = (double *)calloc((size_t)(sz_w > 0 ? sz_w : 1), sizeof(double));
  double *mem = (double *)calloc((size_t)(n * (tab.extended + 6 + 7) + 1), sizeof(double));
  int status = CRK_OK;
  cint steps = 0, rejected = 0, k = 1, steps_here = 0;
  double t = grid[0];
  if (!r.arg || !r.res || !r.iw || !r.w || !mem) {
    free(r.arg); free(r.res); free(r.iw); free(r.w); free(mem);
    return CRK_NOMEM;
  }
  ode_incref();
  r.mem = ode_checkout();
  r.u = u; r.p = p; r.nfev = 0;
  double *K = mem;                               /* extended x n stages */
  double *y = K + (cint)tab.extended * n, *ynew = y + n, *f = ynew + n, *yold = f + n;
  double *scale = yold + n, *tmp = scale + n, *F = tmp + n;   /* F: 7 x n for DOP853 dense output */
  (void)F;
  const double tb = grid[ngrid - 1];
  const double expo = -1.0 / (tab.err_order + 1.0);
  memcpy(y, x0, (size_t)n * sizeof(double));
  memcpy(X, x0, (size_t)n * sizeof(double));
  ctl[0] = 1;
  if (rhs(&r, t, y, f)) { status = CRK_RHS_ERROR; goto done; }
  /* initial step: scipy.integrate._ivp.common.select_initial_step */
  double h_abs;
  {
    double interval = fabs(tb - t), d0, d1, d2, h0, h1;
    for (cint i = 0; i < n; i++) scale[i] = atol + fabs(y[i]) * rtol;
    d0 = rms(y, scale, n); d1 = rms(f, scale, n);
    h0 = (d0 < 1e-5 || d1 < 1e-5) ? 1e-6 : 0.01 * d0 / d1;
    if (h0 > interval) h0 = interval;
    for (cint i = 0; i < n; i++) tmp[i] = y[i] + h0 * f[i];
    if (rhs(&r, t + h0, tmp, ynew)) { status = CRK_RHS_ERROR; goto done; }
    for (cint i = 0; i < n; i++) ynew[i] -= f[i];
    d2 = rms(ynew, scale, n) / h0;
    if (d1 <= 1e-15 && d2 <= 1e-15) h1 = fmax(1e-6, h0 * 1e-3);
    else h1 = pow(0.01 / fmax(d1, d2), 1.0 / (tab.err_order + 1.0));
    h_abs = fmin(fmin(100 * h0, h1), interval);
  }
  while (k < ngrid) {
    if (ctl[1]) { status = CRK_CANCELLED; break; }
    double min_step = 10 * fabs(nextafter(t, INFINITY) - t);
    if (h_abs < min_step) h_abs = min_step;
    int accepted = 0, was_rejected = 0;
    double h = 0.0, t_new = t;
    while (!accepted) {
      if (h_abs < min_step) { status = CRK_TOO_SMALL; goto done; }
      if (hmin > 0 && h_abs < hmin && t + hmin < tb) {
        /* hmin bounds the step from below: a proposal under it (the initial step's heuristic,
           a growth step) is raised to it; error control rejecting a step down below it fails */
        if (was_rejected) { status = CRK_HMIN; goto done; }
        h_abs = hmin;
      }
      h = h_abs;
      t_new = t + h;
      if (t_new > tb) t_new = tb;
      h = t_new - t;
      h_abs = fabs(h);
      memcpy(K, f, (size_t)n * sizeof(double));
      for (int s = 1; s < S; s++) {
        combine(y, K, tab.A + (cint)s * tab.lda, s, h, n, tmp);
        if (rhs(&r, t + tab.C[s] * h, tmp, K + (cint)s * n)) { status = CRK_RHS_ERROR; goto done; }
      }
      combine(y, K, tab.B, S, h, n, ynew);
      if (rhs(&r, t + h, ynew, K + (cint)S * n)) { status = CRK_RHS_ERROR; goto done; }
      for (cint i = 0; i < n; i++) scale[i] = atol + fmax(fabs(y[i]), fabs(ynew[i])) * rtol;
      double en = error_norm(method, K, h, scale, n);
      if (en < 1.0) {
        double factor = en == 0.0 ? MAX_FACTOR : fmin(MAX_FACTOR, SAFETY * pow(en, expo));
        if (was_rejected && factor > 1.0) factor = 1.0;
        h_abs *= factor;
        accepted = 1;
      } else {
        h_abs *= fmax(MIN_FACTOR, SAFETY * pow(en, expo));   /* fmax ignores a NaN norm, as scipy */
        was_rejected = 1;
        rejected++;
      }
    }
    double t_old = t;
    memcpy(yold, y, (size_t)n * sizeof(double));
    memcpy(y, ynew, (size_t)n * sizeof(double));
    memcpy(f, K + (cint)S * n, (size_t)n * sizeof(double));
    t = t_new;
    steps++; steps_here++;
    int finite = 1;
    for (cint i = 0; i < n; i++) if (!isfinite(y[i])) { finite = 0; break; }
    if (!finite) { status = CRK_NONFINITE; goto done; }
    if (k < ngrid && grid[k] <= t) {
      if (method == 1) {   /* the three extra stages and the interpolant's coefficients F */
        for (int s = S + 1; s < tab.extended; s++) {
          combine(yold, K, tab.A + (cint)s * tab.lda, s, h, n, tmp);
          if (rhs(&r, t_old + tab.C[s] * h, tmp, K + (cint)s * n)) { status = CRK_RHS_ERROR; goto done; }
        }
        for (cint i = 0; i < n; i++) {
          double dy = y[i] - yold[i];
          F[i] = dy;
          F[n + i] = h * K[i] - dy;
          F[2 * n + i] = 2 * dy - h * (f[i] + K[i]);
          for (int m = 0; m < 4; m++) {
            double d = 0.0;
            for (int j = 0; j < 16; j++) d += P8_D[m * 16 + j] * K[(cint)j * n + i];
            F[(3 + m) * n + i] = h * d;
          }
        }
      }
      while (k < ngrid && grid[k] <= t) {
        double *row = X + k * n;
        if (grid[k] == t) memcpy(row, y, (size_t)n * sizeof(double));
        else {
          double x = (grid[k] - t_old) / h;
          for (cint i = 0; i < n; i++) {
            if (method == 0) {   /* y_old + h * sum_m (K^T P)_im x^(m+1) */
              double acc = 0.0, xp = 1.0;
              for (int m = 0; m < 4; m++) {
                double q = 0.0;
                for (int j = 0; j < 7; j++) q += K[(cint)j * n + i] * P5_P[j * 4 + m];
                xp *= x;
                acc += q * xp;
              }
              row[i] = yold[i] + h * acc;
            } else {             /* scipy's Dop853DenseOutput: alternate factors x and 1 - x */
              double acc = 0.0;
              for (int m = 6; m >= 0; m--) {
                acc += F[m * n + i];
                acc *= ((6 - m) % 2 == 0) ? x : 1.0 - x;
              }
              row[i] = acc + yold[i];
            }
          }
        }
        k++;
        ctl[0] = k;
      }
      steps_here = 0;
    }
    if (steps_here >= max_steps) { status = CRK_MAX_STEPS; break; }
  }
done:
  stats[0] = (double)steps; stats[1] = (double)r.nfev; stats[2] = (double)rejected; stats[3] = t;
  memcpy(xfail, y, (size_t)n * sizeof(double));
  ode_release(r.mem);
  ode_decref();
  free(r.arg); free(r.res); free(r.iw); free(r.w); free(mem);
  return status;
}
