/* mech_linalg.c: the small dense linear algebra of the FMU runtime (column-major storage).

   Cholesky factorization and solves (mass matrices, Schur complements of independent
   constraint rows), Gaussian elimination with partial pivoting (a fallback), minimum-norm
   solutions of underdetermined systems by Householder QR (consistent initialization), and
   the non-negative least-squares algorithm of Lawson and Hanson (Solving Least Squares
   Problems, 1974, ch. 23), which solves the least-distance problem of an impact as
   mechdsl.impacts.impact_map.ldp does with scipy.optimize.nnls. */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "mech_fmu.h"

#define AT(A, lda, i, j) ((A)[(size_t)(j) * (size_t)(lda) + (size_t)(i)])

/* A = L L^T for symmetric positive definite A (n x n); 0 on success, 1 when not positive */
int la_cholesky(int n, const double *A, double *L) {
  for (int j = 0; j < n; j++) {
    double s = AT(A, n, j, j);
    for (int k = 0; k < j; k++) s -= AT(L, n, j, k) * AT(L, n, j, k);
    if (!(s > 0.0) || !isfinite(s)) return 1;
    double d = sqrt(s);
    AT(L, n, j, j) = d;
    for (int i = j + 1; i < n; i++) {
      double v = AT(A, n, i, j);
      for (int k = 0; k < j; k++) v -= AT(L, n, i, k) * AT(L, n, j, k);
      AT(L, n, i, j) = v / d;
    }
    for (int i = 0; i < j; i++) AT(L, n, i, j) = 0.0;
  }
  return 0;
}

void la_lower_solve(int n, const double *L, double *b) {
  for (int i = 0; i < n; i++) {
    double v = b[i];
    for (int k = 0; k < i; k++) v -= AT(L, n, i, k) * b[k];
    b[i] = v / AT(L, n, i, i);
  }
}

void la_upper_solve_t(int n, const double *L, double *b) {
  for (int i = n - 1; i >= 0; i--) {
    double v = b[i];
    for (int k = i + 1; k < n; k++) v -= AT(L, n, k, i) * b[k];
    b[i] = v / AT(L, n, i, i);
  }
}

void la_chol_solve(int n, const double *L, double *b) {
  la_lower_solve(n, L, b);
  la_upper_solve_t(n, L, b);
}

/* A x = b by Gaussian elimination with partial pivoting, A and b overwritten (x in b);
   1 when A is singular to working precision */
int la_lu_solve(int n, double *A, double *b, int *piv) {
  double big = 0.0;
  for (int i = 0; i < n * n; i++) big = fmax(big, fabs(A[i]));
  for (int j = 0; j < n; j++) {
    int p = j;
    for (int i = j + 1; i < n; i++) if (fabs(AT(A, n, i, j)) > fabs(AT(A, n, p, j))) p = i;
    piv[j] = p;
    if (!(fabs(AT(A, n, p, j)) > 1e-14 * big)) return 1;
    if (p != j) {
      for (int k = 0; k < n; k++) { double s = AT(A, n, j, k); AT(A, n, j, k) = AT(A, n, p, k); AT(A, n, p, k) = s; }
      double s = b[j]; b[j] = b[p]; b[p] = s;
    }
    for (int i = j + 1; i < n; i++) {
      double f = AT(A, n, i, j) / AT(A, n, j, j);
      if (f == 0.0) continue;
      for (int k = j; k < n; k++) AT(A, n, i, k) -= f * AT(A, n, j, k);
      b[i] -= f * b[j];
    }
  }
  for (int i = n - 1; i >= 0; i--) {
    double v = b[i];
    for (int k = i + 1; k < n; k++) v -= AT(A, n, i, k) * b[k];
    b[i] = v / AT(A, n, i, i);
  }
  return 0;
}

/* Householder QR of B (r x c, r >= c, column-major, overwritten: R above the diagonal and
   the reflectors below, their scalars in tau); columns whose remaining norm is below
   1e-12 of the largest are skipped (tau = 0, R_jj = 0): a rank-deficient B. */
