/*
 * Internal helpers shared by the FMI 3.0 front-end files (fmi3_functions.c,
 * fmi3_model_structure.c, fmi3_unsupported.c): the front end's own data and the checks every
 * function starts with. Each check logs an error naming the function when it fails.
 */
#ifndef FMI3_FRONT_END_H
#define FMI3_FRONT_END_H

#include "fmi3Functions.h"
#include "fmu_core.h"

#define ME_MODES (CORE_MODE_EVENT | CORE_MODE_CONTINUOUS_TIME)
#define ANY CORE_MODES_ANY

/* What the front end keeps besides the core instance. */
typedef struct {
    fmi3InstanceEnvironment environment;
    fmi3LogMessageCallback log_message;
    int event_mode_used;
} Fmi3FrontEnd;

static inline CoreInstance *enter(fmi3Instance instance, const char *function,
                                  unsigned int allowed) {
    CoreInstance *s = (CoreInstance *)instance;
    if (s == NULL || !core_check_mode(s, function, allowed)) return NULL;
    return s;
}

static inline CoreInstance *enter_interface(fmi3Instance instance, const char *function,
                                            unsigned int allowed, CoreInterfaceType type) {
    CoreInstance *s = enter(instance, function, allowed);
    if (s == NULL) return NULL;
    if (s->interface_type != type) {
        core_log_error(s, "%s is only available in %s", function,
                       type == CORE_MODEL_EXCHANGE ? "Model Exchange" : "Co-Simulation");
        return NULL;
    }
    return s;
}

static inline int check_scalars(CoreInstance *s, const char *function, size_t nvr,
                                size_t nValues) {
    if (nvr == nValues) return 1;
    core_log_error(s, "%s: %zu values for %zu value references (all variables are scalars)",
                   function, nValues, nvr);
    return 0;
}

static inline int check_count(CoreInstance *s, const char *function, size_t given,
                              size_t expected, const void *array) {
    if (given == expected && (given == 0 || array != NULL)) return 1;
    core_log_error(s, "%s: expected %zu values, got %zu%s", function, expected, given,
                   given > 0 && array == NULL ? " and a NULL array" : "");
    return 0;
}

static inline fmi3Status refuse(fmi3Instance instance, const char *function,
                                const char *reason) {
    CoreInstance *s = (CoreInstance *)instance;
    if (s != NULL) core_log_error(s, "%s: %s", function, reason);
    return fmi3Error;
}

#endif
