/*
 * The FMI 2.0 API (Model Exchange and Co-Simulation in one binary) on top of fmu_core.
 *
 * Every function checks its instance, the state machine and its arguments; a bad call returns
 * fmi2Error with a message through the importer's logger and changes nothing. A failed
 * computation (the model refuses its parameters, the linkage cannot close, the integrator gives
 * up) also moves the instance to the error state, from which fmi2Reset, fmi2SetFMUstate,
 * fmi2Terminate and fmi2FreeInstance lead out. No call returns fmi2OK with a value that is not a
 * finite number (derivatives, outputs, states, event indicators, directional derivatives are
 * checked); a step that cannot advance the time and a tolerance below 1e-15 are refused, and
 * serialised FMU states carry a checksum.
 */
#include <math.h>
#include <string.h>

#include "fmi2Functions.h"
#include "fmu_core.h"

#define ME_MODES (CORE_MODE_EVENT | CORE_MODE_CONTINUOUS_TIME)
#define DIAGNOSTIC_MODES (CORE_MODE_STEP | CORE_MODE_TERMINATED | CORE_MODE_ERROR)

/* ---- plumbing -------------------------------------------------------------------------- */

static void log_to_importer(const CoreInstance *instance, CoreStatus status, const char *category,
                            const char *message) {
    const fmi2CallbackFunctions *functions = instance->front_end;
    if (functions == NULL || functions->logger == NULL) return;
    functions->logger(functions->componentEnvironment, instance->instance_name,
                      (fmi2Status)status, category, "%s", message);
}

/* The instance if it exists and is in one of the allowed modes, else NULL (error logged). */
static CoreInstance *enter(fmi2Component c, const char *function, unsigned int allowed) {
    CoreInstance *s = (CoreInstance *)c;
    if (s == NULL || !core_check_mode(s, function, allowed)) return NULL;
    return s;
}

static int require_interface(CoreInstance *s, const char *function, CoreInterfaceType type) {
    if (s->interface_type == type) return 1;
    core_log_error(s, "%s is only available in %s", function,
                   type == CORE_MODEL_EXCHANGE ? "Model Exchange" : "Co-Simulation");
    return 0;
}

static int check_count(CoreInstance *s, const char *function, size_t given, size_t expected,
                       const void *array) {
    if (given != expected || (given > 0 && array == NULL)) {
        core_log_error(s, "%s: expected %zu values (the number of %s), got %zu%s", function,
                       expected, strstr(function, "Event") ? "event indicators" : "states", given,
                       given > 0 && array == NULL ? " and a NULL array" : "");
        return 0;
    }
    return 1;
}

/* ---- common functions ------------------------------------------------------------------ */

const char *fmi2GetTypesPlatform(void) { return fmi2TypesPlatform; }

const char *fmi2GetVersion(void) { return fmi2Version; }

fmi2Status fmi2SetDebugLogging(fmi2Component c, fmi2Boolean loggingOn, size_t nCategories,
                               const fmi2String categories[]) {
    CoreInstance *s = enter(c, "fmi2SetDebugLogging", CORE_MODES_ANY);
    if (s == NULL) return fmi2Error;
    return (fmi2Status)core_set_debug_logging(s, loggingOn, nCategories, categories);
}

static void log_without_instance(const fmi2CallbackFunctions *functions, fmi2String name,
                                 const char *message, const char *detail) {
    if (functions == NULL || functions->logger == NULL) return;
    functions->logger(functions->componentEnvironment, name ? name : "", fmi2Error,
                      "logStatusError", "fmi2Instantiate: %s%s", message, detail);
}

fmi2Component fmi2Instantiate(fmi2String instanceName, fmi2Type fmuType, fmi2String fmuGUID,
                              fmi2String fmuResourceLocation,
                              const fmi2CallbackFunctions *functions, fmi2Boolean visible,
                              fmi2Boolean loggingOn) {
    (void)fmuResourceLocation; /* the model needs no resources */
    (void)visible;
    if (functions == NULL || functions->allocateMemory == NULL || functions->freeMemory == NULL) {
        log_without_instance(functions, instanceName, "the memory callbacks are missing", "");
        return NULL;
    }
    if (instanceName == NULL || instanceName[0] == '\0') {
        log_without_instance(functions, instanceName, "the instance name is empty", "");
        return NULL;
    }
    if (fmuGUID == NULL || strcmp(fmuGUID, core_instantiation_token()) != 0) {
        log_without_instance(functions, instanceName,
                             "the GUID does not match this binary's, expected ",
                             core_instantiation_token());
        return NULL;
    }
    if (fmuType != fmi2ModelExchange && fmuType != fmi2CoSimulation) {
        log_without_instance(functions, instanceName, "unknown fmuType", "");
        return NULL;
    }
    const CoreInterfaceType type =
        fmuType == fmi2ModelExchange ? CORE_MODEL_EXCHANGE : CORE_CO_SIMULATION;
    return core_instantiate(instanceName, type, log_to_importer, functions->allocateMemory,
                            functions->freeMemory, functions, sizeof(*functions), loggingOn);
}

