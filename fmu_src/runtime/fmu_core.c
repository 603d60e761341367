/*
 * Instance life cycle, the generated variable table, get/set of values, FMU state snapshots and
 * logging, shared by the FMI 2.0 and FMI 3.0 front ends. See fmu_core.h.
 */
#include "fmu_core.h"

#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <string.h>

#include "model_config.h" /* generated: MODEL_VARIABLES, MODEL_INSTANTIATION_TOKEN, ... */

static const char *const LOG_CATEGORIES[] = {
    "logStatusError", "logStatusWarning", "logEvents", "logNonlinearSystems", "logSolver",
    "logStatusDiscard"};
#define NUMBER_OF_LOG_CATEGORIES ((int)(sizeof(LOG_CATEGORIES) / sizeof(LOG_CATEGORIES[0])))

/* ---- variable table -------------------------------------------------------------------- */

const char *core_instantiation_token(void) { return MODEL_INSTANTIATION_TOKEN; }

int core_number_of_variables(void) { return MODEL_NUMBER_OF_VARIABLES; }

const CoreVariable *core_find_variable(const CoreInstance *instance, const char *function,
                                       unsigned int value_reference) {
    if (value_reference >= (unsigned int)MODEL_NUMBER_OF_VARIABLES) {
        core_log_error(instance, "%s: unknown value reference %u (the model has %d variables)",
                       function, value_reference, MODEL_NUMBER_OF_VARIABLES);
        return NULL;
    }
    return &MODEL_VARIABLES[value_reference];
}

const char *core_variable_name(CoreVariableKind kind, int index) {
    for (int i = 0; i < MODEL_NUMBER_OF_VARIABLES; i++) {
        if (MODEL_VARIABLES[i].kind == kind && MODEL_VARIABLES[i].index == index) {
            return MODEL_VARIABLES[i].name;
        }
    }
    return "?";
}

int core_check_finite(const CoreInstance *instance, const char *function, CoreVariableKind kind,
                      const double values[], size_t n) {
    for (size_t i = 0; i < n; i++) {
        if (isfinite(values[i])) continue;
        core_log_error(instance, "%s: %s = %g is not a finite number at t = %g (the states, "
                       "inputs or parameters lie outside the range where model %s can be "
                       "evaluated)", function, core_variable_name(kind, (int)i), values[i],
                       instance->time, MODEL_IDENTIFIER);
        return 0;
    }
    return 1;
}

int core_number_of_event_indicators(void) { return MODEL_NUMBER_OF_EVENT_INDICATORS; }

CoreStatus core_event_indicators(CoreInstance *s, const char *function, double z[]) {
#if MODEL_NUMBER_OF_EVENT_INDICATORS > 0
    const double *x;
    if (core_prepare(s) != CORE_OK || core_effective_state(s, &x) != CORE_OK) return CORE_ERROR;
    s->model_message[0] = '\0';
    if (model_event_indicators(s->p, x, x + s->nq, s->u, z, s->model_message) != 0) {
        s->model_message[MODEL_MESSAGE_LENGTH - 1] = '\0';
        core_log_error(s, "%s: model %s cannot compute its event indicators at t = %g: %s",
                       function, MODEL_IDENTIFIER, s->time, s->model_message);
        return CORE_ERROR;
    }
    if (!core_check_finite(s, function, CORE_VARIABLE_EVENT_INDICATOR, z,
                           MODEL_NUMBER_OF_EVENT_INDICATORS)) {
        return CORE_ERROR;
    }
#else
    (void)s;
    (void)function;
    (void)z;
#endif
    return CORE_OK;
}

void core_state_nominals(double nominals[]) {
    for (int i = 0; i < MODEL_NUMBER_OF_VARIABLES; i++) {
        const CoreVariable *v = &MODEL_VARIABLES[i];
        if (v->kind == CORE_VARIABLE_STATE) nominals[v->index] = v->nominal;
    }
}

int core_dependency_kind(const CoreInstance *instance, int row, int column) {
    return MODEL_DEPENDENCIES[row * (instance->nx + instance->nu) + column];
}

