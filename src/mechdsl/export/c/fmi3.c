/* fmi3.c: the FMI 3.0 interface (model exchange and co-simulation) of an FMU exported by
   mechdsl, on the runtime of mech_fmu.h.  Every function of the standard is defined; those of
   capabilities the modelDescription.xml does not claim (other variable types, clocks,
   scheduled execution, adjoint derivatives, event mode in co-simulation) return fmi3Error.  Variables are scalars (nValues == nValueReferences); the independent variable
   `time` has the value reference VR_END. */
#include <stdlib.h>
#include <string.h>

#include "fmi3Functions.h"
#include "mech_fmu.h"

typedef struct { fmi3LogMessageCallback log; fmi3InstanceEnvironment env; } Env3;

static void bridge(void *env, int status, const char *category, const char *message) {
  Env3 *e = (Env3 *)env;
  if (e && e->log) e->log(e->env, (fmi3Status)status, category, message);
}

#define INST ((Instance *)instance)
#define CHECK(cond, what)                                                          \
  do {                                                                             \
    if (!instance) return fmi3Error;                                               \
    if (!(cond)) {                                                                 \
      mech_log(INST, LOG_ERROR, "%s is not allowed in this state of the FMU", what); \
      return fmi3Error;                                                            \
    }                                                                              \
  } while (0)

static fmi3Status fail(Instance *I) { I->mode = MODE_ERROR; return fmi3Error; }

static fmi3Status unsupported(fmi3Instance instance, const char *what) {
  if (instance) mech_log(INST, LOG_ERROR, "%s is not supported by this FMU (see its modelDescription.xml)", what);
  return fmi3Error;
}

const char *fmi3GetVersion(void) { return fmi3Version; }

fmi3Status fmi3SetDebugLogging(fmi3Instance instance, fmi3Boolean loggingOn, size_t nCategories,
                               const fmi3String categories[]) {
  (void)nCategories; (void)categories;
  if (!instance) return fmi3Error;
  INST->logging = loggingOn ? 1 : 0;
  return fmi3OK;
}

static fmi3Instance instantiate(int kind, fmi3String name, fmi3String token, fmi3Boolean loggingOn,
                                fmi3InstanceEnvironment env, fmi3LogMessageCallback log) {
  Env3 *e = (Env3 *)calloc(1, sizeof(Env3));
  if (!e) return NULL;
  e->log = log; e->env = env;
  const char *problem = NULL;
  if (!token || strcmp(token, MECH.token) != 0) problem = "the instantiation token does not match this FMU's modelDescription.xml";
  else if (kind == KIND_ME && !MECH.has_me) problem = "this FMU was exported for co-simulation only";
  else if (kind == KIND_CS && !MECH.has_cs) problem = "this FMU was exported for model exchange only";
  if (problem) { bridge(e, LOG_ERROR, "logStatusError", problem); free(e); return NULL; }
  Instance *I = mech_new(name, kind, e, bridge, loggingOn ? 1 : 0);
  if (!I) { bridge(e, LOG_ERROR, "logStatusError", "out of memory"); free(e); return NULL; }
  return I;
}

fmi3Instance fmi3InstantiateModelExchange(fmi3String instanceName, fmi3String instantiationToken,
                                          fmi3String resourcePath, fmi3Boolean visible, fmi3Boolean loggingOn,
                                          fmi3InstanceEnvironment instanceEnvironment, fmi3LogMessageCallback logMessage) {
  (void)resourcePath; (void)visible;
  return instantiate(KIND_ME, instanceName, instantiationToken, loggingOn, instanceEnvironment, logMessage);
}

