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
       CRK_CANCELLED = 5, CRK_NOMEM = 6, CRK_RHS_ERROR = 7, CRK_BAD_METHOD = 8,
       CRK_EVENT = 9, CRK_EVENT_AT_START = 10 };

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

/* the continuous extension of the step [t_old, t_old + h] at tt (scipy's dense output) */
typedef struct { int method; const double *K, *F, *yold; double h, t_old; cint n; } Dense;

static void dense_eval(const Dense *d, double tt, double *out) {
  const cint n = d->n;
  const double *K = d->K, *F = d->F, *yold = d->yold;
  double x = (tt - d->t_old) / d->h;
  for (cint i = 0; i < n; i++) {
    if (d->method == 0) {   /* y_old + h * sum_m (K^T P)_im x^(m+1) */
      double acc = 0.0, xp = 1.0;
      for (int m = 0; m < 4; m++) {
        double q = 0.0;
        for (int j = 0; j < 7; j++) q += K[(cint)j * n + i] * P5_P[j * 4 + m];
        xp *= x;
        acc += q * xp;
      }
      out[i] = yold[i] + d->h * acc;
    } else {                /* scipy's Dop853DenseOutput: alternate factors x and 1 - x */
      double acc = 0.0;
      for (int m = 6; m >= 0; m--) {
        acc += F[m * n + i];
        acc *= ((6 - m) % 2 == 0) ? x : 1.0 - x;
      }
      out[i] = acc + yold[i];
    }
  }
}

/* ---------------------------------------------------------------- event location (contacts)

   Models with contacts (mechdsl.impacts.compiled): the CasADi-generated gap function
   `gap(t, x, p) -> g` (k gaps of the open contacts, compiled in the same library, passed in
   by address) is watched on every accepted step: the event function E(t) = min_i g_i + offset
   is sampled at `samples` equal sub-intervals of the step on the continuous extension; the
   first sample with E <= 0 is shrunk by the Illinois iteration of impacts/rootfind.py (forced
   bisection when two steps do not halve the bracket) to the resolution of doubles, then the
   root of the triggering gaps themselves (without the offset) is located the same way from
   the positive side.  The loop stops there (status CRK_EVENT), with the output rows before the
   event written and the state at the event in xfail; Python applies the impact law and calls
   again.  E <= 0 at the start is CRK_EVENT_AT_START (Python handles that step itself). */
typedef int (*casadi_fn)(const double **arg, double **res, cint *iw, double *w, int mem);
typedef int (*casadi_work_fn)(cint *sz_arg, cint *sz_res, cint *sz_iw, cint *sz_w);

typedef struct {
  casadi_fn gap; casadi_work_fn work;
  cint k; double offset; int samples;
  const double **arg; double **res; cint *iw; double *w;
  double *g, *x;        /* k gaps; a state on the interpolant */
  const double *p; double targ;
  cint nev;             /* gap evaluations in root finding */
  double t_event;
  /* impacts applied in C (impacts/compiled.py; NULL imp: every event returns to Python) */
  casadi_fn imp;
  const double **iarg; double **ires; cint *iiw; double *iw_;
  const double *e;      /* k coefficients of restitution */
  double rest_speed, v_eps, touch;
  double *ig, *iu, *iD, *iW, *xa;       /* impact outputs (k, k, n x k, k); the state after */
  double *buf; cint cap, count;          /* event records, CRK_EVENT_ROW(nx) doubles each */
} Events;

#define CRK_EVENT_ROW(nx) (5 + 2 * (nx))

static int gaps_at(Events *e, double t, const double *x) {
  e->targ = t;
  e->arg[0] = &e->targ; e->arg[1] = x; e->arg[2] = e->p;
  e->res[0] = e->g;
  return e->gap(e->arg, e->res, e->iw, e->w, 0);
}

/* min_i g_i + offset, or min over the flagged gaps (raw, no offset) when `only` is given */
static double event_value(Events *e, const int *only) {
  double v = INFINITY;
  for (cint i = 0; i < e->k; i++) {
    if (only && !only[i]) continue;
    double gi = only ? e->g[i] : e->g[i] + e->offset;
    if (gi != gi) return gi;   /* a NaN gap: find_event reports an error */
    if (gi < v) v = gi;
  }
  return v;
}

