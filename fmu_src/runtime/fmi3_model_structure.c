/*
 * FMI 3.0 functions about the model's structure and state: variable dependencies (as declared in
 * <ModelStructure>), FMU state get/set/serialise, and exact directional and adjoint derivatives.
 */
#include "fmi3_front_end.h"

/* ---- variable dependencies (as declared in <ModelStructure>) --------------------------- */

/* Row of the dependency table for an unknown (state derivative, output), -1 for anything else. */
static int dependency_row(const CoreInstance *s, const CoreVariable *v) {
    if (v->kind == CORE_VARIABLE_DERIVATIVE) return v->index;
    if (v->kind == CORE_VARIABLE_OUTPUT) return s->nx + v->index;
    return -1;
}

/* The knowns an unknown depends on, as declared in <ModelStructure> (same generated table). */
static size_t count_dependencies(const CoreInstance *s, const CoreVariable *v) {
    const int row = dependency_row(s, v);
    size_t count = 0;
    for (int column = 0; row >= 0 && column < s->nx + s->nu; column++) {
        count += core_dependency_kind(s, row, column) != 0;
    }
    return count;
}

fmi3Status fmi3GetNumberOfVariableDependencies(fmi3Instance instance,
                                               fmi3ValueReference valueReference,
                                               size_t *nDependencies) {
    CoreInstance *s = enter(instance, "fmi3GetNumberOfVariableDependencies", ANY);
    if (s == NULL || nDependencies == NULL) return fmi3Error;
    const CoreVariable *v =
        core_find_variable(s, "fmi3GetNumberOfVariableDependencies", valueReference);
    if (v == NULL) return fmi3Error;
    *nDependencies = count_dependencies(s, v);
    return fmi3OK;
}

/* Value reference of the state or input with the given index. */
static fmi3ValueReference known_reference(CoreVariableKind kind, int index) {
    for (int vr = 0; vr < core_number_of_variables(); vr++) {
        const CoreVariable *v = core_find_variable(NULL, "", (unsigned int)vr);
        if (v->kind == kind && v->index == index) return (fmi3ValueReference)vr;
    }
    return 0; /* not reached: the table holds every state and input */
}

fmi3Status fmi3GetVariableDependencies(fmi3Instance instance, fmi3ValueReference dependent,
                                       size_t elementIndicesOfDependent[],
                                       fmi3ValueReference independents[],
                                       size_t elementIndicesOfIndependents[],
                                       fmi3DependencyKind dependencyKinds[],
                                       size_t nDependencies) {
    CoreInstance *s = enter(instance, "fmi3GetVariableDependencies", ANY);
    if (s == NULL) return fmi3Error;
    const CoreVariable *v = core_find_variable(s, "fmi3GetVariableDependencies", dependent);
    if (v == NULL) return fmi3Error;
    const size_t n = count_dependencies(s, v);
    if (!check_count(s, "fmi3GetVariableDependencies", nDependencies, n, independents) ||
        (n > 0 && (elementIndicesOfDependent == NULL || elementIndicesOfIndependents == NULL ||
                   dependencyKinds == NULL))) {
        return fmi3Error;
    }
    const int row = dependency_row(s, v);
    size_t i = 0;
    for (int column = 0; row >= 0 && column < s->nx + s->nu; column++) {
        const int kind = core_dependency_kind(s, row, column);
        if (kind == 0) continue;
        independents[i] = column < s->nx ? known_reference(CORE_VARIABLE_STATE, column)
                                         : known_reference(CORE_VARIABLE_INPUT, column - s->nx);
        elementIndicesOfDependent[i] = 0;
        elementIndicesOfIndependents[i] = 0;
        dependencyKinds[i] = (fmi3DependencyKind)kind;
        i++;
    }
    return fmi3OK;
}

/* ---- FMU state ------------------------------------------------------------------------- */

fmi3Status fmi3GetFMUState(fmi3Instance instance, fmi3FMUState *FMUState) {
    CoreInstance *s = enter(instance, "fmi3GetFMUState", ANY);
    if (s == NULL) return fmi3Error;
    if (FMUState == NULL) return refuse(instance, "fmi3GetFMUState", "FMUState is NULL");
    void *snapshot = core_get_state(s, *FMUState);
    if (snapshot == NULL) return fmi3Error;
    *FMUState = snapshot;
    return fmi3OK;
}

