/*
 * The parts of the FMI 3.0 API this model does not use: getters and setters of every type other
 * than Float64 and Boolean, clocks, configuration mode and Scheduled Execution. Each exists (an
 * importer may look them up) and refuses with fmi3Error and a log message naming the function.
 */
#include "fmi3_front_end.h"

/* ---- every other type: the model has no such variables -------------------------------- */

#define REFUSE_GET(Type, CType)                                                                \
    fmi3Status fmi3Get##Type(fmi3Instance instance, const fmi3ValueReference valueReferences[], \
                             size_t nValueReferences, CType values[], size_t nValues) {        \
        (void)valueReferences;                                                                 \
        (void)values;                                                                          \
        (void)nValues;                                                                         \
        CoreInstance *s = enter(instance, "fmi3Get" #Type, ANY);                               \
        return s == NULL ? fmi3Error                                                           \
                         : (fmi3Status)core_refuse_type(s, "fmi3Get" #Type, #Type,             \
                                                        nValueReferences);                     \
    }
#define REFUSE_SET(Type, CType)                                                                \
    fmi3Status fmi3Set##Type(fmi3Instance instance, const fmi3ValueReference valueReferences[], \
                             size_t nValueReferences, const CType values[], size_t nValues) {  \
        (void)valueReferences;                                                                 \
        (void)values;                                                                          \
        (void)nValues;                                                                         \
        CoreInstance *s = enter(instance, "fmi3Set" #Type, ANY);                               \
        return s == NULL ? fmi3Error                                                           \
                         : (fmi3Status)core_refuse_type(s, "fmi3Set" #Type, #Type,             \
                                                        nValueReferences);                     \
    }
#define REFUSE_TYPE(Type, CType) REFUSE_GET(Type, CType) REFUSE_SET(Type, CType)

REFUSE_TYPE(Float32, fmi3Float32)
REFUSE_TYPE(Int8, fmi3Int8)
REFUSE_TYPE(UInt8, fmi3UInt8)
REFUSE_TYPE(Int16, fmi3Int16)
REFUSE_TYPE(UInt16, fmi3UInt16)
REFUSE_TYPE(Int32, fmi3Int32)
REFUSE_TYPE(UInt32, fmi3UInt32)
REFUSE_TYPE(Int64, fmi3Int64)
REFUSE_TYPE(UInt64, fmi3UInt64)
REFUSE_TYPE(String, fmi3String)

fmi3Status fmi3GetBinary(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                         size_t nValueReferences, size_t valueSizes[], fmi3Binary values[],
                         size_t nValues) {
    (void)valueReferences;
    (void)valueSizes;
    (void)values;
    (void)nValues;
    CoreInstance *s = enter(instance, "fmi3GetBinary", ANY);
    return s == NULL ? fmi3Error
                     : (fmi3Status)core_refuse_type(s, "fmi3GetBinary", "Binary", nValueReferences);
}

fmi3Status fmi3SetBinary(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                         size_t nValueReferences, const size_t valueSizes[],
                         const fmi3Binary values[], size_t nValues) {
    (void)valueReferences;
    (void)valueSizes;
    (void)values;
    (void)nValues;
    CoreInstance *s = enter(instance, "fmi3SetBinary", ANY);
    return s == NULL ? fmi3Error
                     : (fmi3Status)core_refuse_type(s, "fmi3SetBinary", "Binary", nValueReferences);
}

fmi3Status fmi3GetClock(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                        size_t nValueReferences, fmi3Clock values[]) {
    (void)valueReferences;
    (void)values;
    CoreInstance *s = enter(instance, "fmi3GetClock", ANY);
    return s == NULL ? fmi3Error
                     : (fmi3Status)core_refuse_type(s, "fmi3GetClock", "Clock", nValueReferences);
}

fmi3Status fmi3SetClock(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                        size_t nValueReferences, const fmi3Clock values[]) {
    (void)valueReferences;
    (void)values;
    CoreInstance *s = enter(instance, "fmi3SetClock", ANY);
    return s == NULL ? fmi3Error
                     : (fmi3Status)core_refuse_type(s, "fmi3SetClock", "Clock", nValueReferences);
}

/* ---- configuration mode and clocks: not used by this model ----------------------------- */

fmi3Status fmi3EnterConfigurationMode(fmi3Instance instance) {
    return refuse(instance, "fmi3EnterConfigurationMode", "the model has no structural parameters");
}

fmi3Status fmi3ExitConfigurationMode(fmi3Instance instance) {
    return refuse(instance, "fmi3ExitConfigurationMode", "the model has no structural parameters");
}

#define NO_CLOCKS "the model has no clocks"

fmi3Status fmi3GetIntervalDecimal(fmi3Instance instance, const fmi3ValueReference vr[],
                                  size_t n, fmi3Float64 intervals[],
                                  fmi3IntervalQualifier qualifiers[]) {
    (void)vr, (void)n, (void)intervals, (void)qualifiers;
    return refuse(instance, "fmi3GetIntervalDecimal", NO_CLOCKS);
}

fmi3Status fmi3GetIntervalFraction(fmi3Instance instance, const fmi3ValueReference vr[],
                                   size_t n, fmi3UInt64 counters[], fmi3UInt64 resolutions[],
                                   fmi3IntervalQualifier qualifiers[]) {
    (void)vr, (void)n, (void)counters, (void)resolutions, (void)qualifiers;
    return refuse(instance, "fmi3GetIntervalFraction", NO_CLOCKS);
}

fmi3Status fmi3GetShiftDecimal(fmi3Instance instance, const fmi3ValueReference vr[], size_t n,
                               fmi3Float64 shifts[]) {
    (void)vr, (void)n, (void)shifts;
    return refuse(instance, "fmi3GetShiftDecimal", NO_CLOCKS);
}

fmi3Status fmi3GetShiftFraction(fmi3Instance instance, const fmi3ValueReference vr[], size_t n,
                                fmi3UInt64 counters[], fmi3UInt64 resolutions[]) {
    (void)vr, (void)n, (void)counters, (void)resolutions;
    return refuse(instance, "fmi3GetShiftFraction", NO_CLOCKS);
}

fmi3Status fmi3SetIntervalDecimal(fmi3Instance instance, const fmi3ValueReference vr[],
                                  size_t n, const fmi3Float64 intervals[]) {
    (void)vr, (void)n, (void)intervals;
    return refuse(instance, "fmi3SetIntervalDecimal", NO_CLOCKS);
}

fmi3Status fmi3SetIntervalFraction(fmi3Instance instance, const fmi3ValueReference vr[],
                                   size_t n, const fmi3UInt64 counters[],
                                   const fmi3UInt64 resolutions[]) {
    (void)vr, (void)n, (void)counters, (void)resolutions;
    return refuse(instance, "fmi3SetIntervalFraction", NO_CLOCKS);
}

fmi3Status fmi3SetShiftDecimal(fmi3Instance instance, const fmi3ValueReference vr[], size_t n,
                               const fmi3Float64 shifts[]) {
    (void)vr, (void)n, (void)shifts;
    return refuse(instance, "fmi3SetShiftDecimal", NO_CLOCKS);
}

fmi3Status fmi3SetShiftFraction(fmi3Instance instance, const fmi3ValueReference vr[], size_t n,
                                const fmi3UInt64 counters[], const fmi3UInt64 resolutions[]) {
    (void)vr, (void)n, (void)counters, (void)resolutions;
    return refuse(instance, "fmi3SetShiftFraction", NO_CLOCKS);
}

fmi3Status fmi3ActivateModelPartition(fmi3Instance instance, fmi3ValueReference clockReference,
                                      fmi3Float64 activationTime) {
    (void)clockReference, (void)activationTime;
    return refuse(instance, "fmi3ActivateModelPartition", "Scheduled Execution is not supported");
}

/* ---- Scheduled Execution ------------------------------------------------------------- */

fmi3Instance fmi3InstantiateScheduledExecution(
    fmi3String instanceName, fmi3String instantiationToken, fmi3String resourcePath,
    fmi3Boolean visible, fmi3Boolean loggingOn, fmi3InstanceEnvironment instanceEnvironment,
    fmi3LogMessageCallback logMessage, fmi3ClockUpdateCallback clockUpdate,
    fmi3LockPreemptionCallback lockPreemption, fmi3UnlockPreemptionCallback unlockPreemption) {
    (void)instanceName;
    (void)instantiationToken;
    (void)resourcePath;
    (void)visible;
    (void)loggingOn;
    (void)clockUpdate;
    (void)lockPreemption;
    (void)unlockPreemption;
    if (logMessage != NULL) {
        logMessage(instanceEnvironment, fmi3Error, "logStatusError",
                   "fmi3InstantiateScheduledExecution: this FMU does not support Scheduled "
                   "Execution");
    }
    return NULL;
}