void fmi2FreeInstance(fmi2Component c) { core_free((CoreInstance *)c); }

fmi2Status fmi2SetupExperiment(fmi2Component c, fmi2Boolean toleranceDefined,
                               fmi2Real tolerance, fmi2Real startTime,
                               fmi2Boolean stopTimeDefined, fmi2Real stopTime) {
    CoreInstance *s = enter(c, "fmi2SetupExperiment", CORE_MODE_INSTANTIATED);
    if (s == NULL) return fmi2Error;
    CoreStatus status = CORE_OK;
    if (toleranceDefined) {
        status = core_check_tolerance(s, "fmi2SetupExperiment", tolerance);
        if (status == CORE_ERROR) return fmi2Error;
    }
    if (!isfinite(startTime) || (stopTimeDefined && !(stopTime >= startTime))) {
        core_log_error(s, "fmi2SetupExperiment: invalid arguments (startTime = %g, tolerance = "
                       "%g, stopTime = %g)", startTime, tolerance, stopTime);
        return fmi2Error;
    }
    s->time = startTime;
    s->experiment_tolerance = toleranceDefined ? tolerance : 0.0;
    return (fmi2Status)status;
}

fmi2Status fmi2EnterInitializationMode(fmi2Component c) {
    CoreInstance *s = enter(c, "fmi2EnterInitializationMode", CORE_MODE_INSTANTIATED);
    if (s == NULL) return fmi2Error;
    core_set_mode(s, CORE_MODE_INITIALIZATION);
    core_touch(s);
    return fmi2OK;
}

fmi2Status fmi2ExitInitializationMode(fmi2Component c) {
    CoreInstance *s = enter(c, "fmi2ExitInitializationMode", CORE_MODE_INITIALIZATION);
    if (s == NULL) return fmi2Error;
    if (core_initialize(s) != CORE_OK) return (fmi2Status)core_fail(s);
    core_set_mode(s, s->interface_type == CORE_MODEL_EXCHANGE ? CORE_MODE_EVENT : CORE_MODE_STEP);
    return fmi2OK;
}

fmi2Status fmi2Terminate(fmi2Component c) {
    CoreInstance *s = enter(c, "fmi2Terminate", ME_MODES | CORE_MODE_STEP | CORE_MODE_ERROR);
    if (s == NULL) return fmi2Error;
    core_set_mode(s, CORE_MODE_TERMINATED);
    return fmi2OK;
}

fmi2Status fmi2Reset(fmi2Component c) {
    CoreInstance *s = enter(c, "fmi2Reset", CORE_MODES_ANY);
    if (s == NULL) return fmi2Error;
    core_reset(s);
    return fmi2OK;
}

/* ---- getting and setting values -------------------------------------------------------- */

fmi2Status fmi2GetReal(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                       fmi2Real value[]) {
    CoreInstance *s = enter(c, "fmi2GetReal", CORE_MODES_ANY);
    if (s == NULL) return fmi2Error;
    return (fmi2Status)core_get_real(s, "fmi2GetReal", vr, nvr, value);
}

fmi2Status fmi2GetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                          fmi2Integer value[]) {
    (void)vr;
    (void)value;
    CoreInstance *s = enter(c, "fmi2GetInteger", CORE_MODES_ANY);
    if (s == NULL) return fmi2Error;
    return (fmi2Status)core_refuse_type(s, "fmi2GetInteger", "Integer", nvr);
}

fmi2Status fmi2GetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                          fmi2Boolean value[]) {
    CoreInstance *s = enter(c, "fmi2GetBoolean", CORE_MODES_ANY);
    if (s == NULL) return fmi2Error;
    return (fmi2Status)core_get_boolean(s, "fmi2GetBoolean", vr, nvr, value);
}

