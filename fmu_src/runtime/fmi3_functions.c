/*
 * The FMI 3.0 API (Model Exchange and Co-Simulation; no Scheduled Execution) on top of
 * fmu_core.
 *
 * As in fmi2_functions.c: a bad call returns fmi3Error with a message through the importer's
 * logMessage callback and changes nothing; a failed computation also moves the instance to the
 * error state. FMI 3.0 has no memory callbacks, so the instance uses calloc/free.
 *
 * Files: fmi3_functions.c (life cycle, Float64/Boolean values, events, Model Exchange,
 * Co-Simulation), fmi3_model_structure.c (variable dependencies, FMU state, directional and
 * adjoint derivatives), fmi3_unsupported.c (other types, clocks, configuration mode, Scheduled
 * Execution: all refused), fmi3_front_end.h (shared checks).
 */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fmi3_front_end.h"

/* ---- plumbing -------------------------------------------------------------------------- */

static void log_to_importer(const CoreInstance *instance, CoreStatus status, const char *category,
                            const char *message) {
    const Fmi3FrontEnd *f = instance->front_end;
    if (f == NULL || f->log_message == NULL) return;
    f->log_message(f->environment, (fmi3Status)status, category, message);
}

static void *allocate_zeroed(size_t count, size_t size) { return calloc(count, size); }

/* ---- inquiry, logging, instantiation --------------------------------------------------- */

const char *fmi3GetVersion(void) { return fmi3Version; }

fmi3Status fmi3SetDebugLogging(fmi3Instance instance, fmi3Boolean loggingOn, size_t nCategories,
                               const fmi3String categories[]) {
    CoreInstance *s = enter(instance, "fmi3SetDebugLogging", ANY);
    if (s == NULL) return fmi3Error;
    return (fmi3Status)core_set_debug_logging(s, loggingOn, nCategories, categories);
}

static fmi3Instance instantiate(fmi3String name, fmi3String token, CoreInterfaceType type,
                                fmi3Boolean loggingOn, const Fmi3FrontEnd *front_end) {
    const char *function = type == CORE_MODEL_EXCHANGE ? "fmi3InstantiateModelExchange"
                                                       : "fmi3InstantiateCoSimulation";
    const char *problem = NULL;
    if (name == NULL || name[0] == '\0') problem = "the instance name is empty";
    else if (token == NULL || strcmp(token, core_instantiation_token()) != 0) {
        problem = "the instantiation token does not match this binary's";
    }
    if (problem != NULL) {
        if (front_end->log_message != NULL) {
            char message[256];
            snprintf(message, sizeof(message), "%s: %s", function, problem);
            front_end->log_message(front_end->environment, fmi3Error, "logStatusError", message);
        }
        return NULL;
    }
    return core_instantiate(name, type, log_to_importer, allocate_zeroed, free, front_end,
                            sizeof(*front_end), loggingOn);
}

fmi3Instance fmi3InstantiateModelExchange(fmi3String instanceName,
                                          fmi3String instantiationToken,
                                          fmi3String resourcePath, fmi3Boolean visible,
                                          fmi3Boolean loggingOn,
                                          fmi3InstanceEnvironment instanceEnvironment,
                                          fmi3LogMessageCallback logMessage) {
    (void)resourcePath;
    (void)visible;
    const Fmi3FrontEnd front_end = {instanceEnvironment, logMessage, 0};
    return instantiate(instanceName, instantiationToken, CORE_MODEL_EXCHANGE, loggingOn,
                       &front_end);
}

fmi3Instance fmi3InstantiateCoSimulation(
    fmi3String instanceName, fmi3String instantiationToken, fmi3String resourcePath,
    fmi3Boolean visible, fmi3Boolean loggingOn, fmi3Boolean eventModeUsed,
    fmi3Boolean earlyReturnAllowed, const fmi3ValueReference requiredIntermediateVariables[],
    size_t nRequiredIntermediateVariables, fmi3InstanceEnvironment instanceEnvironment,
    fmi3LogMessageCallback logMessage, fmi3IntermediateUpdateCallback intermediateUpdate) {
    (void)resourcePath;
    (void)visible;
    (void)earlyReturnAllowed; /* steps always run to the end */
    (void)requiredIntermediateVariables;
    (void)nRequiredIntermediateVariables;
    (void)intermediateUpdate; /* providesIntermediateUpdate = false */
    const Fmi3FrontEnd front_end = {instanceEnvironment, logMessage, eventModeUsed ? 1 : 0};
    return instantiate(instanceName, instantiationToken, CORE_CO_SIMULATION, loggingOn,
                       &front_end);
}