CoreStatus core_check_tolerance(const CoreInstance *instance, const char *function,
                                double tolerance) {
    if (!(tolerance >= CORE_SMALLEST_TOLERANCE && tolerance < 1.0)) {
        core_log_error(instance, "%s: tolerance = %g is refused: it must lie in [%g, 1) (below, "
                       "double precision cannot honour it)", function, tolerance,
                       CORE_SMALLEST_TOLERANCE);
        return CORE_ERROR;
    }
    if (tolerance < CORE_MINIMUM_TOLERANCE) {
        core_log(instance, CORE_WARNING, "logStatusWarning", "%s: tolerance = %g is below %g, "
                 "the smallest the co-simulation integrator honours; it uses %g", function,
                 tolerance, CORE_MINIMUM_TOLERANCE, CORE_MINIMUM_TOLERANCE);
        return CORE_WARNING;
    }
    return CORE_OK;
}

CoreStatus core_check_step(const CoreInstance *instance, const char *function,
                           double current_time, double step) {
    const char *problem = NULL;
    if (instance->last_step_status == CORE_DISCARD) {
        problem = "the previous step was discarded (restore an FMU state or reset the FMU first)";
    } else if (!isfinite(current_time) || !isfinite(step)) problem = "not a finite number";
    else if (step < 0.0) problem = "a negative step";
    else if (fabs(current_time - instance->time) > 1e-9 * fmax(1.0, fabs(current_time))) {
        problem = "not from the FMU's time";
    } else if (step > 0.0 && !(current_time + step > current_time)) {
        problem = "too small to advance the time in double precision";
    } else if (!isfinite(current_time + step)) {
        problem = "ending at a time that is not a finite number";
    }
    if (problem == NULL) return CORE_OK;
    core_log_error(instance, "%s: the step from t = %.17g of size %.17g is refused: %s (the FMU "
                   "is at t = %.17g)", function, current_time, step, problem, instance->time);
    return CORE_ERROR;
}

static int count_kind(CoreVariableKind kind) {
    int count = 0;
    for (int i = 0; i < MODEL_NUMBER_OF_VARIABLES; i++) {
        if (MODEL_VARIABLES[i].kind == kind) count++;
    }
    return count;
}

/* The generated table must describe the compiled model (same NQ, NU, NY, NP). */
static int check_variable_table(const CoreInstance *instance) {
    const int expected_operating_points = instance->linearised ? MODEL_NU : 0;
    if (count_kind(CORE_VARIABLE_STATE) != 2 * MODEL_NQ ||
        count_kind(CORE_VARIABLE_DERIVATIVE) != 2 * MODEL_NQ ||
        count_kind(CORE_VARIABLE_INPUT) != MODEL_NU ||
        count_kind(CORE_VARIABLE_OUTPUT) != MODEL_NY ||
        count_kind(CORE_VARIABLE_PARAMETER) != MODEL_NP ||
        count_kind(CORE_VARIABLE_OPERATING_POINT) != expected_operating_points ||
        count_kind(CORE_VARIABLE_EVENT_INDICATOR) != MODEL_NUMBER_OF_EVENT_INDICATORS) {
        core_log_error(instance,
                       "the variable table in model_config.h does not match model %s "
                       "(NQ = %d, NU = %d, NY = %d, NP = %d): rebuild the FMU",
                       MODEL_IDENTIFIER, MODEL_NQ, MODEL_NU, MODEL_NY, MODEL_NP);
        return 0;
    }
    return 1;
}

/* ---- logging --------------------------------------------------------------------------- */

static int category_index(const char *category) {
    for (int i = 0; i < NUMBER_OF_LOG_CATEGORIES; i++) {
        if (strcmp(LOG_CATEGORIES[i], category) == 0) return i;
    }
    return -1;
}