fmi2Status fmi2GetString(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                         fmi2String value[]) {
    (void)vr;
    (void)value;
    CoreInstance *s = enter(c, "fmi2GetString", CORE_MODES_ANY);
    if (s == NULL) return fmi2Error;
    return (fmi2Status)core_refuse_type(s, "fmi2GetString", "String", nvr);
}

fmi2Status fmi2SetReal(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                       const fmi2Real value[]) {
    CoreInstance *s = enter(c, "fmi2SetReal", CORE_MODES_ANY);
    if (s == NULL) return fmi2Error;
    return (fmi2Status)core_set_real(s, "fmi2SetReal", vr, nvr, value);
}

fmi2Status fmi2SetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                          const fmi2Integer value[]) {
    (void)vr;
    (void)value;
    CoreInstance *s = enter(c, "fmi2SetInteger", CORE_MODES_ANY);
    if (s == NULL) return fmi2Error;
    return (fmi2Status)core_refuse_type(s, "fmi2SetInteger", "Integer", nvr);
}

fmi2Status fmi2SetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                          const fmi2Boolean value[]) {
    CoreInstance *s = enter(c, "fmi2SetBoolean", CORE_MODES_ANY);
    if (s == NULL) return fmi2Error;
    return (fmi2Status)core_set_boolean(s, "fmi2SetBoolean", vr, nvr, value);
}

fmi2Status fmi2SetString(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                         const fmi2String value[]) {
    (void)vr;
    (void)value;
    CoreInstance *s = enter(c, "fmi2SetString", CORE_MODES_ANY);
    if (s == NULL) return fmi2Error;
    return (fmi2Status)core_refuse_type(s, "fmi2SetString", "String", nvr);
}

/* ---- FMU state ------------------------------------------------------------------------- */

fmi2Status fmi2GetFMUstate(fmi2Component c, fmi2FMUstate *FMUstate) {
    CoreInstance *s = enter(c, "fmi2GetFMUstate", CORE_MODES_ANY);
    if (s == NULL) return fmi2Error;
    if (FMUstate == NULL) {
        core_log_error(s, "fmi2GetFMUstate: FMUstate is NULL");
        return fmi2Error;
    }
    void *snapshot = core_get_state(s, *FMUstate);
    if (snapshot == NULL) return fmi2Error;
    *FMUstate = snapshot;
    return fmi2OK;
}

fmi2Status fmi2SetFMUstate(fmi2Component c, fmi2FMUstate FMUstate) {
    CoreInstance *s = enter(c, "fmi2SetFMUstate", CORE_MODES_ANY);
    if (s == NULL) return fmi2Error;
    return (fmi2Status)core_set_state(s, FMUstate);
}

fmi2Status fmi2FreeFMUstate(fmi2Component c, fmi2FMUstate *FMUstate) {
    CoreInstance *s = enter(c, "fmi2FreeFMUstate", CORE_MODES_ANY);
    if (s == NULL) return fmi2Error;
    if (FMUstate != NULL) {
        core_free_state(s, *FMUstate);
        *FMUstate = NULL;
    }
    return fmi2OK;
}

fmi2Status fmi2SerializedFMUstateSize(fmi2Component c, fmi2FMUstate FMUstate, size_t *size) {
    (void)FMUstate;
    CoreInstance *s = enter(c, "fmi2SerializedFMUstateSize", CORE_MODES_ANY);
    if (s == NULL || size == NULL) return fmi2Error;
    *size = core_serialized_state_size(s);
    return fmi2OK;
}

fmi2Status fmi2SerializeFMUstate(fmi2Component c, fmi2FMUstate FMUstate,
                                 fmi2Byte serializedState[], size_t size) {
    CoreInstance *s = enter(c, "fmi2SerializeFMUstate", CORE_MODES_ANY);
    if (s == NULL) return fmi2Error;
    return (fmi2Status)core_serialize_state(s, FMUstate, (unsigned char *)serializedState, size);
}

