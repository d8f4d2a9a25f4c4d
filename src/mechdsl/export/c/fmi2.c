/* fmi2.c: the FMI 2.0 interface (model exchange and co-simulation) of an FMU exported by
   mechdsl, on the runtime of mech_fmu.h.  Every function of the standard is defined; those of
   capabilities the modelDescription.xml does not claim (output derivatives, asynchronous
   steps) return fmi2Error. */
#include <stdlib.h>
#include <string.h>

#include "fmi2Functions.h"
#include "mech_fmu.h"

typedef struct { fmi2CallbackFunctions cb; char name[256]; } Env2;

static void bridge(void *env, int status, const char *category, const char *message) {
  Env2 *e = (Env2 *)env;
  if (!e || !e->cb.logger) return;
  char text[2048];
  size_t j = 0;
  for (size_t i = 0; message[i] && j + 2 < sizeof text; i++) {   /* the logger takes a format: escape '%' */
    if (message[i] == '%') text[j++] = '%';
    text[j++] = message[i];
  }
  text[j] = 0;
  e->cb.logger(e->cb.componentEnvironment, e->name, (fmi2Status)status, category, text);
}

#define INST ((Instance *)c)
#define CHECK(cond, what)                                                         \
  do {                                                                            \
    if (!c) return fmi2Error;                                                     \
    if (!(cond)) {                                                                \
      mech_log(INST, LOG_ERROR, "%s is not allowed in this state of the FMU", what); \
      return fmi2Error;                                                           \
    }                                                                             \
  } while (0)

static fmi2Status fail(Instance *I) { I->mode = MODE_ERROR; return fmi2Error; }

const char *fmi2GetTypesPlatform(void) { return fmi2TypesPlatform; }
const char *fmi2GetVersion(void) { return fmi2Version; }

fmi2Status fmi2SetDebugLogging(fmi2Component c, fmi2Boolean loggingOn, size_t nCategories, const fmi2String categories[]) {
  (void)nCategories; (void)categories;
  if (!c) return fmi2Error;
  INST->logging = loggingOn ? 1 : 0;
  return fmi2OK;
}

fmi2Component fmi2Instantiate(fmi2String instanceName, fmi2Type fmuType, fmi2String fmuGUID,
                              fmi2String fmuResourceLocation, const fmi2CallbackFunctions *functions,
                              fmi2Boolean visible, fmi2Boolean loggingOn) {
  (void)fmuResourceLocation; (void)visible;
  Env2 *env = (Env2 *)calloc(1, sizeof(Env2));
  if (!env) return NULL;
  if (functions) env->cb = *functions;
  strncpy(env->name, instanceName ? instanceName : "", sizeof env->name - 1);
  int kind = fmuType == fmi2CoSimulation ? KIND_CS : KIND_ME;
  const char *problem = NULL;
  if (!fmuGUID || strcmp(fmuGUID, MECH.token) != 0) problem = "the GUID does not match this FMU's modelDescription.xml";
  else if (kind == KIND_ME && !MECH.has_me) problem = "this FMU was exported for co-simulation only";
  else if (kind == KIND_CS && !MECH.has_cs) problem = "this FMU was exported for model exchange only";
  if (problem) {
    bridge(env, LOG_ERROR, "logStatusError", problem);
    free(env);
    return NULL;
  }
  Instance *I = mech_new(instanceName, kind, env, bridge, loggingOn ? 1 : 0);
  if (!I) { bridge(env, LOG_ERROR, "logStatusError", "out of memory"); free(env); return NULL; }
  return I;
}

void fmi2FreeInstance(fmi2Component c) {
  if (!c) return;
  free(INST->env);
  mech_free(INST);
}

fmi2Status fmi2SetupExperiment(fmi2Component c, fmi2Boolean toleranceDefined, fmi2Real tolerance, fmi2Real startTime,
                               fmi2Boolean stopTimeDefined, fmi2Real stopTime) {
  CHECK(INST->mode == MODE_INSTANTIATED, "fmi2SetupExperiment");
  INST->tolerance_defined = toleranceDefined ? 1 : 0;
  INST->tolerance = tolerance;
  INST->t = INST->t_start = startTime;
  INST->stop_defined = stopTimeDefined ? 1 : 0;
  INST->t_stop = stopTime;
  return fmi2OK;
}