void core_log(const CoreInstance *instance, CoreStatus status, const char *category,
              const char *format, ...) {
    if (instance == NULL) return;
    char buffer[CORE_LOG_LENGTH];
    va_list arguments;
    va_start(arguments, format);
    vsnprintf(buffer, sizeof(buffer), format, arguments);
    va_end(arguments);
    if (status >= CORE_ERROR) {
        /* keeping the last error is the one change logging makes to an instance */
        CoreInstance *writable = (CoreInstance *)instance;
        snprintf(writable->last_error, sizeof(writable->last_error), "%s", buffer);
        if (instance->errors_suppressed) return;
    }
    if (instance->log == NULL) return;
    if (status < CORE_WARNING) {
        const int index = category_index(category);
        if (!instance->logging_on || index < 0 || !(instance->log_categories & (1u << index))) {
            return;
        }
    }
    instance->log(instance, status, category, buffer);
}

CoreStatus core_set_debug_logging(CoreInstance *instance, int logging_on, size_t n_categories,
                                  const char *const categories[]) {
    instance->logging_on = logging_on;
    if (n_categories == 0) {
        instance->log_categories = (1u << NUMBER_OF_LOG_CATEGORIES) - 1u;
        return CORE_OK;
    }
    if (categories == NULL) {
        core_log_error(instance, "SetDebugLogging: %zu categories announced but none passed",
                       n_categories);
        return CORE_ERROR;
    }
    unsigned int mask = 0;
    for (size_t i = 0; i < n_categories; i++) {
        const int index = categories[i] ? category_index(categories[i]) : -1;
        if (index < 0) {
            core_log_error(instance, "SetDebugLogging: unknown log category '%s'",
                           categories[i] ? categories[i] : "(null)");
            return CORE_ERROR;
        }
        mask |= 1u << index;
    }
    instance->log_categories = mask;
    return CORE_OK;
}

/* ---- state machine --------------------------------------------------------------------- */

const char *core_mode_name(CoreMode mode) {
    switch (mode) {
        case CORE_MODE_INSTANTIATED: return "Instantiated";
        case CORE_MODE_INITIALIZATION: return "Initialization Mode";
        case CORE_MODE_EVENT: return "Event Mode";
        case CORE_MODE_CONTINUOUS_TIME: return "Continuous-Time Mode";
        case CORE_MODE_STEP: return "Step Mode";
        case CORE_MODE_TERMINATED: return "Terminated";
        case CORE_MODE_ERROR: return "Error";
    }
    return "unknown mode";
}

int core_check_mode(const CoreInstance *instance, const char *function, unsigned int allowed) {
    if (instance->mode & allowed) return 1;
    char list[256] = "";
    for (unsigned int bit = 1; bit <= CORE_MODE_ERROR; bit <<= 1) {
        if (!(allowed & bit)) continue;
        if (list[0] != '\0') strncat(list, ", ", sizeof(list) - strlen(list) - 1);
        strncat(list, core_mode_name((CoreMode)bit), sizeof(list) - strlen(list) - 1);
    }
    core_log_error(instance, "%s is not allowed in %s (allowed in: %s)", function,
                   core_mode_name(instance->mode), list);
    return 0;
}

void core_set_mode(CoreInstance *instance, CoreMode mode) {
    core_log(instance, CORE_OK, "logEvents", "%s -> %s", core_mode_name(instance->mode),
             core_mode_name(mode));
    instance->mode = mode;
}

CoreStatus core_fail(CoreInstance *instance) {
    if (instance->mode == CORE_MODE_ERROR) return CORE_ERROR;
    core_log(instance, CORE_OK, "logEvents", "%s -> %s: %s", core_mode_name(instance->mode),
             core_mode_name(CORE_MODE_ERROR),
             instance->last_error[0] ? instance->last_error : "(no message)");
    instance->mode = CORE_MODE_ERROR;
    return CORE_ERROR;
}

void core_touch(CoreInstance *instance) { instance->cache_valid = 0; }

void core_invalidate_parameters(CoreInstance *instance) {
    instance->parameters_checked = 0;
    instance->linearisation_valid = 0;
    instance->prepare_failed = 0;
    instance->initial_state_valid = 0;
    instance->cache_valid = 0;
}

/* ---- life cycle ------------------------------------------------------------------------ */

static double *take(double **cursor, size_t count) {
    double *block = *cursor;
    *cursor += count;
    return block;
}