fmi2Status fmi2DeSerializeFMUstate(fmi2Component c, const fmi2Byte serializedState[],
                                   size_t size, fmi2FMUstate *FMUstate) {
    CoreInstance *s = enter(c, "fmi2DeSerializeFMUstate", CORE_MODES_ANY);
    if (s == NULL) return fmi2Error;
    if (FMUstate == NULL) {
        core_log_error(s, "fmi2DeSerializeFMUstate: FMUstate is NULL");
        return fmi2Error;
    }
    void *snapshot = core_deserialize_state(s, (const unsigned char *)serializedState, size,
                                            *FMUstate);
    if (snapshot == NULL) return fmi2Error;
    *FMUstate = snapshot;
    return fmi2OK;
}

fmi2Status fmi2GetDirectionalDerivative(fmi2Component c, const fmi2ValueReference vUnknown_ref[],
                                        size_t nUnknown, const fmi2ValueReference vKnown_ref[],
                                        size_t nKnown, const fmi2Real dvKnown[],
                                        fmi2Real dvUnknown[]) {
    CoreInstance *s = enter(c, "fmi2GetDirectionalDerivative",
                            CORE_MODE_INITIALIZATION | CORE_MODES_INITIALISED);
    if (s == NULL) return fmi2Error;
    return (fmi2Status)core_directional_derivative(s, "fmi2GetDirectionalDerivative",
                                                   vUnknown_ref, nUnknown, vKnown_ref, nKnown,
                                                   dvKnown, dvUnknown, 0);
}

/* ---- Model Exchange -------------------------------------------------------------------- */

static CoreInstance *enter_model_exchange(fmi2Component c, const char *function,
                                          unsigned int allowed) {
    CoreInstance *s = enter(c, function, allowed);
    if (s == NULL || !require_interface(s, function, CORE_MODEL_EXCHANGE)) return NULL;
    return s;
}

fmi2Status fmi2EnterEventMode(fmi2Component c) {
    CoreInstance *s = enter_model_exchange(c, "fmi2EnterEventMode", ME_MODES);
    if (s == NULL) return fmi2Error;
    core_set_mode(s, CORE_MODE_EVENT);
    return fmi2OK;
}

fmi2Status fmi2NewDiscreteStates(fmi2Component c, fmi2EventInfo *eventInfo) {
    CoreInstance *s = enter_model_exchange(c, "fmi2NewDiscreteStates", CORE_MODE_EVENT);
    if (s == NULL || eventInfo == NULL) return fmi2Error;
    /* no discrete states and no time events; at a state event (contact loss or re-contact, see
     * fmi2GetEventIndicators) nothing changes: the contact force switches on the continuous gap */
    eventInfo->newDiscreteStatesNeeded = fmi2False;
    eventInfo->terminateSimulation = fmi2False;
    eventInfo->nominalsOfContinuousStatesChanged = fmi2False;
    eventInfo->valuesOfContinuousStatesChanged = fmi2False;
    eventInfo->nextEventTimeDefined = fmi2False;
    eventInfo->nextEventTime = 0.0;
    return fmi2OK;
}

fmi2Status fmi2EnterContinuousTimeMode(fmi2Component c) {
    CoreInstance *s = enter_model_exchange(c, "fmi2EnterContinuousTimeMode", CORE_MODE_EVENT);
    if (s == NULL) return fmi2Error;
    core_set_mode(s, CORE_MODE_CONTINUOUS_TIME);
    return fmi2OK;
}

fmi2Status fmi2CompletedIntegratorStep(fmi2Component c,
                                       fmi2Boolean noSetFMUStatePriorToCurrentPoint,
                                       fmi2Boolean *enterEventMode,
                                       fmi2Boolean *terminateSimulation) {
    (void)noSetFMUStatePriorToCurrentPoint;
    CoreInstance *s = enter_model_exchange(c, "fmi2CompletedIntegratorStep",
                                           CORE_MODE_CONTINUOUS_TIME);
    if (s == NULL || enterEventMode == NULL || terminateSimulation == NULL) return fmi2Error;
    *enterEventMode = fmi2False;
    *terminateSimulation = fmi2False;
    return fmi2OK;
}

fmi2Status fmi2SetTime(fmi2Component c, fmi2Real time) {
    CoreInstance *s = enter_model_exchange(c, "fmi2SetTime", ME_MODES);
    if (s == NULL) return fmi2Error;
    if (!isfinite(time)) {
        core_log_error(s, "fmi2SetTime: time = %g is not a finite number", time);
        return fmi2Error;
    }
    s->time = time;
    return fmi2OK;
}