void fmi3FreeInstance(fmi3Instance instance) { core_free((CoreInstance *)instance); }

/* ---- life cycle ------------------------------------------------------------------------ */

fmi3Status fmi3EnterInitializationMode(fmi3Instance instance, fmi3Boolean toleranceDefined,
                                       fmi3Float64 tolerance, fmi3Float64 startTime,
                                       fmi3Boolean stopTimeDefined, fmi3Float64 stopTime) {
    CoreInstance *s = enter(instance, "fmi3EnterInitializationMode", CORE_MODE_INSTANTIATED);
    if (s == NULL) return fmi3Error;
    CoreStatus status = CORE_OK;
    if (toleranceDefined) {
        status = core_check_tolerance(s, "fmi3EnterInitializationMode", tolerance);
        if (status == CORE_ERROR) return fmi3Error;
    }
    if (!isfinite(startTime) || (stopTimeDefined && !(stopTime >= startTime))) {
        core_log_error(s, "fmi3EnterInitializationMode: invalid arguments (startTime = %g, "
                       "tolerance = %g, stopTime = %g)", startTime, tolerance, stopTime);
        return fmi3Error;
    }
    s->time = startTime;
    s->experiment_tolerance = toleranceDefined ? tolerance : 0.0;
    core_set_mode(s, CORE_MODE_INITIALIZATION);
    core_touch(s);
    return (fmi3Status)status;
}

fmi3Status fmi3ExitInitializationMode(fmi3Instance instance) {
    CoreInstance *s = enter(instance, "fmi3ExitInitializationMode", CORE_MODE_INITIALIZATION);
    if (s == NULL) return fmi3Error;
    if (core_initialize(s) != CORE_OK) return (fmi3Status)core_fail(s);
    const Fmi3FrontEnd *f = s->front_end;
    const int step_mode = s->interface_type == CORE_CO_SIMULATION && !f->event_mode_used;
    core_set_mode(s, step_mode ? CORE_MODE_STEP : CORE_MODE_EVENT);
    return fmi3OK;
}

fmi3Status fmi3EnterEventMode(fmi3Instance instance) {
    CoreInstance *s = enter(instance, "fmi3EnterEventMode", ME_MODES | CORE_MODE_STEP);
    if (s == NULL) return fmi3Error;
    const Fmi3FrontEnd *f = s->front_end;
    if (s->interface_type == CORE_CO_SIMULATION && !f->event_mode_used) {
        return refuse(instance, "fmi3EnterEventMode", "the instance was created with "
                      "eventModeUsed = false");
    }
    core_set_mode(s, CORE_MODE_EVENT);
    return fmi3OK;
}

fmi3Status fmi3Terminate(fmi3Instance instance) {
    CoreInstance *s = enter(instance, "fmi3Terminate", ME_MODES | CORE_MODE_STEP |
                            CORE_MODE_ERROR);
    if (s == NULL) return fmi3Error;
    core_set_mode(s, CORE_MODE_TERMINATED);
    return fmi3OK;
}

fmi3Status fmi3Reset(fmi3Instance instance) {
    CoreInstance *s = enter(instance, "fmi3Reset", ANY);
    if (s == NULL) return fmi3Error;
    core_reset(s);
    return fmi3OK;
}

/* ---- Float64 and Boolean --------------------------------------------------------------- */

fmi3Status fmi3GetFloat64(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                          size_t nValueReferences, fmi3Float64 values[], size_t nValues) {
    CoreInstance *s = enter(instance, "fmi3GetFloat64", ANY);
    if (s == NULL || !check_scalars(s, "fmi3GetFloat64", nValueReferences, nValues)) {
        return fmi3Error;
    }
    return (fmi3Status)core_get_real(s, "fmi3GetFloat64", valueReferences, nValueReferences,
                                     values);
}