/* All arrays of one instance in one block of doubles (sizes in model_interface.h order). */
static int allocate_arrays(CoreInstance *s) {
    const size_t nq = (size_t)s->nq, nx = (size_t)s->nx, nu = (size_t)s->nu;
    const size_t ny = (size_t)s->ny, np = (size_t)s->np;
    const size_t total = nx + nu + np + nu                                   /* values */
                         + nq + ny + nx * nx + nx * nu + ny * nx + ny * nu    /* linearisation */
                         + nx + ny + nx                                      /* caches */
                         + nq * nq + nq * nq * nq + 3 * nq + 2 * nq * nq + nq * nu
                         + 2 * ny * nq + ny * nu + (nx + ny) * (nx + nu) + nx
                         + 4 * nq + nq * nq + nx * nx + 10 * nx + nu + 1;
    double *cursor = s->allocate(total, sizeof(double));
    s->work.pivots = s->allocate(2 * nx + 1, sizeof(int));
    if (cursor == NULL || s->work.pivots == NULL) {
        if (cursor) s->release(cursor);
        if (s->work.pivots) s->release(s->work.pivots);
        return 0;
    }
    s->work.w_pivots = s->work.pivots + nx;
    s->x = take(&cursor, nx);
    s->u = take(&cursor, nu);
    s->p = take(&cursor, np);
    s->u0 = take(&cursor, nu);
    s->q0 = take(&cursor, nq);
    s->y0 = take(&cursor, ny);
    s->a_matrix = take(&cursor, nx * nx);
    s->b_matrix = take(&cursor, nx * nu);
    s->c_matrix = take(&cursor, ny * nx);
    s->d_matrix = take(&cursor, ny * nu);
    s->cached_derivatives = take(&cursor, nx);
    s->cached_outputs = take(&cursor, ny);
    s->initial_x = take(&cursor, nx);
    CoreWorkspace *w = &s->work;
    w->mass = take(&cursor, nq * nq);
    w->mass_derivative = take(&cursor, nq * nq * nq);
    w->forces = take(&cursor, nq);
    w->acceleration = take(&cursor, nq);
    w->column = take(&cursor, nq);
    w->dr_dq = take(&cursor, nq * nq);
    w->dr_dv = take(&cursor, nq * nq);
    w->dr_du = take(&cursor, nq * nu);
    w->dy_dq = take(&cursor, ny * nq);
    w->dy_dv = take(&cursor, ny * nq);
    w->dy_du = take(&cursor, ny * nu);
    w->jacobian = take(&cursor, (nx + ny) * (nx + nu));
    w->point = take(&cursor, nx);
    w->zeros = take(&cursor, nx);
    w->input_deviation = take(&cursor, nu);
    w->newton_q = take(&cursor, nq);
    w->newton_step = take(&cursor, nq);
    w->newton_trial = take(&cursor, nq);
    w->newton_residual = take(&cursor, nq);
    w->newton_matrix = take(&cursor, nq * nq);
    w->w_matrix = take(&cursor, nx * nx);
    for (int i = 0; i < 6; i++) w->k[i] = take(&cursor, nx);
    w->stage = take(&cursor, nx);
    w->rhs = take(&cursor, nx);
    w->x_new = take(&cursor, nx);
    return 1;
}