static double event_at(Events *e, const Dense *d, double tt, const int *only, int *err) {
  dense_eval(d, tt, e->x);
  if (gaps_at(e, tt, e->x)) *err = 1;
  return event_value(e, only);
}

/* impacts/rootfind.py's bracket_root: f(a) > 0 >= f(b) shrunk to b - a <= xtol */
static void bracket_root(Events *e, const Dense *d, const int *only, double *pa, double *pb, double fa,
                         double fb, double xtol, int *err) {
  double a = *pa, b = *pb, wa = fa, wb = fb, w1 = INFINITY, w2 = INFINITY, w3 = b - a;
  int side = 0, nev = 0;
  while (b - a > xtol && nev < 200) {
    double c;
    if (b - a > 0.5 * w1) c = 0.5 * (a + b);
    else {
      c = wb != wa ? (a * wb - b * wa) / (wb - wa) : 0.5 * (a + b);
      if (!isfinite(c)) c = 0.5 * (a + b);
      double margin = 1e-3 * (b - a);
      c = fmin(fmax(c, a + margin), b - margin);
    }
    if (!(a < c && c < b)) break;
    double fc = event_at(e, d, c, only, err);
    nev++;
    if (fc > 0) { a = c; wa = fc; if (side == 1) wb *= 0.5; side = 1; }
    else { b = c; wb = fc; if (side == -1) wa *= 0.5; side = -1; }
    w1 = w2; w2 = w3; w3 = b - a;
  }
  e->nev += nev;
  *pa = a; *pb = b;
}

/* The earliest event in the step (t_old, t_old + h]: 1 and its time in e->t_event, the state
   in e->x; 0 if none.  ea: E at the step start (> 0).  flags: k ints of scratch. */
static int find_event(Events *e, const Dense *d, double ea, int *flags, int *err) {
  double ta = d->t_old, tb = d->t_old + d->h, lo = ta, flo = ea, hi = ta, fhi = ea;
  int hit = 0;
  for (int j = 1; j <= e->samples; j++) {
    hi = j == e->samples ? tb : ta + (tb - ta) * j / e->samples;
    fhi = event_at(e, d, hi, NULL, err);
    if (!(fhi == fhi)) { *err = 1; return 0; }   /* a NaN gap: the caller fails (Python takes over) */
    if (fhi <= 0) { hit = 1; break; }
    lo = hi; flo = fhi;
  }
  if (!hit) return 0;
  double xtol = 4e-16 * fmax(fabs(ta), fabs(tb)) + 1e-15 * (tb - ta);
  double a = lo, b = hi, s0 = lo;
  bracket_root(e, d, NULL, &a, &b, flo, fhi, xtol, err);
  /* the triggering gaps at b, then the root of those gaps themselves (no offset) */
  event_at(e, d, b, NULL, err);
  cint worst = 0, any = 0;
  for (cint i = 0; i < e->k; i++) {
    flags[i] = e->g[i] + e->offset <= 0;
    any |= flags[i];
    if (e->g[i] < e->g[worst]) worst = i;
  }
  if (!any) flags[worst] = 1;
  double rb = event_value(e, flags);
  double rlo = event_at(e, d, s0, flags, err);
  e->nev += 2;
  if (rlo > 0 && rb <= 0) bracket_root(e, d, flags, &s0, &b, rlo, rb, xtol, err), a = s0;
  e->t_event = a;
  dense_eval(d, a, e->x);
  return 1;
}

/* the impact outputs at (t, x): gaps g, normal speeds u, D = M^-1 A^T (n x k, column-major),
   W_i = a_i M^-1 a_i^T (a_i = dg_i/dq) */
static int impact_eval(Events *e, double t, const double *x) {
  e->targ = t;
  e->iarg[0] = &e->targ; e->iarg[1] = x; e->iarg[2] = e->p;
  e->ires[0] = e->ig; e->ires[1] = e->iu; e->ires[2] = e->iD; e->ires[3] = e->iW;
  return e->imp(e->iarg, e->ires, e->iiw, e->iw_, 0);
}