fmi2Status fmi2SetContinuousStates(fmi2Component c, const fmi2Real x[], size_t nx) {
    CoreInstance *s = enter_model_exchange(c, "fmi2SetContinuousStates", ME_MODES);
    if (s == NULL || !check_count(s, "fmi2SetContinuousStates", nx, (size_t)s->nx, x)) {
        return fmi2Error;
    }
    for (size_t i = 0; i < nx; i++) {
        if (!isfinite(x[i])) {
            core_log_error(s, "fmi2SetContinuousStates: state %zu = %g is not a finite number", i,
                           x[i]);
            return fmi2Error;
        }
    }
    memcpy(s->x, x, nx * sizeof(double));
    core_touch(s);
    return fmi2OK;
}

fmi2Status fmi2GetDerivatives(fmi2Component c, fmi2Real derivatives[], size_t nx) {
    CoreInstance *s = enter_model_exchange(c, "fmi2GetDerivatives",
                                           CORE_MODE_INITIALIZATION | ME_MODES |
                                               CORE_MODE_TERMINATED | CORE_MODE_ERROR);
    if (s == NULL || !check_count(s, "fmi2GetDerivatives", nx, (size_t)s->nx, derivatives)) {
        return fmi2Error;
    }
    if (core_update_cache(s) != CORE_OK) return (fmi2Status)core_fail(s);
    memcpy(derivatives, s->cached_derivatives, nx * sizeof(double));
    return fmi2OK;
}

fmi2Status fmi2GetEventIndicators(fmi2Component c, fmi2Real eventIndicators[], size_t ni) {
    CoreInstance *s = enter_model_exchange(c, "fmi2GetEventIndicators", CORE_MODES_ANY);
    if (s == NULL || !check_count(s, "fmi2GetEventIndicators", ni,
                                  (size_t)core_number_of_event_indicators(), eventIndicators)) {
        return fmi2Error;
    }
    if (core_event_indicators(s, "fmi2GetEventIndicators", eventIndicators) != CORE_OK) {
        return (fmi2Status)core_fail(s);
    }
    return fmi2OK;
}

fmi2Status fmi2GetContinuousStates(fmi2Component c, fmi2Real x[], size_t nx) {
    CoreInstance *s = enter_model_exchange(c, "fmi2GetContinuousStates", CORE_MODES_ANY);
    if (s == NULL || !check_count(s, "fmi2GetContinuousStates", nx, (size_t)s->nx, x)) {
        return fmi2Error;
    }
    const double *state;
    if (core_effective_state(s, &state) != CORE_OK ||
        !core_check_finite(s, "fmi2GetContinuousStates", CORE_VARIABLE_STATE, state, nx)) {
        return (fmi2Status)core_fail(s);
    }
    memcpy(x, state, nx * sizeof(double));
    return fmi2OK;
}

fmi2Status fmi2GetNominalsOfContinuousStates(fmi2Component c, fmi2Real x_nominal[], size_t nx) {
    CoreInstance *s = enter_model_exchange(c, "fmi2GetNominalsOfContinuousStates",
                                           CORE_MODES_ANY);
    if (s == NULL ||
        !check_count(s, "fmi2GetNominalsOfContinuousStates", nx, (size_t)s->nx, x_nominal)) {
        return fmi2Error;
    }
    core_state_nominals(x_nominal);
    return fmi2OK;
}

/* ---- Co-Simulation --------------------------------------------------------------------- */

static CoreInstance *enter_co_simulation(fmi2Component c, const char *function,
                                         unsigned int allowed) {
    CoreInstance *s = enter(c, function, allowed);
    if (s == NULL || !require_interface(s, function, CORE_CO_SIMULATION)) return NULL;
    return s;
}

fmi2Status fmi2SetRealInputDerivatives(fmi2Component c, const fmi2ValueReference vr[],
                                       size_t nvr, const fmi2Integer order[],
                                       const fmi2Real value[]) {
    (void)vr;
    (void)order;
    (void)value;
    CoreInstance *s = enter_co_simulation(c, "fmi2SetRealInputDerivatives", CORE_MODES_ANY);
    if (s == NULL) return fmi2Error;
    core_log_error(s, "fmi2SetRealInputDerivatives: not supported, the inputs are held constant "
                   "over a step (canInterpolateInputs = false); %zu values refused", nvr);
    return fmi2Error;
}