fmi2Status fmi2EnterInitializationMode(fmi2Component c) {
  CHECK(INST->mode == MODE_INSTANTIATED, "fmi2EnterInitializationMode");
  return mech_enter_init(INST) ? fail(INST) : fmi2OK;
}

fmi2Status fmi2ExitInitializationMode(fmi2Component c) {
  CHECK(INST->mode == MODE_INIT, "fmi2ExitInitializationMode");
  if (mech_exit_init(INST)) return fail(INST);
  INST->mode = INST->kind == KIND_ME ? MODE_EVENT : MODE_STEP;
  return fmi2OK;
}

fmi2Status fmi2Terminate(fmi2Component c) {
  if (!c) return fmi2Error;
  INST->mode = MODE_TERMINATED;
  return fmi2OK;
}

fmi2Status fmi2Reset(fmi2Component c) {
  if (!c) return fmi2Error;
  mech_reset(INST);
  return fmi2OK;
}

fmi2Status fmi2GetReal(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2Real value[]) {
  CHECK(INST->mode != MODE_ERROR, "fmi2GetReal");
  for (size_t i = 0; i < nvr; i++) if (mech_get_real(INST, vr[i], &value[i])) return fmi2Error;
  return fmi2OK;
}

fmi2Status fmi2GetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2Integer value[]) {
  CHECK(INST->mode != MODE_ERROR, "fmi2GetInteger");
  for (size_t i = 0; i < nvr; i++) if (mech_get_int(INST, vr[i], &value[i])) return fmi2Error;
  return fmi2OK;
}

fmi2Status fmi2GetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2Boolean value[]) {
  (void)vr; (void)value;
  if (!c) return fmi2Error;
  if (nvr) { mech_log(INST, LOG_ERROR, "this FMU has no Boolean variables"); return fmi2Error; }
  return fmi2OK;
}

fmi2Status fmi2GetString(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2String value[]) {
  (void)vr; (void)value;
  if (!c) return fmi2Error;
  if (nvr) { mech_log(INST, LOG_ERROR, "this FMU has no String variables"); return fmi2Error; }
  return fmi2OK;
}

fmi2Status fmi2SetReal(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const fmi2Real value[]) {
  CHECK(INST->mode != MODE_ERROR && INST->mode != MODE_TERMINATED, "fmi2SetReal");
  for (size_t i = 0; i < nvr; i++) if (mech_set_real(INST, vr[i], value[i])) return fmi2Error;
  return fmi2OK;
}

fmi2Status fmi2SetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const fmi2Integer value[]) {
  CHECK(INST->mode != MODE_ERROR && INST->mode != MODE_TERMINATED, "fmi2SetInteger");
  for (size_t i = 0; i < nvr; i++) if (mech_set_int(INST, vr[i], value[i])) return fmi2Error;
  return fmi2OK;
}

fmi2Status fmi2SetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const fmi2Boolean value[]) {
  (void)vr; (void)value;
  if (!c) return fmi2Error;
  if (nvr) { mech_log(INST, LOG_ERROR, "this FMU has no Boolean variables"); return fmi2Error; }
  return fmi2OK;
}

fmi2Status fmi2SetString(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const fmi2String value[]) {
  (void)vr; (void)value;
  if (!c) return fmi2Error;
  if (nvr) { mech_log(INST, LOG_ERROR, "this FMU has no String variables"); return fmi2Error; }
  return fmi2OK;
}

static fmi2Status unsupported(fmi2Component c, const char *what) {
  if (c) mech_log(INST, LOG_ERROR, "%s is not supported by this FMU (see its modelDescription.xml)", what);
  return fmi2Error;
}

fmi2Status fmi2GetFMUstate(fmi2Component c, fmi2FMUstate *s) {
  CHECK(INST->mode != MODE_ERROR && s, "fmi2GetFMUstate");
  return mech_state_get(INST, s) ? fmi2Error : fmi2OK;
}
fmi2Status fmi2SetFMUstate(fmi2Component c, fmi2FMUstate s) {
  CHECK(INST->mode != MODE_ERROR, "fmi2SetFMUstate");
  return mech_state_set(INST, s) ? fmi2Error : fmi2OK;
}
fmi2Status fmi2FreeFMUstate(fmi2Component c, fmi2FMUstate *s) {
  if (!c) return fmi2Error;
  mech_state_free(s);
  return fmi2OK;
}
fmi2Status fmi2SerializedFMUstateSize(fmi2Component c, fmi2FMUstate s, size_t *size) {
  CHECK(s && size, "fmi2SerializedFMUstateSize");
  *size = mech_state_size(s);
  return fmi2OK;
}
fmi2Status fmi2SerializeFMUstate(fmi2Component c, fmi2FMUstate s, fmi2Byte b[], size_t size) {
  CHECK(s && b, "fmi2SerializeFMUstate");
  return mech_state_serialize(INST, s, b, size) ? fmi2Error : fmi2OK;
}
fmi2Status fmi2DeSerializeFMUstate(fmi2Component c, const fmi2Byte b[], size_t size, fmi2FMUstate *s) {
  CHECK(s && b, "fmi2DeSerializeFMUstate");
  return mech_state_deserialize(INST, b, size, s) ? fmi2Error : fmi2OK;
}