/* Run.handle for the simple case, in C: one touching contact i (gap <= touch, every other gap
   above it), approaching (u_i < -v_eps), rebounding faster than rest_speed (e_i |u_i| >=
   rest_speed), no other row: the closed-form impact of impact_map._single (Lambda = (h - u) / W,
   q'+ = q'- + D_i Lambda) and the one-sided position projection of ContactSystem.project (Newton
   steps q -= D_j g_j / W_j while a gap is below -offset/2, to |g_j| <= 1e-3 offset).  On
   success 1, the state after in e->xa and the record appended to e->buf; 0 (nothing changed)
   whenever anything else could happen: Python then handles the event as before. */
static int impact_in_c(Events *e, double t, const double *x, cint n, cint nx) {
  if (!e->imp || e->count >= e->cap) return 0;
  if (impact_eval(e, t, x)) return 0;
  cint i = -1;
  for (cint j = 0; j < e->k; j++) {
    if (!(e->ig[j] == e->ig[j])) return 0;
    if (e->ig[j] <= e->touch) { if (i >= 0) return 0; i = j; }
  }
  if (i < 0) return 0;
  double u = e->iu[i], W = e->iW[i];
  if (!(u < -e->v_eps) || !(W > 0.0 && isfinite(W))) return 0;
  if (!(e->e[i] * -u >= e->rest_speed)) return 0;
  double h = -e->e[i] * u;
  double lam = fmax(0.0, h - u) / W;
  double *xa = e->xa;
  memcpy(xa, x, (size_t)nx * sizeof(double));
  for (cint j = 0; j < n; j++) xa[n + j] = x[n + j] + e->iD[i * n + j] * lam;
  double u_after = u + W * lam;
  if (!(u_after > e->v_eps)) return 0;
  double *rec = e->buf + e->count * CRK_EVENT_ROW(nx);
  rec[0] = t; rec[1] = (double)i; rec[2] = lam; rec[3] = u;
  memcpy(rec + 5, x, (size_t)nx * sizeof(double));
  double tol = 1e-3 * e->offset, below = -0.5 * e->offset;
  for (int it = 0; it < 8; it++) {
    if (impact_eval(e, t, xa)) return 0;
    cint use = -1, many = 0;
    for (cint j = 0; j < e->k; j++)
      if (e->ig[j] < below) { many |= use >= 0; use = j; }
    if (use < 0 || fabs(e->ig[use]) <= tol) break;
    if (many || !(e->iW[use] > 0.0)) return 0;
    double step = e->ig[use] / e->iW[use];
    for (cint j = 0; j < n; j++) xa[j] -= e->iD[use * n + j] * step;
  }
  rec[4] = u_after;
  for (cint j = 0; j < nx; j++) if (!isfinite(xa[j])) return 0;
  /* the run must restart above the event threshold */
  if (gaps_at(e, t, xa) || !(event_value(e, NULL) > 0)) return 0;
  memcpy(rec + 5 + nx, xa, (size_t)nx * sizeof(double));
  e->count++;
  return 1;
}