fmi3Status fmi3SetFMUState(fmi3Instance instance, fmi3FMUState FMUState) {
    CoreInstance *s = enter(instance, "fmi3SetFMUState", ANY);
    if (s == NULL) return fmi3Error;
    return (fmi3Status)core_set_state(s, FMUState);
}

fmi3Status fmi3FreeFMUState(fmi3Instance instance, fmi3FMUState *FMUState) {
    CoreInstance *s = enter(instance, "fmi3FreeFMUState", ANY);
    if (s == NULL) return fmi3Error;
    if (FMUState != NULL) {
        core_free_state(s, *FMUState);
        *FMUState = NULL;
    }
    return fmi3OK;
}

fmi3Status fmi3SerializedFMUStateSize(fmi3Instance instance, fmi3FMUState FMUState,
                                      size_t *size) {
    (void)FMUState;
    CoreInstance *s = enter(instance, "fmi3SerializedFMUStateSize", ANY);
    if (s == NULL || size == NULL) return fmi3Error;
    *size = core_serialized_state_size(s);
    return fmi3OK;
}

fmi3Status fmi3SerializeFMUState(fmi3Instance instance, fmi3FMUState FMUState,
                                 fmi3Byte serializedState[], size_t size) {
    CoreInstance *s = enter(instance, "fmi3SerializeFMUState", ANY);
    if (s == NULL) return fmi3Error;
    return (fmi3Status)core_serialize_state(s, FMUState, serializedState, size);
}

fmi3Status fmi3DeserializeFMUState(fmi3Instance instance, const fmi3Byte serializedState[],
                                   size_t size, fmi3FMUState *FMUState) {
    CoreInstance *s = enter(instance, "fmi3DeserializeFMUState", ANY);
    if (s == NULL) return fmi3Error;
    if (FMUState == NULL) return refuse(instance, "fmi3DeserializeFMUState", "FMUState is NULL");
    void *snapshot = core_deserialize_state(s, serializedState, size, *FMUState);
    if (snapshot == NULL) return fmi3Error;
    *FMUState = snapshot;
    return fmi3OK;
}

/* ---- partial derivatives --------------------------------------------------------------- */

static fmi3Status partial_derivative(fmi3Instance instance, const char *function,
                                     const fmi3ValueReference unknowns[], size_t nUnknowns,
                                     const fmi3ValueReference knowns[], size_t nKnowns,
                                     const fmi3Float64 seed[], size_t nSeed,
                                     fmi3Float64 sensitivity[], size_t nSensitivity,
                                     int adjoint) {
    CoreInstance *s = enter(instance, function,
                            CORE_MODE_INITIALIZATION | CORE_MODES_INITIALISED);
    if (s == NULL) return fmi3Error;
    const size_t seeds = adjoint ? nUnknowns : nKnowns;
    const size_t sensitivities = adjoint ? nKnowns : nUnknowns;
    if (nSeed != seeds || nSensitivity != sensitivities) {
        core_log_error(s, "%s: nSeed = %zu and nSensitivity = %zu, expected %zu and %zu",
                       function, nSeed, nSensitivity, seeds, sensitivities);
        return fmi3Error;
    }
    return (fmi3Status)core_directional_derivative(s, function, unknowns, nUnknowns, knowns,
                                                   nKnowns, seed, sensitivity, adjoint);
}

fmi3Status fmi3GetDirectionalDerivative(fmi3Instance instance,
                                        const fmi3ValueReference unknowns[], size_t nUnknowns,
                                        const fmi3ValueReference knowns[], size_t nKnowns,
                                        const fmi3Float64 seed[], size_t nSeed,
                                        fmi3Float64 sensitivity[], size_t nSensitivity) {
    return partial_derivative(instance, "fmi3GetDirectionalDerivative", unknowns, nUnknowns,
                              knowns, nKnowns, seed, nSeed, sensitivity, nSensitivity, 0);
}

fmi3Status fmi3GetAdjointDerivative(fmi3Instance instance, const fmi3ValueReference unknowns[],
                                    size_t nUnknowns, const fmi3ValueReference knowns[],
                                    size_t nKnowns, const fmi3Float64 seed[], size_t nSeed,
                                    fmi3Float64 sensitivity[], size_t nSensitivity) {
    return partial_derivative(instance, "fmi3GetAdjointDerivative", unknowns, nUnknowns, knowns,
                              nKnowns, seed, nSeed, sensitivity, nSensitivity, 1);
}