fmi2Status fmi2GetDirectionalDerivative(fmi2Component c, const fmi2ValueReference vUnknown_ref[], size_t nUnknown,
                                        const fmi2ValueReference vKnown_ref[], size_t nKnown,
                                        const fmi2Real dvKnown[], fmi2Real dvUnknown[]) {
  CHECK(INST->mode != MODE_ERROR && INST->mode != MODE_INSTANTIATED, "fmi2GetDirectionalDerivative");
  if (MECH.k || MECH.nfix) return unsupported(c, "directional derivatives of a model with contacts");
  return mech_directional(INST, vUnknown_ref, nUnknown, vKnown_ref, nKnown, dvKnown, dvUnknown) ? fmi2Error : fmi2OK;
}

/* ------------------------------------------------------------------ model exchange */

fmi2Status fmi2EnterEventMode(fmi2Component c) {
  CHECK(INST->kind == KIND_ME && (INST->mode == MODE_CONTINUOUS || INST->mode == MODE_EVENT), "fmi2EnterEventMode");
  INST->mode = MODE_EVENT;
  return fmi2OK;
}

fmi2Status fmi2NewDiscreteStates(fmi2Component c, fmi2EventInfo *info) {
  CHECK(INST->kind == KIND_ME && INST->mode == MODE_EVENT, "fmi2NewDiscreteStates");
  info->newDiscreteStatesNeeded = fmi2False;
  info->terminateSimulation = fmi2False;
  info->nominalsOfContinuousStatesChanged = fmi2False;
  info->valuesOfContinuousStatesChanged = fmi2False;
  info->nextEventTimeDefined = fmi2False;
  info->nextEventTime = 0.0;
  int changed = 0, next_defined = 0;
  double next_time = 0.0;
  if (mech_me_event_update(INST, &changed, &next_defined, &next_time)) return fail(INST);
  info->valuesOfContinuousStatesChanged = changed ? fmi2True : fmi2False;
  info->nextEventTimeDefined = next_defined ? fmi2True : fmi2False;
  info->nextEventTime = next_time;
  return fmi2OK;
}

fmi2Status fmi2EnterContinuousTimeMode(fmi2Component c) {
  CHECK(INST->kind == KIND_ME && INST->mode == MODE_EVENT, "fmi2EnterContinuousTimeMode");
  INST->mode = MODE_CONTINUOUS;
  return fmi2OK;
}

fmi2Status fmi2CompletedIntegratorStep(fmi2Component c, fmi2Boolean noSetFMUStatePriorToCurrentPoint,
                                       fmi2Boolean *enterEventMode, fmi2Boolean *terminateSimulation) {
  (void)noSetFMUStatePriorToCurrentPoint;
  CHECK(INST->kind == KIND_ME && INST->mode == MODE_CONTINUOUS, "fmi2CompletedIntegratorStep");
  int enter = 0;
  *terminateSimulation = fmi2False;
  if (mech_me_step_done(INST, &enter)) return fail(INST);
  *enterEventMode = enter ? fmi2True : fmi2False;
  return fmi2OK;
}

fmi2Status fmi2SetTime(fmi2Component c, fmi2Real time) {
  CHECK(INST->kind == KIND_ME, "fmi2SetTime");
  INST->t = time;
  INST->valid = 0;
  return fmi2OK;
}

fmi2Status fmi2SetContinuousStates(fmi2Component c, const fmi2Real x[], size_t nx) {
  CHECK(INST->kind == KIND_ME && nx == (size_t)(2 * MECH.n), "fmi2SetContinuousStates");
  memcpy(INST->x, x, sizeof(double) * nx);
  INST->valid = 0;
  return fmi2OK;
}