static void householder(int r, int c, double *B, double *tau) {
  double big = 0.0;
  for (int j = 0; j < c; j++) {
    double s = 0.0;
    for (int i = 0; i < r; i++) s += AT(B, r, i, j) * AT(B, r, i, j);
    big = fmax(big, sqrt(s));
  }
  for (int j = 0; j < c; j++) {
    double s = 0.0;
    for (int i = j; i < r; i++) s += AT(B, r, i, j) * AT(B, r, i, j);
    double nrm = sqrt(s);
    if (!(nrm > 1e-12 * big)) {
      tau[j] = 0.0;
      for (int i = j; i < r; i++) AT(B, r, i, j) = 0.0;
      continue;
    }
    double a = AT(B, r, j, j);
    double alpha = a > 0 ? -nrm : nrm;
    double v0 = a - alpha;
    AT(B, r, j, j) = alpha;
    for (int i = j + 1; i < r; i++) AT(B, r, i, j) /= v0;
    tau[j] = -v0 / alpha;     /* H = I - tau v v^T with v = (1, B[j+1:, j]) */
    for (int k = j + 1; k < c; k++) {
      double d = AT(B, r, j, k);
      for (int i = j + 1; i < r; i++) d += AT(B, r, i, j) * AT(B, r, i, k);
      d *= tau[j];
      AT(B, r, j, k) -= d;
      for (int i = j + 1; i < r; i++) AT(B, r, i, k) -= d * AT(B, r, i, j);
    }
  }
}

/* y := Q y (Q = H_0 H_1 ... H_{c-1}) or Q^T y, from householder's output */
static void apply_q(int r, int c, const double *B, const double *tau, double *y, int transpose) {
  for (int s = 0; s < c; s++) {
    int j = transpose ? s : c - 1 - s;
    if (tau[j] == 0.0) continue;
    double d = y[j];
    for (int i = j + 1; i < r; i++) d += AT(B, r, i, j) * y[i];
    d *= tau[j];
    y[j] -= d;
    for (int i = j + 1; i < r; i++) y[i] -= d * AT(B, r, i, j);
  }
}

/* The minimum-norm least-squares solution x (n) of A x = b, A (m x n, leading dimension lda):
   for m <= n through the QR of A^T (x = Q R^-T b), else through the QR of A
   (x = R^-1 Q^T b); directions with a vanishing pivot are dropped (a rank-deficient A).
   0 on success, 1 when out of memory. */
int la_min_norm(int m, int n, const double *A, int lda, const double *b, double *x, double *work) {
  (void)work;
  int r = m <= n ? n : m, c = m <= n ? m : n;
  double *B = (double *)malloc(sizeof(double) * ((size_t)r * c + c + r + 1));
  if (!B) return 1;
  double *tau = B + (size_t)r * c, *y = tau + c;
  for (int j = 0; j < c; j++)
    for (int i = 0; i < r; i++) AT(B, r, i, j) = m <= n ? AT(A, lda, j, i) : AT(A, lda, i, j);
  householder(r, c, B, tau);
  if (m <= n) {
    /* A = R^T Q^T: solve R^T z = b (forward), x = Q [z; 0] */
    for (int i = 0; i < r; i++) y[i] = 0.0;
    for (int i = 0; i < c; i++) {
      double d = AT(B, r, i, i);
      if (tau[i] == 0.0 && d == 0.0) { y[i] = 0.0; continue; }
      double v = b[i];
      for (int k = 0; k < i; k++) v -= AT(B, r, k, i) * y[k];
      y[i] = v / d;
    }
    apply_q(r, c, B, tau, y, 0);
    memcpy(x, y, sizeof(double) * (size_t)n);
  } else {
    memcpy(y, b, sizeof(double) * (size_t)m);
    apply_q(r, c, B, tau, y, 1);
    for (int i = c - 1; i >= 0; i--) {
      double d = AT(B, r, i, i);
      if (d == 0.0) { x[i] = 0.0; continue; }
      double v = y[i];
      for (int k = i + 1; k < c; k++) v -= AT(B, r, i, k) * x[k];
      x[i] = v / d;
    }
  }
  free(B);
  return 0;
}