/* DOP853: the three extra stages and the interpolant's coefficients F of the accepted step */
static int dense_coefficients(Rhs *r, const Tableau *tab, double *K, double *F, const double *y,
                              const double *yold, const double *f, double *tmp, double h, double t_old, cint n) {
  for (int s = tab->stages + 1; s < tab->extended; s++) {
    combine(yold, K, tab->A + (cint)s * tab->lda, s, h, n, tmp);
    if (rhs(r, t_old + tab->C[s] * h, tmp, K + (cint)s * n)) return 1;
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
  return 0;
}

/* the initial step: scipy.integrate._ivp.common.select_initial_step (1: the rhs failed) */
static int initial_step(Rhs *r, const Tableau *tab, double t, double tb, const double *y, const double *f,
                        double *scale, double *tmp, double *ynew, double rtol, double atol, cint n, double *out) {
  double interval = fabs(tb - t), d0, d1, d2, h0, h1;
  for (cint i = 0; i < n; i++) scale[i] = atol + fabs(y[i]) * rtol;
  d0 = rms(y, scale, n); d1 = rms(f, scale, n);
  h0 = (d0 < 1e-5 || d1 < 1e-5) ? 1e-6 : 0.01 * d0 / d1;
  if (h0 > interval) h0 = interval;
  for (cint i = 0; i < n; i++) tmp[i] = y[i] + h0 * f[i];
  if (rhs(r, t + h0, tmp, ynew)) return 1;
  for (cint i = 0; i < n; i++) ynew[i] -= f[i];
  d2 = rms(ynew, scale, n) / h0;
  if (d1 <= 1e-15 && d2 <= 1e-15) h1 = fmax(1e-6, h0 * 1e-3);
  else h1 = pow(0.01 / fmax(d1, d2), 1.0 / (tab->err_order + 1.0));
  *out = fmin(fmin(100 * h0, h1), interval);
  return 0;
}

/* The last step's continuous extension, kept for a caller that interpolates after the call
   (crk_run_dense): method, t_old, h, t_new, then y_old, y_new and f(t_new, y_new) (n each),
   then the interpolant's coefficients (7 x n: the stages K of dopri5, F of dop853). */
#define CRK_DENSE_SIZE(nx) (4 + 10 * (nx))

static void dense_keep(double *out, const Dense *d, const double *y, const double *f) {
  const cint n = d->n;
  out[0] = (double)d->method; out[1] = d->t_old; out[2] = d->h; out[3] = d->t_old + d->h;
  memcpy(out + 4, d->yold, (size_t)n * sizeof(double));
  memcpy(out + 4 + n, y, (size_t)n * sizeof(double));
  memcpy(out + 4 + 2 * n, f, (size_t)n * sizeof(double));
  memcpy(out + 4 + 3 * n, d->method == 0 ? d->K : d->F, (size_t)(7 * n) * sizeof(double));
}

static int crk_core(int method, cint nx, const double *grid, cint ngrid, const double *x0, const double *u,
            const double *p, double rtol, double atol, double hmin, cint max_steps,
            double *X, double *stats, volatile cint *ctl, double *xfail, Events *ev, double *h_io,
            double t_limit, const double *f0, double *dense) {
  int *flags = NULL;
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
  double t = grid[0], h_keep = 0.0;     /* h_keep: the step proposed for a next call (h_io) */
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
  const double tlim = t_limit > tb ? t_limit : tb;   /* steps end at or before this (past tb: dense) */
  const double expo = -1.0 / (tab.err_order + 1.0);
  memcpy(y, x0, (size_t)n * sizeof(double));
  memcpy(X, x0, (size_t)n * sizeof(double));
  ctl[0] = 1;
  if (f0) memcpy(f, f0, (size_t)n * sizeof(double));         /* f(t0, x0) from the caller's last step */
  else if (rhs(&r, t, y, f)) { status = CRK_RHS_ERROR; goto done; }
  double e_start = INFINITY;      /* the event function at the current step's start */
  if (ev) {
    flags = (int *)calloc((size_t)(ev->k > 0 ? ev->k : 1), sizeof(int));
    if (!flags) { status = CRK_NOMEM; goto done; }
    if (gaps_at(ev, t, y)) { status = CRK_RHS_ERROR; goto done; }
    e_start = event_value(ev, NULL);
    if (!(e_start > 0)) { status = CRK_EVENT_AT_START; goto done; }
  }
  double h_abs;
  if (h_io && *h_io > 0) h_abs = fmin(*h_io, fabs(tlim - t));   /* a step proposed by the caller's last call */
  else if (initial_step(&r, &tab, t, tlim, y, f, scale, tmp, ynew, rtol, atol, n, &h_abs)) { status = CRK_RHS_ERROR; goto done; }
  h_keep = h_abs;
  while (k < ngrid) {
    if (ctl[1]) { status = CRK_CANCELLED; break; }
    double min_step = 10 * fabs(nextafter(t, INFINITY) - t);
    if (h_abs < min_step) h_abs = min_step;
    int accepted = 0, was_rejected = 0, clipped = 0;
    double h = 0.0, t_new = t, h_want = h_abs;
    while (!accepted) {
      if (h_abs < min_step) { status = CRK_TOO_SMALL; goto done; }
      if (hmin > 0 && h_abs < hmin && t + hmin < tb) {
        /* hmin bounds the step from below: a proposal under it (the initial step's heuristic,
           a growth step) is raised to it; error control rejecting a step down below it fails */
        if (was_rejected) { status = CRK_HMIN; goto done; }
        h_abs = hmin;
      }
      h = h_abs;
      h_want = h_abs;
      t_new = t + h;
      clipped = t_new > tlim;
      if (clipped) t_new = tlim;
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
        /* a step shortened to end at tlim says little about the next one: keep the step the
           control wanted unless the short step's error already asks for less */
        h_keep = (clipped && factor >= 1.0) ? fmax(h_abs, h_want) : h_abs;
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
    Dense dn = {method, K, F, yold, h, t_old, n};
    double t_out = t;           /* rows up to here (inclusive) come from this step */
    int dense_ready = 0, event = 0;
    if (ev && ev->k > 0) {
      if (method == 1) {
        if (dense_coefficients(&r, &tab, K, F, y, yold, f, tmp, h, t_old, n)) { status = CRK_RHS_ERROR; goto done; }
        dense_ready = 1;
      }
      int err = 0;
      event = find_event(ev, &dn, e_start, flags, &err);
      if (err) { status = CRK_RHS_ERROR; goto done; }
      if (event) t_out = nextafter(ev->t_event, -INFINITY);
      else e_start = event_value(ev, NULL);    /* the last sample: E at the step end */
    }
    if (k < ngrid && grid[k] <= t_out) {
      if (method == 1 && !dense_ready) {   /* the three extra stages and the interpolant's coefficients F */
        if (dense_coefficients(&r, &tab, K, F, y, yold, f, tmp, h, t_old, n)) { status = CRK_RHS_ERROR; goto done; }
      }
      while (k < ngrid && grid[k] <= t_out) {
        double *row = X + k * n;
        if (grid[k] == t) memcpy(row, y, (size_t)n * sizeof(double));
        else dense_eval(&dn, grid[k], row);
        k++;
        ctl[0] = k;
      }
      if (!ev) steps_here = 0;     /* with events max_steps bounds the whole call */
      if (dense && k == ngrid) dense_keep(dense, &dn, y, K + (cint)S * n);
    }
    if (event) {
      memcpy(y, ev->x, (size_t)n * sizeof(double));
      t = ev->t_event;
      if (!impact_in_c(ev, t, y, n / 2, n)) { status = CRK_EVENT; break; }
      /* handled in C: a new segment from the event, as Python would start it */
      memcpy(y, ev->xa, (size_t)n * sizeof(double));
      while (k < ngrid - 1 && grid[k] <= t) {        /* points at the event time: the state after it */
        memcpy(X + k * n, y, (size_t)n * sizeof(double));
        k++;
        ctl[0] = k;
      }
      if (rhs(&r, t, y, f)) { status = CRK_RHS_ERROR; goto done; }
      e_start = event_value(ev, NULL);      /* impact_in_c left the gaps at y in ev->g */
      if (initial_step(&r, &tab, t, tb, y, f, scale, tmp, ynew, rtol, atol, n, &h_abs)) {
        status = CRK_RHS_ERROR; goto done;
      }
      continue;
    }
    if (steps_here >= max_steps) { status = CRK_MAX_STEPS; break; }
  }
done:
  if (h_io) *h_io = h_keep;
  stats[0] = (double)steps; stats[1] = (double)r.nfev; stats[2] = (double)rejected; stats[3] = t;
  memcpy(xfail, y, (size_t)n * sizeof(double));
  ode_release(r.mem);
  ode_decref();
  free(r.arg); free(r.res); free(r.iw); free(r.w); free(mem); free(flags);
  return status;
}

int crk_run(int method, cint nx, const double *grid, cint ngrid, const double *x0, const double *u,
            const double *p, double rtol, double atol, double hmin, cint max_steps,
            double *X, double *stats, volatile cint *ctl, double *xfail) {
  return crk_core(method, nx, grid, ngrid, x0, u, p, rtol, atol, hmin, max_steps, X, stats, ctl, xfail, NULL, NULL,
                  0.0, NULL, NULL);
}

/* crk_run with the first step taken from *h_io when it is positive (else the initial-step
   heuristic) and the step proposed after the last accepted step written back: a caller that
   advances in many short calls (an FMU's co-simulation steps, mechdsl.export) keeps the
   step size from one call to the next instead of starting each call afresh. */
int crk_run_h(int method, cint nx, const double *grid, cint ngrid, const double *x0, const double *u,
              const double *p, double rtol, double atol, double hmin, cint max_steps,
              double *X, double *stats, volatile cint *ctl, double *xfail, double *h_io) {
  return crk_core(method, nx, grid, ngrid, x0, u, p, rtol, atol, hmin, max_steps, X, stats, ctl, xfail, NULL, h_io,
                  0.0, NULL, NULL);
}

/* crk_run_h whose steps are not shortened to end at the last output time: the last step may
   end past it, up to t_limit (an event time, an input change, the end of the run; t_limit <=
   the last output time: shortened as crk_run_h), the output rows interpolated on the continuous
   extension.  f0 (when not NULL): f(grid[0], x0), carried from the caller's last call (one
   evaluation fewer).  On success `dense` (crk_dense_size(nx) doubles) holds the last step:
   its end t_new = dense[3] and state (crk_dense_state), f there (crk_dense_rhs), and its
   interpolant (crk_dense_eval) for output times up to t_new without another call.  A caller
   that advances in short calls (an FMU's co-simulation steps, mechdsl.export) so takes the
   steps one long call takes. */
int crk_run_dense(int method, cint nx, const double *grid, cint ngrid, const double *x0, const double *u,
                  const double *p, double rtol, double atol, double hmin, cint max_steps,
                  double *X, double *stats, volatile cint *ctl, double *xfail, double *h_io,
                  double t_limit, const double *f0, double *dense) {
  return crk_core(method, nx, grid, ngrid, x0, u, p, rtol, atol, hmin, max_steps, X, stats, ctl, xfail, NULL, h_io,
                  t_limit, f0, dense);
}

cint crk_dense_size(cint nx) { return CRK_DENSE_SIZE(nx); }
const double *crk_dense_state(const double *dense, cint nx) { return dense + 4 + nx; }
const double *crk_dense_rhs(const double *dense, cint nx) { return dense + 4 + 2 * nx; }

/* the state at tt (t_old <= tt <= t_new) on the step kept by crk_run_dense */
void crk_dense_eval(const double *dense, cint nx, double tt, double *out) {
  const double *coef = dense + 4 + 3 * nx;
  Dense d = {(int)dense[0], coef, coef, dense + 4, dense[2], dense[1], nx};
  if (tt == dense[3]) memcpy(out, dense + 4 + nx, (size_t)nx * sizeof(double));
  else dense_eval(&d, tt, out);
}

/* crk_run watching the gaps `gap` (k outputs, CasADi signature, work sizes from `work`):
   stops at the first event (CRK_EVENT, the time in stats[3], the state in xfail); stats[4]
   counts the gap evaluations of root finding; max_steps bounds the whole call.  With `imp`
   (the CasADi `contact_impact(t, x, p) -> g, u, D, W`, work sizes from `imp_work`),
   restitution coefficients `rest` (k), limits = {rest_speed, v_eps, touch} and a record buffer
   `buf` of `cap` rows of CRK_EVENT_ROW(nx) doubles, the simple impacts are applied in the loop
   (impact_in_c) and stepping goes on; stats[5] counts the records.  imp NULL: every event
   returns. */
int crk_run_events_h(int method, cint nx, const double *grid, cint ngrid, const double *x0, const double *u,
                     const double *p, double rtol, double atol, double hmin, cint max_steps,
                     double *X, double *stats, volatile cint *ctl, double *xfail,
                     void *gap, void *gap_work, cint k, double offset, int samples, const double *gp,
                     void *imp, void *imp_work, const double *rest, const double *limits, double *buf, cint cap,
                     double *h_io);

int crk_run_events(int method, cint nx, const double *grid, cint ngrid, const double *x0, const double *u,
                   const double *p, double rtol, double atol, double hmin, cint max_steps,
                   double *X, double *stats, volatile cint *ctl, double *xfail,
                   void *gap, void *gap_work, cint k, double offset, int samples, const double *gp,
                   void *imp, void *imp_work, const double *rest, const double *limits, double *buf, cint cap) {
  return crk_run_events_h(method, nx, grid, ngrid, x0, u, p, rtol, atol, hmin, max_steps, X, stats, ctl, xfail,
                          gap, gap_work, k, offset, samples, gp, imp, imp_work, rest, limits, buf, cap, NULL);
}

/* crk_run_events with the step carried between calls in *h_io (as crk_run_h) */
int crk_run_events_h(int method, cint nx, const double *grid, cint ngrid, const double *x0, const double *u,
                     const double *p, double rtol, double atol, double hmin, cint max_steps,
                     double *X, double *stats, volatile cint *ctl, double *xfail,
                     void *gap, void *gap_work, cint k, double offset, int samples, const double *gp,
                     void *imp, void *imp_work, const double *rest, const double *limits, double *buf, cint cap,
                     double *h_io) {
  Events e;
  memset(&e, 0, sizeof e);
  e.gap = (casadi_fn)gap; e.work = (casadi_work_fn)gap_work;
  e.k = k; e.offset = offset; e.samples = samples < 1 ? 1 : samples; e.p = gp;
  cint sz_arg = 0, sz_res = 0, sz_iw = 0, sz_w = 0;
  e.work(&sz_arg, &sz_res, &sz_iw, &sz_w);
  if (sz_arg < 3) sz_arg = 3;
  if (sz_res < 1) sz_res = 1;
  e.arg = (const double **)calloc((size_t)sz_arg, sizeof(double *));
  e.res = (double **)calloc((size_t)sz_res, sizeof(double *));
  e.iw = (cint *)calloc((size_t)(sz_iw > 0 ? sz_iw : 1), sizeof(cint));
  e.w = (double *)calloc((size_t)(sz_w > 0 ? sz_w : 1), sizeof(double));
  e.g = (double *)calloc((size_t)(k > 0 ? k : 1), sizeof(double));
  e.x = (double *)calloc((size_t)(nx > 0 ? nx : 1), sizeof(double));
  int ok = e.arg && e.res && e.iw && e.w && e.g && e.x;
  if (imp && ok) {       /* impacts in C: limits = rest_speed, v_eps, touch */
    e.imp = (casadi_fn)imp; e.e = rest; e.rest_speed = limits[0]; e.v_eps = limits[1]; e.touch = limits[2];
    e.buf = buf; e.cap = cap;
    cint ia = 0, ir = 0, iiw = 0, iw = 0, nq = nx / 2;
    ((casadi_work_fn)imp_work)(&ia, &ir, &iiw, &iw);
    e.iarg = (const double **)calloc((size_t)(ia < 3 ? 3 : ia), sizeof(double *));
    e.ires = (double **)calloc((size_t)(ir < 4 ? 4 : ir), sizeof(double *));
    e.iiw = (cint *)calloc((size_t)(iiw > 0 ? iiw : 1), sizeof(cint));
    e.iw_ = (double *)calloc((size_t)(iw > 0 ? iw : 1), sizeof(double));
    e.ig = (double *)calloc((size_t)(3 * k + nq * k + 1), sizeof(double));
    e.xa = (double *)calloc((size_t)(nx + 1), sizeof(double));
    ok = e.iarg && e.ires && e.iiw && e.iw_ && e.ig && e.xa;
    if (ok) { e.iu = e.ig + k; e.iW = e.iu + k; e.iD = e.iW + k; }
  }
  int status = CRK_NOMEM;
  if (ok)
    status = crk_core(method, nx, grid, ngrid, x0, u, p, rtol, atol, hmin, max_steps, X, stats, ctl, xfail, &e, h_io,
                      0.0, NULL, NULL);
  stats[4] = (double)e.nev;
  stats[5] = (double)e.count;
  free(e.arg); free(e.res); free(e.iw); free(e.w); free(e.g); free(e.x);
  free(e.iarg); free(e.ires); free(e.iiw); free(e.iw_); free(e.ig); free(e.xa);
  return status;
}