fmi2Status fmi2GetDerivatives(fmi2Component c, fmi2Real derivatives[], size_t nx) {
  CHECK(INST->kind == KIND_ME && nx == (size_t)(2 * MECH.n), "fmi2GetDerivatives");
  if (mech_evaluate(INST)) return fmi2Error;
  memcpy(derivatives, INST->xdot, sizeof(double) * nx);
  INST->stats[STAT_RHS] += 1;
  return fmi2OK;
}

fmi2Status fmi2GetEventIndicators(fmi2Component c, fmi2Real eventIndicators[], size_t ni) {
  CHECK(INST->kind == KIND_ME && ni == (size_t)(MECH.contacts ? MECH.k : 0), "fmi2GetEventIndicators");
  return mech_me_indicators(INST, eventIndicators, ni) ? fail(INST) : fmi2OK;
}

fmi2Status fmi2GetContinuousStates(fmi2Component c, fmi2Real x[], size_t nx) {
  CHECK(INST->kind == KIND_ME && nx == (size_t)(2 * MECH.n), "fmi2GetContinuousStates");
  memcpy(x, INST->x, sizeof(double) * nx);
  return fmi2OK;
}

fmi2Status fmi2GetNominalsOfContinuousStates(fmi2Component c, fmi2Real x_nominal[], size_t nx) {
  CHECK(nx == (size_t)(2 * MECH.n), "fmi2GetNominalsOfContinuousStates");
  for (size_t i = 0; i < nx; i++) x_nominal[i] = 1.0;
  return fmi2OK;
}

/* ------------------------------------------------------------------ co-simulation */

fmi2Status fmi2SetRealInputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                                       const fmi2Integer order[], const fmi2Real value[]) {
  CHECK(INST->kind == KIND_CS && (INST->mode == MODE_INIT || INST->mode == MODE_STEP), "fmi2SetRealInputDerivatives");
  for (size_t i = 0; i < nvr; i++)
    if (mech_set_input_derivative(INST, vr[i], order[i], value[i])) return fmi2Error;
  return fmi2OK;
}

fmi2Status fmi2GetRealOutputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                                        const fmi2Integer order[], fmi2Real value[]) {
  (void)vr; (void)order; (void)value;
  if (!c) return fmi2Error;
  return nvr ? unsupported(c, "fmi2GetRealOutputDerivatives (maxOutputDerivativeOrder is 0)") : fmi2OK;
}

fmi2Status fmi2DoStep(fmi2Component c, fmi2Real currentCommunicationPoint, fmi2Real communicationStepSize,
                      fmi2Boolean noSetFMUStatePriorToCurrentPoint) {
  (void)noSetFMUStatePriorToCurrentPoint;
  CHECK(INST->kind == KIND_CS && INST->mode == MODE_STEP, "fmi2DoStep");
  int st = mech_cs_step(INST, currentCommunicationPoint, communicationStepSize);
  if (st == LOG_OK) return fmi2OK;
  if (st == LOG_DISCARD) return fmi2Discard;
  return fail(INST);
}

fmi2Status fmi2CancelStep(fmi2Component c) { return unsupported(c, "fmi2CancelStep (steps are synchronous)"); }

fmi2Status fmi2GetStatus(fmi2Component c, const fmi2StatusKind s, fmi2Status *value) {
  (void)s; (void)value;
  return unsupported(c, "fmi2GetStatus");
}

fmi2Status fmi2GetRealStatus(fmi2Component c, const fmi2StatusKind s, fmi2Real *value) {
  if (!c) return fmi2Error;
  if (s == fmi2LastSuccessfulTime) { *value = INST->last_ok_time; return fmi2OK; }
  return unsupported(c, "this fmi2GetRealStatus kind");
}

fmi2Status fmi2GetIntegerStatus(fmi2Component c, const fmi2StatusKind s, fmi2Integer *value) {
  (void)s; (void)value;
  return unsupported(c, "fmi2GetIntegerStatus");
}

fmi2Status fmi2GetBooleanStatus(fmi2Component c, const fmi2StatusKind s, fmi2Boolean *value) {
  if (!c) return fmi2Error;
  if (s == fmi2Terminated) { *value = fmi2False; return fmi2OK; }
  return unsupported(c, "this fmi2GetBooleanStatus kind");
}

fmi2Status fmi2GetStringStatus(fmi2Component c, const fmi2StatusKind s, fmi2String *value) {
  (void)s; (void)value;
  return unsupported(c, "fmi2GetStringStatus");
}