fmi3Status fmi3SetFloat64(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                          size_t nValueReferences, const fmi3Float64 values[], size_t nValues) {
    CoreInstance *s = enter(instance, "fmi3SetFloat64", ANY);
    if (s == NULL || !check_scalars(s, "fmi3SetFloat64", nValueReferences, nValues)) {
        return fmi3Error;
    }
    return (fmi3Status)core_set_real(s, "fmi3SetFloat64", valueReferences, nValueReferences,
                                     values);
}

#define MAX_BOOLEANS_PER_CALL 256

fmi3Status fmi3GetBoolean(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                          size_t nValueReferences, fmi3Boolean values[], size_t nValues) {
    CoreInstance *s = enter(instance, "fmi3GetBoolean", ANY);
    if (s == NULL || !check_scalars(s, "fmi3GetBoolean", nValueReferences, nValues)) {
        return fmi3Error;
    }
    if (nValueReferences > MAX_BOOLEANS_PER_CALL) {
        return refuse(instance, "fmi3GetBoolean", "too many value references in one call");
    }
    int buffer[MAX_BOOLEANS_PER_CALL];
    const CoreStatus status =
        core_get_boolean(s, "fmi3GetBoolean", valueReferences, nValueReferences, buffer);
    if (status != CORE_OK) return (fmi3Status)status;
    for (size_t i = 0; i < nValueReferences; i++) values[i] = buffer[i] != 0;
    return fmi3OK;
}

fmi3Status fmi3SetBoolean(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                          size_t nValueReferences, const fmi3Boolean values[], size_t nValues) {
    CoreInstance *s = enter(instance, "fmi3SetBoolean", ANY);
    if (s == NULL || !check_scalars(s, "fmi3SetBoolean", nValueReferences, nValues)) {
        return fmi3Error;
    }
    if (nValueReferences > MAX_BOOLEANS_PER_CALL) {
        return refuse(instance, "fmi3SetBoolean", "too many value references in one call");
    }
    if (nValueReferences > 0 && values == NULL) {
        return refuse(instance, "fmi3SetBoolean", "values is NULL");
    }
    int buffer[MAX_BOOLEANS_PER_CALL];
    for (size_t i = 0; i < nValueReferences; i++) buffer[i] = values[i] ? 1 : 0;
    return (fmi3Status)core_set_boolean(s, "fmi3SetBoolean", valueReferences, nValueReferences,
                                        buffer);
}

/* ---- events: contact event indicators, but no discrete states (every update is trivial) - */

fmi3Status fmi3EvaluateDiscreteStates(fmi3Instance instance) {
    CoreInstance *s = enter(instance, "fmi3EvaluateDiscreteStates", ANY);
    return s == NULL ? fmi3Error : fmi3OK;
}

fmi3Status fmi3UpdateDiscreteStates(fmi3Instance instance, fmi3Boolean *discreteStatesNeedUpdate,
                                    fmi3Boolean *terminateSimulation,
                                    fmi3Boolean *nominalsOfContinuousStatesChanged,
                                    fmi3Boolean *valuesOfContinuousStatesChanged,
                                    fmi3Boolean *nextEventTimeDefined,
                                    fmi3Float64 *nextEventTime) {
    CoreInstance *s = enter(instance, "fmi3UpdateDiscreteStates", CORE_MODE_EVENT);
    if (s == NULL) return fmi3Error;
    fmi3Boolean *flags[] = {discreteStatesNeedUpdate, terminateSimulation,
                            nominalsOfContinuousStatesChanged, valuesOfContinuousStatesChanged,
                            nextEventTimeDefined};
    for (size_t i = 0; i < sizeof(flags) / sizeof(flags[0]); i++) {
        if (flags[i] != NULL) *flags[i] = false;
    }
    if (nextEventTime != NULL) *nextEventTime = 0.0;
    return fmi3OK;
}

/* ---- Model Exchange -------------------------------------------------------------------- */

fmi3Status fmi3EnterContinuousTimeMode(fmi3Instance instance) {
    CoreInstance *s = enter_interface(instance, "fmi3EnterContinuousTimeMode", CORE_MODE_EVENT,
                                      CORE_MODEL_EXCHANGE);
    if (s == NULL) return fmi3Error;
    core_set_mode(s, CORE_MODE_CONTINUOUS_TIME);
    return fmi3OK;
}