CoreInstance *core_instantiate(const char *instance_name, CoreInterfaceType interface_type,
                               CoreLogFunction log, CoreAllocateFunction allocate,
                               CoreFreeFunction release, const void *front_end,
                               size_t front_end_size, int logging_on) {
    /* A stand-in on the stack so that errors before allocation can be logged. */
    CoreInstance early;
    memset(&early, 0, sizeof(early));
    early.instance_name = (char *)(instance_name ? instance_name : "");
    early.log = log;
    early.front_end = (void *)front_end;
#ifdef MODEL_LINEARISED
    early.linearised = 1;
#endif
    if (!check_variable_table(&early)) return NULL;

    CoreInstance *s = allocate(1, sizeof(CoreInstance));
    if (s == NULL) {
        core_log_error(&early, "Instantiate: out of memory");
        return NULL;
    }
    *s = early;
    s->allocate = allocate;
    s->release = release;
    s->interface_type = interface_type;
    s->logging_on = logging_on;
    s->log_categories = (1u << NUMBER_OF_LOG_CATEGORIES) - 1u;
    s->nq = MODEL_NQ;
    s->nx = 2 * MODEL_NQ;
    s->nu = MODEL_NU;
    s->ny = MODEL_NY;
    s->np = MODEL_NP;
    s->instance_name = allocate(strlen(early.instance_name) + 1, 1);
    s->front_end = allocate(front_end_size > 0 ? front_end_size : 1, 1);
    if (s->instance_name == NULL || s->front_end == NULL || !allocate_arrays(s)) {
        core_log_error(&early, "Instantiate: out of memory");
        if (s->instance_name) release(s->instance_name);
        if (s->front_end) release(s->front_end);
        release(s);
        return NULL;
    }
    strcpy(s->instance_name, early.instance_name);
    if (front_end_size > 0) memcpy(s->front_end, front_end, front_end_size);
    core_reset(s);
    return s;
}

void core_free(CoreInstance *instance) {
    if (instance == NULL) return;
    CoreFreeFunction release = instance->release;
    release(instance->x); /* start of the block of doubles */
    release(instance->work.pivots);
    release(instance->instance_name);
    release(instance->front_end);
    release(instance);
}

/* Back to the state right after instantiation: start values from the variable table. */
void core_reset(CoreInstance *instance) {
    for (int i = 0; i < MODEL_NUMBER_OF_VARIABLES; i++) {
        const CoreVariable *v = &MODEL_VARIABLES[i];
        switch (v->kind) {
            case CORE_VARIABLE_STATE: instance->x[v->index] = v->start; break;
            case CORE_VARIABLE_INPUT: instance->u[v->index] = v->start; break;
            case CORE_VARIABLE_PARAMETER: instance->p[v->index] = v->start; break;
            case CORE_VARIABLE_OPERATING_POINT: instance->u0[v->index] = v->start; break;
            case CORE_VARIABLE_SOLVER_TOLERANCE: instance->solver_tolerance = v->start; break;
            case CORE_VARIABLE_START_IN_EQUILIBRIUM:
                instance->start_in_equilibrium = v->start != 0.0;
                break;
            default: break;
        }
    }
    instance->mode = CORE_MODE_INSTANTIATED;
    instance->time = 0.0;
    instance->experiment_tolerance = 0.0;
    instance->step_size = 0.0;
    instance->last_successful_time = 0.0;
    instance->last_step_status = CORE_OK;
    instance->substeps = 0;
    core_invalidate_parameters(instance);
}

/* ---- get and set ----------------------------------------------------------------------- */

static const char *type_name(CoreVariableType type) {
    return type == CORE_TYPE_REAL ? "Real" : "Boolean";
}

/* Look up all value references and check their type before touching anything. */
static const CoreVariable *find_typed(CoreInstance *instance, const char *function,
                                      unsigned int vr, CoreVariableType type) {
    const CoreVariable *v = core_find_variable(instance, function, vr);
    if (v != NULL && v->type != type) {
        core_log_error(instance, "%s: variable '%s' (value reference %u) is a %s, not a %s",
                       function, v->name, vr, type_name(v->type), type_name(type));
        return NULL;
    }
    return v;
}

static int check_arrays(CoreInstance *instance, const char *function, size_t n,
                        const void *vr, const void *values) {
    if (n > 0 && (vr == NULL || values == NULL)) {
        core_log_error(instance, "%s: %zu value references announced but an array is NULL",
                       function, n);
        return 0;
    }
    return 1;
}

static int needs_computation(const CoreVariable *v) {
    return v->kind == CORE_VARIABLE_DERIVATIVE || v->kind == CORE_VARIABLE_OUTPUT ||
           v->kind == CORE_VARIABLE_STATE;
}

