/* vm.c: an interpreter of CasADi SX algorithms for mechdsl's compiled loop (crk.c).

   A program (mechdsl.eom.sxcode.program) is the SX Function's instruction list rewritten for
   a register file w = [inputs' nonzeros | constants | work slots]: an instruction reads its
   operands straight from the inputs or the constants (no INPUT or CONST instructions), and
   OUT copies a register to an output nonzero.  Each operation is the C expression CasADi's
   code generator prints for it (calculus.hpp), evaluated in the same order, so a program
   gives the same bits as the generated C of the same Function (tests/test_sxcode.py).

   The loop calls vm_eval through its Fun record (ctx = the Prog) on work memory of nreg
   doubles that vm_init filled with the constants once; nothing else is written between
   calls, so the interpreter is reentrant. */
#include <math.h>
#include <string.h>

typedef long long cint;

typedef struct {
  const int *ins;          /* 4 ints an instruction: op, out, a, b */
  cint nins;
  const double *consts; cint nconst; cint const_off;
  int nin; const cint *in_off; const cint *in_nnz;
} Prog;

/* opcodes: the order of mechdsl.eom.sxcode.VM_OPS */
enum { V_END, V_OUT, V_ASSIGN, V_ADD, V_SUB, V_MUL, V_DIV, V_NEG, V_EXP, V_LOG, V_POW, V_SQRT, V_SQ,
       V_TWICE, V_SIN, V_COS, V_TAN, V_ASIN, V_ACOS, V_ATAN, V_LT, V_LE, V_EQ, V_NE, V_NOT, V_AND, V_OR,
       V_FLOOR, V_CEIL, V_FMOD, V_FABS, V_SIGN, V_COPYSIGN, V_IF_ELSE_ZERO, V_ERF, V_FMIN, V_FMAX, V_INV,
       V_SINH, V_COSH, V_TANH, V_ASINH, V_ACOSH, V_ATANH, V_ATAN2, V_LOG1P, V_EXPM1, V_HYPOT, V_REMAINDER,
       V_BLOCK, V_NOPS };
/* a block's operations: the order of mechdsl.eom.sxcode._BLOCKED */
enum { B_OUT, B_ADD, B_SUB, B_MUL, B_DIV };

static double sign_of(double x) { return x < 0 ? -1. : x > 0 ? 1. : x; }
/* fmin, fmax, hypot are commutative to gcc, which would swap their operands; on signed zeros
   the C library's answer depends on the order (as in mechdsl.eom.sxcode's C) */
#if defined(__GNUC__)
#define VM_KEEP __attribute__((noinline))
#else
#define VM_KEEP
#endif
static VM_KEEP double vm_fmin(double x, double y) { return fmin(x, y); }
static VM_KEEP double vm_fmax(double x, double y) { return fmax(x, y); }
static VM_KEEP double vm_hypot(double x, double y) { return hypot(x, y); }

void vm_init(const void *ctx, double *w) {
  const Prog *P = (const Prog *)ctx;
  if (P->nconst) memcpy(w + P->const_off, P->consts, (size_t)P->nconst * sizeof(double));
}

/* gcc merges the handlers' common tails (store, fetch, jump) into one indirect jump, which the
   branch predictor cannot learn: the interpreter ran at half speed */
