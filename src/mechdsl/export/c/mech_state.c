/* mech_state.c: the FMU state (FMI 2 fmi2GetFMUstate/SetFMUstate/FreeFMUstate and their
   serialization, FMI 3 the same for FMUState).

   A state is one flat block: a header (magic, layout version, size, a hash of the
   instantiation token) and every value an instance carries from one call to the next -- the
   mode and times, parameters, states, inputs with their derivatives, settings, statistics,
   the co-simulation stepper's kept step (dense output) and proposed step size, the contacts'
   closed set, fixations and anchors, the Zeno guard's history.  Scratch and the logger are
   not part of it.  Serialized, the block is its own bytes: it can be restored by the same FMU
   (same token, same binary layout) in this or another process, not by another FMU or
   platform. */
#include <stdlib.h>
#include <string.h>

#include "mech_fmu.h"

#define STATE_MAGIC 0x5354464Du     /* "MFTS" */
#define STATE_VERSION 1u

typedef struct { unsigned magic, version; size_t size; unsigned long long token; } Header;

static unsigned long long token_hash(void) {      /* FNV-1a of the token */
  unsigned long long h = 1469598103934665603ull;
  for (const char *c = MECH.token; *c; c++) { h ^= (unsigned char)*c; h *= 1099511628211ull; }
  return h;
}

enum { MEASURE, SAVE, LOAD };

/* every field in a fixed order: its size (MEASURE), copied into buf (SAVE) or out of it (LOAD) */
static size_t walk(Instance *I, unsigned char *buf, int how) {
  size_t off = sizeof(Header);
#define FIELD(ptr, bytes)                                                    \
  do {                                                                      \
    size_t b_ = (size_t)(bytes);                                            \
    if (how == SAVE) memcpy(buf + off, (const void *)(ptr), b_);            \
    else if (how == LOAD) memcpy((void *)(ptr), buf + off, b_);             \
    off += b_;                                                              \
  } while (0)
#define SCALAR(v) FIELD(&(v), sizeof(v))
#define ARRAY(a, count) FIELD((a), sizeof(*(a)) * (size_t)(count))
  const int n = MECH.n, nu = MECH.nu, nr = MECH.nrows, k = MECH.k;
  SCALAR(I->mode); SCALAR(I->t); SCALAR(I->t_start); SCALAR(I->t_stop); SCALAR(I->tolerance);
  SCALAR(I->tolerance_defined); SCALAR(I->stop_defined); SCALAR(I->started);
  ARRAY(I->p, MECH.np); ARRAY(I->free, MECH.nfree); ARRAY(I->x, 2 * n); ARRAY(I->x_set, 2 * n);
  ARRAY(I->u, nu); ARRAY(I->u_t0, nu); ARRAY(I->u_der, MAX_INPUT_ORDER * nu); SCALAR(I->u_moving);
  ARRAY(I->real_settings, N_REAL_SETTINGS); ARRAY(I->int_settings, N_INT_SETTINGS); ARRAY(I->stats, N_STATS);
  SCALAR(I->ti); ARRAY(I->xi, 2 * n); ARRAY(I->dense, crk_dense_size(2 * n)); SCALAR(I->ahead); SCALAR(I->fi_ok);
  SCALAR(I->h_next); SCALAR(I->last_ok_time); SCALAR(I->next_projection);
  ARRAY(I->closed, k); ARRAY(I->fix_done, MECH.nfix); ARRAY(I->active, nr); SCALAR(I->nactive);
  SCALAR(I->use_base); ARRAY(I->fix_sel, nr); ARRAY(I->anchor, nr); ARRAY(I->e, k);
  SCALAR(I->burst_count); SCALAR(I->burst_time); ARRAY(I->recent, MECH.rules.zeno_events > 0 ? MECH.rules.zeno_events : 1);
  SCALAR(I->nrecent); SCALAR(I->irecent);
#undef ARRAY
#undef SCALAR
#undef FIELD
  return off;
}

static int header_ok(Instance *I, const Header *h, size_t have) {
  if (have < sizeof(Header) || h->magic != STATE_MAGIC || h->version != STATE_VERSION || h->token != token_hash()
      || h->size != walk(I, NULL, MEASURE) || (have != (size_t)-1 && have != h->size)) {
    mech_log(I, LOG_ERROR, "not a state of this FMU (another model, version or binary)");
    return 0;
  }
  return 1;
}

int mech_state_get(Instance *I, void **state) {
  size_t size = walk(I, NULL, MEASURE);
  unsigned char *buf = (unsigned char *)*state;
  if (!buf || ((Header *)buf)->size != size) {
    free(buf);
    *state = buf = (unsigned char *)malloc(size);
    if (!buf) { mech_log(I, LOG_ERROR, "out of memory"); return 1; }
  }
  Header h = {STATE_MAGIC, STATE_VERSION, size, token_hash()};
  memcpy(buf, &h, sizeof h);
  walk(I, buf, SAVE);
  return 0;
}

void mech_state_free(void **state) {
  if (state) { free(*state); *state = NULL; }
}

int mech_state_set(Instance *I, const void *state) {
  if (!state) { mech_log(I, LOG_ERROR, "no FMU state given"); return 1; }
  Header h;
  memcpy(&h, state, sizeof h);
  if (!header_ok(I, &h, (size_t)-1)) return 1;
  walk(I, (unsigned char *)state, LOAD);
  I->valid = 0;
  return 0;
}

size_t mech_state_size(const void *state) {
  Header h;
  memcpy(&h, state, sizeof h);
  return h.size;
}

int mech_state_serialize(Instance *I, const void *state, void *bytes, size_t size) {
  if (size != mech_state_size(state)) {
    mech_log(I, LOG_ERROR, "serializing an FMU state: %zu bytes given, the state has %zu", size, mech_state_size(state));
    return 1;
  }
  memcpy(bytes, state, size);
  return 0;
}

int mech_state_deserialize(Instance *I, const void *bytes, size_t size, void **state) {
  Header h;
  if (!bytes || size < sizeof h) { mech_log(I, LOG_ERROR, "a serialized FMU state too short (%zu bytes)", size); return 1; }
  memcpy(&h, bytes, sizeof h);
  if (!header_ok(I, &h, size)) return 1;
  void *buf = malloc(size);
  if (!buf) { mech_log(I, LOG_ERROR, "out of memory"); return 1; }
  memcpy(buf, bytes, size);
  free(*state);
  *state = buf;
  return 0;
}