fmi3Status fmi3CompletedIntegratorStep(fmi3Instance instance,
                                       fmi3Boolean noSetFMUStatePriorToCurrentPoint,
                                       fmi3Boolean *enterEventMode,
                                       fmi3Boolean *terminateSimulation) {
    (void)noSetFMUStatePriorToCurrentPoint;
    CoreInstance *s = enter_interface(instance, "fmi3CompletedIntegratorStep",
                                      CORE_MODE_CONTINUOUS_TIME, CORE_MODEL_EXCHANGE);
    if (s == NULL || enterEventMode == NULL || terminateSimulation == NULL) return fmi3Error;
    *enterEventMode = false;
    *terminateSimulation = false;
    return fmi3OK;
}

fmi3Status fmi3SetTime(fmi3Instance instance, fmi3Float64 time) {
    CoreInstance *s = enter_interface(instance, "fmi3SetTime", ME_MODES, CORE_MODEL_EXCHANGE);
    if (s == NULL) return fmi3Error;
    if (!isfinite(time)) return refuse(instance, "fmi3SetTime", "time is not a finite number");
    s->time = time;
    return fmi3OK;
}

fmi3Status fmi3SetContinuousStates(fmi3Instance instance, const fmi3Float64 continuousStates[],
                                   size_t nContinuousStates) {
    CoreInstance *s = enter_interface(instance, "fmi3SetContinuousStates", ME_MODES,
                                      CORE_MODEL_EXCHANGE);
    if (s == NULL || !check_count(s, "fmi3SetContinuousStates", nContinuousStates,
                                  (size_t)s->nx, continuousStates)) {
        return fmi3Error;
    }
    for (size_t i = 0; i < nContinuousStates; i++) {
        if (!isfinite(continuousStates[i])) {
            core_log_error(s, "fmi3SetContinuousStates: state %zu = %g is not a finite number",
                           i, continuousStates[i]);
            return fmi3Error;
        }
    }
    memcpy(s->x, continuousStates, nContinuousStates * sizeof(double));
    core_touch(s);
    return fmi3OK;
}

fmi3Status fmi3GetContinuousStateDerivatives(fmi3Instance instance, fmi3Float64 derivatives[],
                                             size_t nContinuousStates) {
    CoreInstance *s = enter_interface(instance, "fmi3GetContinuousStateDerivatives",
                                      CORE_MODE_INITIALIZATION | ME_MODES |
                                          CORE_MODE_TERMINATED | CORE_MODE_ERROR,
                                      CORE_MODEL_EXCHANGE);
    if (s == NULL || !check_count(s, "fmi3GetContinuousStateDerivatives", nContinuousStates,
                                  (size_t)s->nx, derivatives)) {
        return fmi3Error;
    }
    if (core_update_cache(s) != CORE_OK) return (fmi3Status)core_fail(s);
    memcpy(derivatives, s->cached_derivatives, nContinuousStates * sizeof(double));
    return fmi3OK;
}

fmi3Status fmi3GetEventIndicators(fmi3Instance instance, fmi3Float64 eventIndicators[],
                                  size_t nEventIndicators) {
    CoreInstance *s = enter_interface(instance, "fmi3GetEventIndicators", ANY,
                                      CORE_MODEL_EXCHANGE);
    if (s == NULL || !check_count(s, "fmi3GetEventIndicators", nEventIndicators,
                                  (size_t)core_number_of_event_indicators(), eventIndicators)) {
        return fmi3Error;
    }
    if (core_event_indicators(s, "fmi3GetEventIndicators", eventIndicators) != CORE_OK) {
        return (fmi3Status)core_fail(s);
    }
    return fmi3OK;
}

fmi3Status fmi3GetContinuousStates(fmi3Instance instance, fmi3Float64 continuousStates[],
                                   size_t nContinuousStates) {
    CoreInstance *s = enter_interface(instance, "fmi3GetContinuousStates", ANY,
                                      CORE_MODEL_EXCHANGE);
    if (s == NULL || !check_count(s, "fmi3GetContinuousStates", nContinuousStates,
                                  (size_t)s->nx, continuousStates)) {
        return fmi3Error;
    }
    const double *x;
    if (core_effective_state(s, &x) != CORE_OK ||
        !core_check_finite(s, "fmi3GetContinuousStates", CORE_VARIABLE_STATE, x,
                           nContinuousStates)) {
        return (fmi3Status)core_fail(s);
    }
    memcpy(continuousStates, x, nContinuousStates * sizeof(double));
    return fmi3OK;
}