#if defined(__GNUC__) && !defined(__clang__)
__attribute__((optimize("no-crossjumping", "no-gcse")))
#endif
int vm_eval(const void *ctx, const double **arg, double **res, cint *iw, double *w) {
  const Prog *P = (const Prog *)ctx;
  (void)iw;
  for (int i = 0; i < P->nin; i++) {
    if (!P->in_nnz[i]) continue;
    if (arg[i]) memcpy(w + P->in_off[i], arg[i], (size_t)P->in_nnz[i] * sizeof(double));
    else memset(w + P->in_off[i], 0, (size_t)P->in_nnz[i] * sizeof(double));
  }
  const int *p = P->ins;
#define O w[p[1]]
#define A w[p[2]]
#define B w[p[3]]
#if defined(__GNUC__)
  static const void *T[V_NOPS] = {
    &&L_END, &&L_OUT, &&L_ASSIGN, &&L_ADD, &&L_SUB, &&L_MUL, &&L_DIV, &&L_NEG, &&L_EXP, &&L_LOG, &&L_POW,
    &&L_SQRT, &&L_SQ, &&L_TWICE, &&L_SIN, &&L_COS, &&L_TAN, &&L_ASIN, &&L_ACOS, &&L_ATAN, &&L_LT, &&L_LE,
    &&L_EQ, &&L_NE, &&L_NOT, &&L_AND, &&L_OR, &&L_FLOOR, &&L_CEIL, &&L_FMOD, &&L_FABS, &&L_SIGN,
    &&L_COPYSIGN, &&L_IF_ELSE_ZERO, &&L_ERF, &&L_FMIN, &&L_FMAX, &&L_INV, &&L_SINH, &&L_COSH, &&L_TANH,
    &&L_ASINH, &&L_ACOSH, &&L_ATANH, &&L_ATAN2, &&L_LOG1P, &&L_EXPM1, &&L_HYPOT, &&L_REMAINDER,
    &&L_BLOCK};
#define CASE(name) L_##name:
#define NEXT p += 4; goto *T[p[0]];
  goto *T[p[0]];
#else
#define CASE(name) case V_##name:
#define NEXT p += 4; continue;
  for (;;) switch (p[0]) {
#endif
  CASE(OUT) { double *r = res[p[3]]; if (r) r[p[1]] = A; } NEXT
  CASE(ASSIGN) O = A; NEXT
  CASE(ADD) O = A + B; NEXT
  CASE(SUB) O = A - B; NEXT
  CASE(MUL) O = A * B; NEXT
  CASE(DIV) O = A / B; NEXT
  CASE(NEG) O = -A; NEXT
  CASE(EXP) O = exp(A); NEXT
  CASE(LOG) O = log(A); NEXT
  CASE(POW) O = pow(A, B); NEXT
  CASE(SQRT) O = sqrt(A); NEXT
  CASE(SQ) { double a = A; O = a * a; } NEXT
  CASE(TWICE) O = 2. * A; NEXT
  CASE(SIN) O = sin(A); NEXT
  CASE(COS) O = cos(A); NEXT
  CASE(TAN) O = tan(A); NEXT
  CASE(ASIN) O = asin(A); NEXT
  CASE(ACOS) O = acos(A); NEXT
  CASE(ATAN) O = atan(A); NEXT
  CASE(LT) O = A < B; NEXT
  CASE(LE) O = A <= B; NEXT
  CASE(EQ) O = A == B; NEXT
  CASE(NE) O = A != B; NEXT
  CASE(NOT) O = !A; NEXT
  CASE(AND) O = A && B; NEXT
  CASE(OR) O = A || B; NEXT
  CASE(FLOOR) O = floor(A); NEXT
  CASE(CEIL) O = ceil(A); NEXT
  CASE(FMOD) O = fmod(A, B); NEXT
  CASE(FABS) O = fabs(A); NEXT
  CASE(SIGN) O = sign_of(A); NEXT
  CASE(COPYSIGN) O = copysign(A, B); NEXT
  CASE(IF_ELSE_ZERO) O = A ? B : 0; NEXT
  CASE(ERF) O = erf(A); NEXT
  CASE(FMIN) O = vm_fmin(A, B); NEXT
  CASE(FMAX) O = vm_fmax(A, B); NEXT
  CASE(INV) O = 1. / A; NEXT
  CASE(SINH) O = sinh(A); NEXT
  CASE(COSH) O = cosh(A); NEXT
  CASE(TANH) O = tanh(A); NEXT
  CASE(ASINH) O = asinh(A); NEXT
  CASE(ACOSH) O = acosh(A); NEXT
  CASE(ATANH) O = atanh(A); NEXT
  CASE(ATAN2) O = atan2(A, B); NEXT
  CASE(LOG1P) O = log1p(A); NEXT
  CASE(EXPM1) O = expm1(A); NEXT
  CASE(HYPOT) O = vm_hypot(A, B); NEXT
  CASE(REMAINDER) O = remainder(A, B); NEXT
  CASE(BLOCK) {
    /* (V_BLOCK, count, operation, 0), then count records (0, out, a, b): one dispatch for a run
       of the same operation, in order (a record may read an earlier one's result) */
    const int *q = p + 4, *e = q + 4 * (cint)p[1];
    switch (p[2]) {
    case B_OUT: for (; q < e; q += 4) { double *r = res[q[3]]; if (r) r[q[1]] = w[q[2]]; } break;
    case B_ADD: for (; q < e; q += 4) w[q[1]] = w[q[2]] + w[q[3]]; break;
    case B_SUB: for (; q < e; q += 4) w[q[1]] = w[q[2]] - w[q[3]]; break;
    case B_MUL: for (; q < e; q += 4) w[q[1]] = w[q[2]] * w[q[3]]; break;
    case B_DIV: for (; q < e; q += 4) w[q[1]] = w[q[2]] / w[q[3]]; break;
    default: return 1;
    }
    p = e - 4;
  } NEXT
  CASE(END) return 0;
#if !defined(__GNUC__)
  default: return 1;
  }
#endif
#undef O
#undef A
#undef B
}