fmi3Instance fmi3InstantiateCoSimulation(fmi3String instanceName, fmi3String instantiationToken,
                                         fmi3String resourcePath, fmi3Boolean visible, fmi3Boolean loggingOn,
                                         fmi3Boolean eventModeUsed, fmi3Boolean earlyReturnAllowed,
                                         const fmi3ValueReference requiredIntermediateVariables[],
                                         size_t nRequiredIntermediateVariables,
                                         fmi3InstanceEnvironment instanceEnvironment, fmi3LogMessageCallback logMessage,
                                         fmi3IntermediateUpdateCallback intermediateUpdate) {
  (void)resourcePath; (void)visible; (void)earlyReturnAllowed; (void)requiredIntermediateVariables;
  (void)nRequiredIntermediateVariables; (void)intermediateUpdate;
  if (eventModeUsed) {
    Env3 e = {logMessage, instanceEnvironment};
    bridge(&e, LOG_ERROR, "logStatusError", "this FMU has no event mode in co-simulation (hasEventMode is false)");
    return NULL;
  }
  return instantiate(KIND_CS, instanceName, instantiationToken, loggingOn, instanceEnvironment, logMessage);
}

fmi3Instance fmi3InstantiateScheduledExecution(fmi3String instanceName, fmi3String instantiationToken,
                                               fmi3String resourcePath, fmi3Boolean visible, fmi3Boolean loggingOn,
                                               fmi3InstanceEnvironment instanceEnvironment,
                                               fmi3LogMessageCallback logMessage, fmi3ClockUpdateCallback clockUpdate,
                                               fmi3LockPreemptionCallback lockPreemption,
                                               fmi3UnlockPreemptionCallback unlockPreemption) {
  (void)instanceName; (void)instantiationToken; (void)resourcePath; (void)visible; (void)loggingOn;
  (void)clockUpdate; (void)lockPreemption; (void)unlockPreemption;
  Env3 e = {logMessage, instanceEnvironment};
  bridge(&e, LOG_ERROR, "logStatusError", "this FMU does not support scheduled execution");
  return NULL;
}

void fmi3FreeInstance(fmi3Instance instance) {
  if (!instance) return;
  free(INST->env);
  mech_free(INST);
}

fmi3Status fmi3EnterInitializationMode(fmi3Instance instance, fmi3Boolean toleranceDefined, fmi3Float64 tolerance,
                                       fmi3Float64 startTime, fmi3Boolean stopTimeDefined, fmi3Float64 stopTime) {
  CHECK(INST->mode == MODE_INSTANTIATED, "fmi3EnterInitializationMode");
  INST->tolerance_defined = toleranceDefined ? 1 : 0;
  INST->tolerance = tolerance;
  INST->t = INST->t_start = startTime;
  INST->stop_defined = stopTimeDefined ? 1 : 0;
  INST->t_stop = stopTime;
  return mech_enter_init(INST) ? fail(INST) : fmi3OK;
}

fmi3Status fmi3ExitInitializationMode(fmi3Instance instance) {
  CHECK(INST->mode == MODE_INIT, "fmi3ExitInitializationMode");
  if (mech_exit_init(INST)) return fail(INST);
  INST->mode = INST->kind == KIND_ME ? MODE_EVENT : MODE_STEP;
  return fmi3OK;
}

fmi3Status fmi3EnterEventMode(fmi3Instance instance) {
  CHECK(INST->kind == KIND_ME && (INST->mode == MODE_CONTINUOUS || INST->mode == MODE_EVENT), "fmi3EnterEventMode");
  INST->mode = MODE_EVENT;
  return fmi3OK;
}

fmi3Status fmi3Terminate(fmi3Instance instance) {
  if (!instance) return fmi3Error;
  INST->mode = MODE_TERMINATED;
  return fmi3OK;
}

fmi3Status fmi3Reset(fmi3Instance instance) {
  if (!instance) return fmi3Error;
  mech_reset(INST);
  return fmi3OK;
}

/* ------------------------------------------------------------------ values */

fmi3Status fmi3GetFloat64(fmi3Instance instance, const fmi3ValueReference valueReferences[], size_t nValueReferences,
                          fmi3Float64 values[], size_t nValues) {
  CHECK(INST->mode != MODE_ERROR && nValues == nValueReferences, "fmi3GetFloat64");
  double *e = NULL;                   /* mechdsl.event_indicator[...]: all k evaluated once per call, when first asked */
  for (size_t i = 0; i < nValueReferences; i++) {
    fmi3ValueReference vr = valueReferences[i];
    if (vr == VR_END) { values[i] = INST->t; continue; }
    if (vr > VR_END && vr <= VR_END + (unsigned)MECH.k && INST->kind == KIND_ME && MECH.contacts) {
      if (!e) {
        e = (double *)calloc((size_t)MECH.k, sizeof(double));
        if (!e || mech_me_indicators(INST, e, (size_t)MECH.k)) { free(e); return fail(INST); }
      }
      values[i] = e[vr - VR_END - 1];
      continue;
    }
    if (mech_get_real(INST, vr, &values[i])) { free(e); return fmi3Error; }
  }
  free(e);
  return fmi3OK;
}