fmi2Status fmi2GetRealOutputDerivatives(fmi2Component c, const fmi2ValueReference vr[],
                                        size_t nvr, const fmi2Integer order[],
                                        fmi2Real value[]) {
    (void)vr;
    (void)order;
    (void)value;
    CoreInstance *s = enter_co_simulation(c, "fmi2GetRealOutputDerivatives", CORE_MODES_ANY);
    if (s == NULL) return fmi2Error;
    core_log_error(s, "fmi2GetRealOutputDerivatives: not supported (maxOutputDerivativeOrder = "
                   "0); %zu values asked for", nvr);
    return fmi2Error;
}

fmi2Status fmi2DoStep(fmi2Component c, fmi2Real currentCommunicationPoint,
                      fmi2Real communicationStepSize,
                      fmi2Boolean noSetFMUStatePriorToCurrentPoint) {
    (void)noSetFMUStatePriorToCurrentPoint;
    CoreInstance *s = enter_co_simulation(c, "fmi2DoStep", CORE_MODE_STEP);
    if (s == NULL) return fmi2Error;
    const double t = currentCommunicationPoint, h = communicationStepSize;
    if (core_check_step(s, "fmi2DoStep", t, h) != CORE_OK) return fmi2Error;
    s->time = t;
    s->last_step_status = core_do_step(s, t, h);
    if (s->last_step_status == CORE_DISCARD) return fmi2Discard; /* the instance stays usable */
    if (s->last_step_status != CORE_OK) return (fmi2Status)core_fail(s);
    return fmi2OK;
}

fmi2Status fmi2CancelStep(fmi2Component c) {
    CoreInstance *s = enter_co_simulation(c, "fmi2CancelStep", CORE_MODES_ANY);
    if (s == NULL) return fmi2Error;
    core_log_error(s, "fmi2CancelStep: fmi2DoStep runs synchronously, there is no step to cancel");
    return fmi2Error;
}

static fmi2Status refuse_status(CoreInstance *s, const char *function, fmi2StatusKind kind) {
    core_log_error(s, "%s: status kind %d is not provided (no asynchronous steps)", function,
                   (int)kind);
    return fmi2Error;
}

fmi2Status fmi2GetStatus(fmi2Component c, const fmi2StatusKind kind, fmi2Status *value) {
    CoreInstance *s = enter_co_simulation(c, "fmi2GetStatus", DIAGNOSTIC_MODES);
    if (s == NULL || value == NULL) return fmi2Error;
    if (kind != fmi2DoStepStatus) return refuse_status(s, "fmi2GetStatus", kind);
    *value = (fmi2Status)s->last_step_status;
    return fmi2OK;
}

fmi2Status fmi2GetRealStatus(fmi2Component c, const fmi2StatusKind kind, fmi2Real *value) {
    CoreInstance *s = enter_co_simulation(c, "fmi2GetRealStatus", DIAGNOSTIC_MODES);
    if (s == NULL || value == NULL) return fmi2Error;
    if (kind != fmi2LastSuccessfulTime) return refuse_status(s, "fmi2GetRealStatus", kind);
    *value = s->last_successful_time;
    return fmi2OK;
}

fmi2Status fmi2GetIntegerStatus(fmi2Component c, const fmi2StatusKind kind, fmi2Integer *value) {
    (void)value;
    CoreInstance *s = enter_co_simulation(c, "fmi2GetIntegerStatus", DIAGNOSTIC_MODES);
    if (s == NULL) return fmi2Error;
    return refuse_status(s, "fmi2GetIntegerStatus", kind);
}

fmi2Status fmi2GetBooleanStatus(fmi2Component c, const fmi2StatusKind kind, fmi2Boolean *value) {
    CoreInstance *s = enter_co_simulation(c, "fmi2GetBooleanStatus", DIAGNOSTIC_MODES);
    if (s == NULL || value == NULL) return fmi2Error;
    if (kind != fmi2Terminated) return refuse_status(s, "fmi2GetBooleanStatus", kind);
    *value = fmi2False; /* the model never asks to stop the simulation */
    return fmi2OK;
}

fmi2Status fmi2GetStringStatus(fmi2Component c, const fmi2StatusKind kind, fmi2String *value) {
    (void)value;
    CoreInstance *s = enter_co_simulation(c, "fmi2GetStringStatus", DIAGNOSTIC_MODES);
    if (s == NULL) return fmi2Error;
    return refuse_status(s, "fmi2GetStringStatus", kind);
}