CoreStatus core_get_real(CoreInstance *instance, const char *function,
                         const unsigned int vr[], size_t n, double values[]) {
    if (!check_arrays(instance, function, n, vr, values)) return CORE_ERROR;
    int compute = 0, indicators = 0;
    for (size_t i = 0; i < n; i++) {
        const CoreVariable *v = find_typed(instance, function, vr[i], CORE_TYPE_REAL);
        if (v == NULL) return CORE_ERROR;
        compute |= needs_computation(v);
        indicators |= v->kind == CORE_VARIABLE_EVENT_INDICATOR;
    }
    const double *x = instance->x;
    double z[MODEL_NUMBER_OF_EVENT_INDICATORS + 1] = {0.0};
    if (compute) {
        if (core_update_cache(instance) != CORE_OK) return core_fail(instance);
        if (core_effective_state(instance, &x) != CORE_OK) return core_fail(instance);
    }
    if (indicators && core_event_indicators(instance, function, z) != CORE_OK) {
        return core_fail(instance);
    }
    for (size_t i = 0; i < n; i++) {
        const CoreVariable *v = &MODEL_VARIABLES[vr[i]];
        switch (v->kind) {
            case CORE_VARIABLE_TIME: values[i] = instance->time; break;
            case CORE_VARIABLE_STATE: values[i] = x[v->index]; break;
            case CORE_VARIABLE_DERIVATIVE:
                values[i] = instance->cached_derivatives[v->index];
                break;
            case CORE_VARIABLE_INPUT: values[i] = instance->u[v->index]; break;
            case CORE_VARIABLE_OUTPUT: values[i] = instance->cached_outputs[v->index]; break;
            case CORE_VARIABLE_PARAMETER: values[i] = instance->p[v->index]; break;
            case CORE_VARIABLE_OPERATING_POINT: values[i] = instance->u0[v->index]; break;
            case CORE_VARIABLE_SOLVER_TOLERANCE: values[i] = instance->solver_tolerance; break;
            case CORE_VARIABLE_START_IN_EQUILIBRIUM:
                values[i] = instance->start_in_equilibrium;
                break;
            case CORE_VARIABLE_EVENT_INDICATOR: values[i] = z[v->index]; break;
        }
        if (!isfinite(values[i])) { /* never an OK with a value that is not a number */
            core_log_error(instance, "%s: '%s' (value reference %u) = %g is not a finite number "
                           "at t = %g (the states, inputs or parameters lie outside the range "
                           "where model %s can be evaluated)", function, v->name, vr[i],
                           values[i], instance->time, MODEL_IDENTIFIER);
            return core_fail(instance);
        }
    }
    return CORE_OK;
}

/* Modes in which a variable of each kind may be set (FMI 2.0 and 3.0 agree on these). */
static unsigned int settable_modes(CoreVariableKind kind) {
    const unsigned int before_end_of_initialisation =
        CORE_MODE_INSTANTIATED | CORE_MODE_INITIALIZATION;
    switch (kind) {
        case CORE_VARIABLE_STATE:
        case CORE_VARIABLE_START_IN_EQUILIBRIUM:
            return before_end_of_initialisation;
        case CORE_VARIABLE_INPUT:
            return before_end_of_initialisation | CORE_MODE_EVENT | CORE_MODE_CONTINUOUS_TIME |
                   CORE_MODE_STEP;
        case CORE_VARIABLE_PARAMETER:
        case CORE_VARIABLE_OPERATING_POINT:
        case CORE_VARIABLE_SOLVER_TOLERANCE:
            return before_end_of_initialisation | CORE_MODE_EVENT | CORE_MODE_STEP;
        default:
            return 0;
    }
}

static int check_settable(CoreInstance *instance, const char *function, const CoreVariable *v,
                          unsigned int vr) {
    const unsigned int modes = settable_modes(v->kind);
    if (modes == 0) {
        core_log_error(instance, "%s: '%s' (value reference %u) is computed by the model and "
                       "cannot be set", function, v->name, vr);
        return 0;
    }
    if (!(instance->mode & modes)) {
        core_log_error(instance, "%s: '%s' (value reference %u) cannot be set in %s%s", function,
                       v->name, vr, core_mode_name(instance->mode),
                       v->kind == CORE_VARIABLE_STATE
                           ? " (states are set through SetContinuousStates after initialisation)"
                           : "");
        return 0;
    }
    return 1;
}