/* least squares on the columns `cols` of A (m x n): z[cols] = argmin |A_P z - b| */
static int ls_columns(int m, const double *A, const double *b, const int *cols, int np, double *z) {
  double *B = (double *)malloc(sizeof(double) * ((size_t)m * np + (size_t)np + (size_t)m + 1));
  if (!B) return 1;
  double *tau = B + (size_t)m * np, *y = tau + np;
  for (int j = 0; j < np; j++)
    for (int i = 0; i < m; i++) AT(B, m, i, j) = AT(A, m, i, cols[j]);
  if (np <= m) {
    householder(m, np, B, tau);
    memcpy(y, b, sizeof(double) * (size_t)m);
    apply_q(m, np, B, tau, y, 1);
    for (int i = np - 1; i >= 0; i--) {
      double d = AT(B, m, i, i), v = y[i];
      for (int k = i + 1; k < np; k++) v -= AT(B, m, i, k) * z[cols[k]];
      z[cols[i]] = d != 0.0 ? v / d : 0.0;
    }
  } else {
    double *x = (double *)malloc(sizeof(double) * (size_t)np);
    if (!x) { free(B); return 1; }
    int st = la_min_norm(m, np, B, m, b, x, NULL);
    for (int j = 0; j < np; j++) z[cols[j]] = x[j];
    free(x);
    if (st) { free(B); return 1; }
  }
  free(B);
  return 0;
}

/* min |A x - b| subject to x >= 0 (A m x n, column-major; A and b unchanged).  w (n) and
   zz (n) scratch, index (n) scratch.  0 on success, 1 when the iterations run out, 2 out of
   memory.  rnorm: the residual norm. */
int la_nnls(int m, int n, double *A, double *b, double *x, double *rnorm, double *w, double *zz, int *index) {
  int *inP = index;
  double anorm = 0.0;
  for (int i = 0; i < m * n; i++) anorm = fmax(anorm, fabs(A[i]));
  const double tol = 10.0 * (double)(m > n ? m : n) * 2.220446049250313e-16 * fmax(anorm, 1e-300);
  int *cols = (int *)malloc(sizeof(int) * (size_t)(n + 1));
  double *r = (double *)malloc(sizeof(double) * (size_t)(m + 1));
  if (!cols || !r) { free(cols); free(r); return 2; }
  for (int j = 0; j < n; j++) { x[j] = 0.0; inP[j] = 0; }
  int status = 0, iter = 0, max_iter = 3 * n + 30;
  for (;;) {
    for (int i = 0; i < m; i++) {
      double v = b[i];
      for (int j = 0; j < n; j++) v -= AT(A, m, i, j) * x[j];
      r[i] = v;
    }
    for (int j = 0; j < n; j++) {
      double v = 0.0;
      for (int i = 0; i < m; i++) v += AT(A, m, i, j) * r[i];
      w[j] = v;
    }
    int t = -1;
    for (int j = 0; j < n; j++) if (!inP[j] && w[j] > tol && (t < 0 || w[j] > w[t])) t = j;
    if (t < 0) break;
    inP[t] = 1;
    for (;;) {
      if (++iter > max_iter) { status = 1; goto done; }
      int np = 0;
      for (int j = 0; j < n; j++) if (inP[j]) cols[np++] = j;
      for (int j = 0; j < n; j++) zz[j] = 0.0;
      if (ls_columns(m, A, b, cols, np, zz)) { status = 2; goto done; }
      int all_pos = 1;
      for (int q = 0; q < np; q++) if (zz[cols[q]] <= tol) { all_pos = 0; break; }
      if (all_pos) { for (int j = 0; j < n; j++) x[j] = zz[j]; break; }
      double alpha = 2.0;
      for (int q = 0; q < np; q++) {
        int j = cols[q];
        if (zz[j] <= tol) {
          double a = x[j] / (x[j] - zz[j]);
          if (a < alpha) alpha = a;
        }
      }
      for (int j = 0; j < n; j++) x[j] += alpha * (zz[j] - x[j]);
      for (int q = 0; q < np; q++) {
        int j = cols[q];
        if (x[j] <= tol) { inP[j] = 0; x[j] = 0.0; }
      }
    }
  }
done:
  {
    double s = 0.0;
    for (int i = 0; i < m; i++) {
      double v = b[i];
      for (int j = 0; j < n; j++) v -= AT(A, m, i, j) * x[j];
      s += v * v;
    }
    *rnorm = sqrt(s);
  }
  free(cols); free(r);
  return status;
}