fmi3Status fmi3SetFloat64(fmi3Instance instance, const fmi3ValueReference valueReferences[], size_t nValueReferences,
                          const fmi3Float64 values[], size_t nValues) {
  CHECK(INST->mode != MODE_ERROR && INST->mode != MODE_TERMINATED && nValues == nValueReferences, "fmi3SetFloat64");
  for (size_t i = 0; i < nValueReferences; i++)
    if (mech_set_real(INST, valueReferences[i], values[i])) return fmi3Error;
  return fmi3OK;
}

fmi3Status fmi3GetInt32(fmi3Instance instance, const fmi3ValueReference valueReferences[], size_t nValueReferences,
                        fmi3Int32 values[], size_t nValues) {
  CHECK(INST->mode != MODE_ERROR && nValues == nValueReferences, "fmi3GetInt32");
  for (size_t i = 0; i < nValueReferences; i++) {
    int v = 0;
    if (mech_get_int(INST, valueReferences[i], &v)) return fmi3Error;
    values[i] = v;
  }
  return fmi3OK;
}

fmi3Status fmi3SetInt32(fmi3Instance instance, const fmi3ValueReference valueReferences[], size_t nValueReferences,
                        const fmi3Int32 values[], size_t nValues) {
  CHECK(INST->mode != MODE_ERROR && INST->mode != MODE_TERMINATED && nValues == nValueReferences, "fmi3SetInt32");
  for (size_t i = 0; i < nValueReferences; i++)
    if (mech_set_int(INST, valueReferences[i], values[i])) return fmi3Error;
  return fmi3OK;
}