fmi3Status fmi3GetNominalsOfContinuousStates(fmi3Instance instance, fmi3Float64 nominals[],
                                             size_t nContinuousStates) {
    CoreInstance *s = enter_interface(instance, "fmi3GetNominalsOfContinuousStates", ANY,
                                      CORE_MODEL_EXCHANGE);
    if (s == NULL || !check_count(s, "fmi3GetNominalsOfContinuousStates", nContinuousStates,
                                  (size_t)s->nx, nominals)) {
        return fmi3Error;
    }
    core_state_nominals(nominals);
    return fmi3OK;
}

fmi3Status fmi3GetNumberOfEventIndicators(fmi3Instance instance, size_t *nEventIndicators) {
    CoreInstance *s = enter(instance, "fmi3GetNumberOfEventIndicators", ANY);
    if (s == NULL || nEventIndicators == NULL) return fmi3Error;
    *nEventIndicators = (size_t)core_number_of_event_indicators();
    return fmi3OK;
}

fmi3Status fmi3GetNumberOfContinuousStates(fmi3Instance instance, size_t *nContinuousStates) {
    CoreInstance *s = enter(instance, "fmi3GetNumberOfContinuousStates", ANY);
    if (s == NULL || nContinuousStates == NULL) return fmi3Error;
    *nContinuousStates = (size_t)s->nx;
    return fmi3OK;
}

/* ---- Co-Simulation --------------------------------------------------------------------- */

fmi3Status fmi3EnterStepMode(fmi3Instance instance) {
    CoreInstance *s = enter_interface(instance, "fmi3EnterStepMode", CORE_MODE_EVENT,
                                      CORE_CO_SIMULATION);
    if (s == NULL) return fmi3Error;
    core_set_mode(s, CORE_MODE_STEP);
    return fmi3OK;
}

fmi3Status fmi3GetOutputDerivatives(fmi3Instance instance,
                                    const fmi3ValueReference valueReferences[],
                                    size_t nValueReferences, const fmi3Int32 orders[],
                                    fmi3Float64 values[], size_t nValues) {
    (void)valueReferences, (void)nValueReferences, (void)orders, (void)values, (void)nValues;
    return refuse(instance, "fmi3GetOutputDerivatives",
                  "not supported (maxOutputDerivativeOrder = 0)");
}

fmi3Status fmi3DoStep(fmi3Instance instance, fmi3Float64 currentCommunicationPoint,
                      fmi3Float64 communicationStepSize,
                      fmi3Boolean noSetFMUStatePriorToCurrentPoint,
                      fmi3Boolean *eventHandlingNeeded, fmi3Boolean *terminateSimulation,
                      fmi3Boolean *earlyReturn, fmi3Float64 *lastSuccessfulTime) {
    (void)noSetFMUStatePriorToCurrentPoint;
    CoreInstance *s = enter_interface(instance, "fmi3DoStep", CORE_MODE_STEP,
                                      CORE_CO_SIMULATION);
    if (s == NULL) return fmi3Error;
    const double t = currentCommunicationPoint, h = communicationStepSize;
    if (core_check_step(s, "fmi3DoStep", t, h) != CORE_OK) return fmi3Error;
    s->time = t;
    s->last_step_status = core_do_step(s, t, h);
    if (eventHandlingNeeded != NULL) *eventHandlingNeeded = false;
    if (terminateSimulation != NULL) *terminateSimulation = false;
    if (earlyReturn != NULL) *earlyReturn = false;
    if (lastSuccessfulTime != NULL) *lastSuccessfulTime = s->last_successful_time;
    if (s->last_step_status == CORE_DISCARD) return fmi3Discard; /* the instance stays usable */
    if (s->last_step_status != CORE_OK) return (fmi3Status)core_fail(s);
    return fmi3OK;
}