static int check_real_value(CoreInstance *instance, const char *function, const CoreVariable *v,
                            unsigned int vr, double value) {
    if (!isfinite(value)) {
        core_log_error(instance, "%s: '%s' (value reference %u) = %g is not a finite number",
                       function, v->name, vr, value);
        return 0;
    }
    if (value < v->minimum || value > v->maximum) {
        core_log_error(instance, "%s: '%s' (value reference %u) = %.17g is outside its admissible "
                       "range [%g, %g]", function, v->name, vr, value, v->minimum, v->maximum);
        return 0;
    }
    return 1;
}

/* Write one checked value and invalidate whatever depends on it. */
static void store_value(CoreInstance *instance, const CoreVariable *v, double value) {
    switch (v->kind) {
        case CORE_VARIABLE_STATE:
            instance->x[v->index] = value;
            break;
        case CORE_VARIABLE_INPUT:
            instance->u[v->index] = value;
            instance->initial_state_valid = 0;
            break;
        case CORE_VARIABLE_PARAMETER:
            instance->p[v->index] = value;
            core_invalidate_parameters(instance);
            break;
        case CORE_VARIABLE_OPERATING_POINT:
            instance->u0[v->index] = value;
            core_invalidate_parameters(instance);
            break;
        case CORE_VARIABLE_SOLVER_TOLERANCE:
            instance->solver_tolerance = value;
            break;
        case CORE_VARIABLE_START_IN_EQUILIBRIUM:
            instance->start_in_equilibrium = value != 0.0;
            instance->initial_state_valid = 0;
            break;
        default:
            break;
    }
    instance->cache_valid = 0;
}

CoreStatus core_set_real(CoreInstance *instance, const char *function,
                         const unsigned int vr[], size_t n, const double values[]) {
    if (!check_arrays(instance, function, n, vr, values)) return CORE_ERROR;
    for (size_t i = 0; i < n; i++) { /* check everything first: all or nothing is applied */
        const CoreVariable *v = find_typed(instance, function, vr[i], CORE_TYPE_REAL);
        if (v == NULL || !check_settable(instance, function, v, vr[i]) ||
            !check_real_value(instance, function, v, vr[i], values[i])) {
            return CORE_ERROR;
        }
    }
    for (size_t i = 0; i < n; i++) store_value(instance, &MODEL_VARIABLES[vr[i]], values[i]);
    return CORE_OK;
}

CoreStatus core_get_boolean(CoreInstance *instance, const char *function,
                            const unsigned int vr[], size_t n, int values[]) {
    if (!check_arrays(instance, function, n, vr, values)) return CORE_ERROR;
    for (size_t i = 0; i < n; i++) {
        if (find_typed(instance, function, vr[i], CORE_TYPE_BOOLEAN) == NULL) return CORE_ERROR;
    }
    for (size_t i = 0; i < n; i++) {
        const CoreVariable *v = &MODEL_VARIABLES[vr[i]];
        values[i] = v->kind == CORE_VARIABLE_START_IN_EQUILIBRIUM
                        ? instance->start_in_equilibrium
                        : instance->p[v->index] != 0.0;
    }
    return CORE_OK;
}

CoreStatus core_set_boolean(CoreInstance *instance, const char *function,
                            const unsigned int vr[], size_t n, const int values[]) {
    if (!check_arrays(instance, function, n, vr, values)) return CORE_ERROR;
    for (size_t i = 0; i < n; i++) {
        const CoreVariable *v = find_typed(instance, function, vr[i], CORE_TYPE_BOOLEAN);
        if (v == NULL || !check_settable(instance, function, v, vr[i])) return CORE_ERROR;
    }
    for (size_t i = 0; i < n; i++) {
        store_value(instance, &MODEL_VARIABLES[vr[i]], values[i] ? 1.0 : 0.0);
    }
    return CORE_OK;
}

CoreStatus core_refuse_type(const CoreInstance *instance, const char *function,
                            const char *type, size_t n) {
    if (n == 0) return CORE_OK;
    core_log_error(instance, "%s: the model has no variables of type %s (%zu value references "
                   "passed)", function, type, n);
    return CORE_ERROR;
}