#define NO_VARIABLES(NAME, TYPE, CONST)                                                                 \
  fmi3Status NAME(fmi3Instance instance, const fmi3ValueReference valueReferences[], size_t nValueReferences, \
                  CONST TYPE values[], size_t nValues) {                                                \
    (void)valueReferences; (void)values; (void)nValues;                                                 \
    if (!instance) return fmi3Error;                                                                    \
    return nValueReferences ? unsupported(instance, #NAME " (no variables of this type)") : fmi3OK;       \
  }

NO_VARIABLES(fmi3GetFloat32, fmi3Float32, )
NO_VARIABLES(fmi3GetInt8, fmi3Int8, )
NO_VARIABLES(fmi3GetUInt8, fmi3UInt8, )
NO_VARIABLES(fmi3GetInt16, fmi3Int16, )
NO_VARIABLES(fmi3GetUInt16, fmi3UInt16, )
NO_VARIABLES(fmi3GetUInt32, fmi3UInt32, )
NO_VARIABLES(fmi3GetInt64, fmi3Int64, )
NO_VARIABLES(fmi3GetUInt64, fmi3UInt64, )
NO_VARIABLES(fmi3GetBoolean, fmi3Boolean, )
NO_VARIABLES(fmi3GetString, fmi3String, )
NO_VARIABLES(fmi3SetFloat32, fmi3Float32, const)
NO_VARIABLES(fmi3SetInt8, fmi3Int8, const)
NO_VARIABLES(fmi3SetUInt8, fmi3UInt8, const)
NO_VARIABLES(fmi3SetInt16, fmi3Int16, const)
NO_VARIABLES(fmi3SetUInt16, fmi3UInt16, const)
NO_VARIABLES(fmi3SetUInt32, fmi3UInt32, const)
NO_VARIABLES(fmi3SetInt64, fmi3Int64, const)
NO_VARIABLES(fmi3SetUInt64, fmi3UInt64, const)
NO_VARIABLES(fmi3SetBoolean, fmi3Boolean, const)
NO_VARIABLES(fmi3SetString, fmi3String, const)

fmi3Status fmi3GetBinary(fmi3Instance instance, const fmi3ValueReference valueReferences[], size_t nValueReferences,
                         size_t valueSizes[], fmi3Binary values[], size_t nValues) {
  (void)valueReferences; (void)valueSizes; (void)values; (void)nValues;
  if (!instance) return fmi3Error;
  return nValueReferences ? unsupported(instance, "fmi3GetBinary (no Binary variables)") : fmi3OK;
}

fmi3Status fmi3SetBinary(fmi3Instance instance, const fmi3ValueReference valueReferences[], size_t nValueReferences,
                         const size_t valueSizes[], const fmi3Binary values[], size_t nValues) {
  (void)valueReferences; (void)valueSizes; (void)values; (void)nValues;
  if (!instance) return fmi3Error;
  return nValueReferences ? unsupported(instance, "fmi3SetBinary (no Binary variables)") : fmi3OK;
}

fmi3Status fmi3GetClock(fmi3Instance instance, const fmi3ValueReference valueReferences[], size_t nValueReferences,
                        fmi3Clock values[]) {
  (void)valueReferences; (void)values;
  if (!instance) return fmi3Error;
  return nValueReferences ? unsupported(instance, "fmi3GetClock (no clocks)") : fmi3OK;
}

fmi3Status fmi3SetClock(fmi3Instance instance, const fmi3ValueReference valueReferences[], size_t nValueReferences,
                        const fmi3Clock values[]) {
  (void)valueReferences; (void)values;
  if (!instance) return fmi3Error;
  return nValueReferences ? unsupported(instance, "fmi3SetClock (no clocks)") : fmi3OK;
}

fmi3Status fmi3GetNumberOfVariableDependencies(fmi3Instance instance, fmi3ValueReference valueReference,
                                               size_t *nDependencies) {
  (void)valueReference; (void)nDependencies;
  return unsupported(instance, "fmi3GetNumberOfVariableDependencies");
}

fmi3Status fmi3GetVariableDependencies(fmi3Instance instance, fmi3ValueReference dependent,
                                       size_t elementIndicesOfDependent[], fmi3ValueReference independents[],
                                       size_t elementIndicesOfIndependents[], fmi3DependencyKind dependencyKinds[],
                                       size_t nDependencies) {
  (void)dependent; (void)elementIndicesOfDependent; (void)independents; (void)elementIndicesOfIndependents;
  (void)dependencyKinds; (void)nDependencies;
  return unsupported(instance, "fmi3GetVariableDependencies");
}

fmi3Status fmi3GetFMUState(fmi3Instance instance, fmi3FMUState *FMUState) {
  CHECK(INST->mode != MODE_ERROR && FMUState, "fmi3GetFMUState");
  return mech_state_get(INST, FMUState) ? fmi3Error : fmi3OK;
}
fmi3Status fmi3SetFMUState(fmi3Instance instance, fmi3FMUState FMUState) {
  CHECK(INST->mode != MODE_ERROR, "fmi3SetFMUState");
  return mech_state_set(INST, FMUState) ? fmi3Error : fmi3OK;
}
fmi3Status fmi3FreeFMUState(fmi3Instance instance, fmi3FMUState *FMUState) {
  if (!instance) return fmi3Error;
  mech_state_free(FMUState);
  return fmi3OK;
}
fmi3Status fmi3SerializedFMUStateSize(fmi3Instance instance, fmi3FMUState FMUState, size_t *size) {
  CHECK(FMUState && size, "fmi3SerializedFMUStateSize");
  *size = mech_state_size(FMUState);
  return fmi3OK;
}
fmi3Status fmi3SerializeFMUState(fmi3Instance instance, fmi3FMUState FMUState, fmi3Byte serializedState[], size_t size) {
  CHECK(FMUState && serializedState, "fmi3SerializeFMUState");
  return mech_state_serialize(INST, FMUState, serializedState, size) ? fmi3Error : fmi3OK;
}
fmi3Status fmi3DeserializeFMUState(fmi3Instance instance, const fmi3Byte serializedState[], size_t size,
                                   fmi3FMUState *FMUState) {
  CHECK(FMUState && serializedState, "fmi3DeserializeFMUState");
  return mech_state_deserialize(INST, serializedState, size, FMUState) ? fmi3Error : fmi3OK;
}

fmi3Status fmi3GetDirectionalDerivative(fmi3Instance instance, const fmi3ValueReference unknowns[], size_t nUnknowns,
                                        const fmi3ValueReference knowns[], size_t nKnowns, const fmi3Float64 seed[],
                                        size_t nSeed, fmi3Float64 sensitivity[], size_t nSensitivity) {
  CHECK(INST->mode != MODE_ERROR && INST->mode != MODE_INSTANTIATED && nSeed == nKnowns && nSensitivity == nUnknowns,
        "fmi3GetDirectionalDerivative");
  if (MECH.k || MECH.nfix) return unsupported(instance, "directional derivatives of a model with contacts");
  return mech_directional(INST, unknowns, nUnknowns, knowns, nKnowns, seed, sensitivity) ? fmi3Error : fmi3OK;
}

fmi3Status fmi3GetAdjointDerivative(fmi3Instance instance, const fmi3ValueReference unknowns[], size_t nUnknowns,
                                    const fmi3ValueReference knowns[], size_t nKnowns, const fmi3Float64 seed[],
                                    size_t nSeed, fmi3Float64 sensitivity[], size_t nSensitivity) {
  (void)unknowns; (void)nUnknowns; (void)knowns; (void)nKnowns; (void)seed; (void)nSeed; (void)sensitivity;
  (void)nSensitivity;
  return unsupported(instance, "fmi3GetAdjointDerivative");
}

fmi3Status fmi3EnterConfigurationMode(fmi3Instance instance) { return unsupported(instance, "fmi3EnterConfigurationMode"); }
fmi3Status fmi3ExitConfigurationMode(fmi3Instance instance) { return unsupported(instance, "fmi3ExitConfigurationMode"); }

fmi3Status fmi3GetIntervalDecimal(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                                  size_t nValueReferences, fmi3Float64 intervals[], fmi3IntervalQualifier qualifiers[]) {
  (void)valueReferences; (void)nValueReferences; (void)intervals; (void)qualifiers;
  return unsupported(instance, "fmi3GetIntervalDecimal (no clocks)");
}
fmi3Status fmi3GetIntervalFraction(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                                   size_t nValueReferences, fmi3UInt64 counters[], fmi3UInt64 resolutions[],
                                   fmi3IntervalQualifier qualifiers[]) {
  (void)valueReferences; (void)nValueReferences; (void)counters; (void)resolutions; (void)qualifiers;
  return unsupported(instance, "fmi3GetIntervalFraction (no clocks)");
}
fmi3Status fmi3GetShiftDecimal(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                               size_t nValueReferences, fmi3Float64 shifts[]) {
  (void)valueReferences; (void)nValueReferences; (void)shifts;
  return unsupported(instance, "fmi3GetShiftDecimal (no clocks)");
}
fmi3Status fmi3GetShiftFraction(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                                size_t nValueReferences, fmi3UInt64 counters[], fmi3UInt64 resolutions[]) {
  (void)valueReferences; (void)nValueReferences; (void)counters; (void)resolutions;
  return unsupported(instance, "fmi3GetShiftFraction (no clocks)");
}
fmi3Status fmi3SetIntervalDecimal(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                                  size_t nValueReferences, const fmi3Float64 intervals[]) {
  (void)valueReferences; (void)nValueReferences; (void)intervals;
  return unsupported(instance, "fmi3SetIntervalDecimal (no clocks)");
}
fmi3Status fmi3SetIntervalFraction(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                                   size_t nValueReferences, const fmi3UInt64 counters[], const fmi3UInt64 resolutions[]) {
  (void)valueReferences; (void)nValueReferences; (void)counters; (void)resolutions;
  return unsupported(instance, "fmi3SetIntervalFraction (no clocks)");
}
fmi3Status fmi3SetShiftDecimal(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                               size_t nValueReferences, const fmi3Float64 shifts[]) {
  (void)valueReferences; (void)nValueReferences; (void)shifts;
  return unsupported(instance, "fmi3SetShiftDecimal (no clocks)");
}
fmi3Status fmi3SetShiftFraction(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                                size_t nValueReferences, const fmi3UInt64 counters[], const fmi3UInt64 resolutions[]) {
  (void)valueReferences; (void)nValueReferences; (void)counters; (void)resolutions;
  return unsupported(instance, "fmi3SetShiftFraction (no clocks)");
}

fmi3Status fmi3EvaluateDiscreteStates(fmi3Instance instance) {
  CHECK(INST->mode != MODE_ERROR, "fmi3EvaluateDiscreteStates");
  return fmi3OK;
}

fmi3Status fmi3UpdateDiscreteStates(fmi3Instance instance, fmi3Boolean *discreteStatesNeedUpdate,
                                    fmi3Boolean *terminateSimulation, fmi3Boolean *nominalsOfContinuousStatesChanged,
                                    fmi3Boolean *valuesOfContinuousStatesChanged, fmi3Boolean *nextEventTimeDefined,
                                    fmi3Float64 *nextEventTime) {
  CHECK(INST->kind == KIND_ME && INST->mode == MODE_EVENT, "fmi3UpdateDiscreteStates");
  *discreteStatesNeedUpdate = fmi3False;
  *terminateSimulation = fmi3False;
  *nominalsOfContinuousStatesChanged = fmi3False;
  *valuesOfContinuousStatesChanged = fmi3False;
  *nextEventTimeDefined = fmi3False;
  *nextEventTime = 0.0;
  int changed = 0, next_defined = 0;
  double next_time = 0.0;
  if (mech_me_event_update(INST, &changed, &next_defined, &next_time)) return fail(INST);
  *valuesOfContinuousStatesChanged = changed ? fmi3True : fmi3False;
  *nextEventTimeDefined = next_defined ? fmi3True : fmi3False;
  *nextEventTime = next_time;
  return fmi3OK;
}

/* ------------------------------------------------------------------ model exchange */

fmi3Status fmi3EnterContinuousTimeMode(fmi3Instance instance) {
  CHECK(INST->kind == KIND_ME && INST->mode == MODE_EVENT, "fmi3EnterContinuousTimeMode");
  INST->mode = MODE_CONTINUOUS;
  return fmi3OK;
}

fmi3Status fmi3CompletedIntegratorStep(fmi3Instance instance, fmi3Boolean noSetFMUStatePriorToCurrentPoint,
                                       fmi3Boolean *enterEventMode, fmi3Boolean *terminateSimulation) {
  (void)noSetFMUStatePriorToCurrentPoint;
  CHECK(INST->kind == KIND_ME && INST->mode == MODE_CONTINUOUS, "fmi3CompletedIntegratorStep");
  int enter = 0;
  *terminateSimulation = fmi3False;
  if (mech_me_step_done(INST, &enter)) return fail(INST);
  *enterEventMode = enter ? fmi3True : fmi3False;
  return fmi3OK;
}

fmi3Status fmi3SetTime(fmi3Instance instance, fmi3Float64 time) {
  CHECK(INST->kind == KIND_ME, "fmi3SetTime");
  INST->t = time;
  INST->valid = 0;
  return fmi3OK;
}

fmi3Status fmi3SetContinuousStates(fmi3Instance instance, const fmi3Float64 continuousStates[], size_t nContinuousStates) {
  CHECK(INST->kind == KIND_ME && nContinuousStates == (size_t)(2 * MECH.n), "fmi3SetContinuousStates");
  memcpy(INST->x, continuousStates, sizeof(double) * nContinuousStates);
  INST->valid = 0;
  return fmi3OK;
}

fmi3Status fmi3GetContinuousStateDerivatives(fmi3Instance instance, fmi3Float64 derivatives[], size_t nContinuousStates) {
  CHECK(INST->kind == KIND_ME && nContinuousStates == (size_t)(2 * MECH.n), "fmi3GetContinuousStateDerivatives");
  if (mech_evaluate(INST)) return fmi3Error;
  memcpy(derivatives, INST->xdot, sizeof(double) * nContinuousStates);
  INST->stats[STAT_RHS] += 1;
  return fmi3OK;
}

static size_t event_indicators(Instance *I) { return I->kind == KIND_ME && MECH.contacts ? (size_t)MECH.k : 0; }

fmi3Status fmi3GetEventIndicators(fmi3Instance instance, fmi3Float64 eventIndicators[], size_t nEventIndicators) {
  CHECK(nEventIndicators == event_indicators(INST), "fmi3GetEventIndicators");
  return mech_me_indicators(INST, eventIndicators, nEventIndicators) ? fail(INST) : fmi3OK;
}

fmi3Status fmi3GetContinuousStates(fmi3Instance instance, fmi3Float64 continuousStates[], size_t nContinuousStates) {
  CHECK(INST->kind == KIND_ME && nContinuousStates == (size_t)(2 * MECH.n), "fmi3GetContinuousStates");
  memcpy(continuousStates, INST->x, sizeof(double) * nContinuousStates);
  return fmi3OK;
}

fmi3Status fmi3GetNominalsOfContinuousStates(fmi3Instance instance, fmi3Float64 nominals[], size_t nContinuousStates) {
  CHECK(nContinuousStates == (size_t)(2 * MECH.n), "fmi3GetNominalsOfContinuousStates");
  for (size_t i = 0; i < nContinuousStates; i++) nominals[i] = 1.0;
  return fmi3OK;
}

fmi3Status fmi3GetNumberOfEventIndicators(fmi3Instance instance, size_t *nEventIndicators) {
  if (!instance) return fmi3Error;
  *nEventIndicators = event_indicators(INST);
  return fmi3OK;
}

fmi3Status fmi3GetNumberOfContinuousStates(fmi3Instance instance, size_t *nContinuousStates) {
  if (!instance) return fmi3Error;
  *nContinuousStates = (size_t)(2 * MECH.n);
  return fmi3OK;
}

/* ------------------------------------------------------------------ co-simulation */

fmi3Status fmi3EnterStepMode(fmi3Instance instance) {
  CHECK(INST->kind == KIND_CS, "fmi3EnterStepMode");
  INST->mode = MODE_STEP;
  return fmi3OK;
}

fmi3Status fmi3GetOutputDerivatives(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                                    size_t nValueReferences, const fmi3Int32 orders[], fmi3Float64 values[],
                                    size_t nValues) {
  (void)valueReferences; (void)orders; (void)values; (void)nValues;
  if (!instance) return fmi3Error;
  return nValueReferences ? unsupported(instance, "fmi3GetOutputDerivatives (maxOutputDerivativeOrder is 0)") : fmi3OK;
}

fmi3Status fmi3DoStep(fmi3Instance instance, fmi3Float64 currentCommunicationPoint, fmi3Float64 communicationStepSize,
                      fmi3Boolean noSetFMUStatePriorToCurrentPoint, fmi3Boolean *eventHandlingNeeded,
                      fmi3Boolean *terminateSimulation, fmi3Boolean *earlyReturn, fmi3Float64 *lastSuccessfulTime) {
  (void)noSetFMUStatePriorToCurrentPoint;
  CHECK(INST->kind == KIND_CS && INST->mode == MODE_STEP, "fmi3DoStep");
  *eventHandlingNeeded = fmi3False;
  *terminateSimulation = fmi3False;
  *earlyReturn = fmi3False;
  int st = mech_cs_step(INST, currentCommunicationPoint, communicationStepSize);
  *lastSuccessfulTime = INST->last_ok_time;
  if (st == LOG_OK) return fmi3OK;
  if (st == LOG_DISCARD) return fmi3Discard;
  return fail(INST);
}

fmi3Status fmi3ActivateModelPartition(fmi3Instance instance, fmi3ValueReference clockReference, fmi3Float64 activationTime) {
  (void)clockReference; (void)activationTime;
  return unsupported(instance, "fmi3ActivateModelPartition (no scheduled execution)");
}
