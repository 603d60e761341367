/*
 * FMU state snapshots (Get/Set/Free/Serialize/Deserialize FMU state), shared by the FMI 2.0 and
 * FMI 3.0 front ends. See fmu_core.h.
 */
#include <math.h>
#include <string.h>

#include "fmu_core.h"

/* ---- FMU state snapshots --------------------------------------------------------------- */

/* A snapshot is an array of doubles: this header, then x, u, p, u0. Serialised, it is the
 * same array as bytes (the importer restores it on the same platform) followed by the 64-bit
 * FNV-1a hash of those bytes (8 bytes, little end first), so that a corrupted copy is refused. */
enum {
    SNAPSHOT_MAGIC, SNAPSHOT_NQ, SNAPSHOT_NU, SNAPSHOT_NY, SNAPSHOT_NP, SNAPSHOT_LINEARISED,
    SNAPSHOT_INTERFACE, SNAPSHOT_MODE, SNAPSHOT_TIME, SNAPSHOT_TOLERANCE,
    SNAPSHOT_START_IN_EQUILIBRIUM, SNAPSHOT_EXPERIMENT_TOLERANCE, SNAPSHOT_STEP_SIZE,
    SNAPSHOT_LAST_SUCCESSFUL_TIME, SNAPSHOT_LAST_STEP_STATUS, SNAPSHOT_SUBSTEPS,
    SNAPSHOT_HEADER_LENGTH
};
#define SNAPSHOT_MAGIC_VALUE 4.2e42 /* marks a block as one of our snapshots */

static size_t snapshot_length(const CoreInstance *s) {
    return SNAPSHOT_HEADER_LENGTH + (size_t)(s->nx + 2 * s->nu + s->np);
}

#define CHECKSUM_BYTES 8

size_t core_serialized_state_size(const CoreInstance *instance) {
    return snapshot_length(instance) * sizeof(double) + CHECKSUM_BYTES;
}

/* FNV-1a, 64 bits (Fowler, Noll, Vo): offset basis and prime of the published algorithm. */
static unsigned long long fnv1a(const unsigned char *bytes, size_t size) {
    unsigned long long hash = 14695981039346656037ULL;
    for (size_t i = 0; i < size; i++) {
        hash ^= bytes[i];
        hash *= 1099511628211ULL;
    }
    return hash;
}

static void write_checksum(unsigned char *out, unsigned long long hash) {
    for (int i = 0; i < CHECKSUM_BYTES; i++) out[i] = (unsigned char)(hash >> (8 * i));
}

static unsigned long long read_checksum(const unsigned char *in) {
    unsigned long long hash = 0;
    for (int i = 0; i < CHECKSUM_BYTES; i++) hash |= (unsigned long long)in[i] << (8 * i);
    return hash;
}

void *core_get_state(CoreInstance *s, void *previous) {
    double *snapshot = previous;
    if (snapshot == NULL) snapshot = s->allocate(snapshot_length(s), sizeof(double));
    if (snapshot == NULL) {
        core_log_error(s, "GetFMUState: out of memory");
        return NULL;
    }
    const double header[SNAPSHOT_HEADER_LENGTH] = {
        SNAPSHOT_MAGIC_VALUE, s->nq, s->nu, s->ny, s->np, s->linearised, s->interface_type,
        s->mode, s->time, s->solver_tolerance, s->start_in_equilibrium, s->experiment_tolerance,
        s->step_size, s->last_successful_time, s->last_step_status, (double)s->substeps};
    memcpy(snapshot, header, sizeof(header));
    double *cursor = snapshot + SNAPSHOT_HEADER_LENGTH;
    memcpy(cursor, s->x, (size_t)s->nx * sizeof(double));
    cursor += s->nx;
    memcpy(cursor, s->u, (size_t)s->nu * sizeof(double));
    cursor += s->nu;
    memcpy(cursor, s->p, (size_t)s->np * sizeof(double));
    cursor += s->np;
    memcpy(cursor, s->u0, (size_t)s->nu * sizeof(double));
    return snapshot;
}

static int check_snapshot(const CoreInstance *s, const double *h, const char *function) {
    if (h[SNAPSHOT_MAGIC] != SNAPSHOT_MAGIC_VALUE || h[SNAPSHOT_NQ] != s->nq ||
        h[SNAPSHOT_NU] != s->nu || h[SNAPSHOT_NY] != s->ny || h[SNAPSHOT_NP] != s->np ||
        h[SNAPSHOT_LINEARISED] != s->linearised) {
        core_log_error(s, "%s: the FMU state does not belong to model %s", function,
                       MODEL_IDENTIFIER);
        return 0;
    }
    const double mode = h[SNAPSHOT_MODE];
    int known_mode = 0;
    for (unsigned int bit = 1; bit <= CORE_MODE_ERROR; bit <<= 1) known_mode |= mode == bit;
    for (size_t i = 0; i < snapshot_length(s); i++) {
        if (!isfinite(h[i]) || !known_mode) {
            core_log_error(s, "%s: the FMU state is corrupted (%s)", function,
                           known_mode ? "a value is not a finite number" : "unknown mode");
            return 0;
        }
    }
    if (h[SNAPSHOT_INTERFACE] != s->interface_type) {
        core_log_error(s, "%s: the FMU state was taken from a %s instance", function,
                       h[SNAPSHOT_INTERFACE] == CORE_CO_SIMULATION ? "Co-Simulation"
                                                                   : "Model Exchange");
        return 0;
    }
    return 1;
}

CoreStatus core_set_state(CoreInstance *s, const void *snapshot) {
    const double *h = snapshot;
    if (h == NULL) {
        core_log_error(s, "SetFMUState: the FMU state is NULL");
        return CORE_ERROR;
    }
    if (!check_snapshot(s, h, "SetFMUState")) return CORE_ERROR;
    s->mode = (CoreMode)h[SNAPSHOT_MODE];
    s->time = h[SNAPSHOT_TIME];
    s->solver_tolerance = h[SNAPSHOT_TOLERANCE];
    s->start_in_equilibrium = h[SNAPSHOT_START_IN_EQUILIBRIUM] != 0.0;
    s->experiment_tolerance = h[SNAPSHOT_EXPERIMENT_TOLERANCE];
    s->step_size = h[SNAPSHOT_STEP_SIZE];
    s->last_successful_time = h[SNAPSHOT_LAST_SUCCESSFUL_TIME];
    s->last_step_status = (CoreStatus)h[SNAPSHOT_LAST_STEP_STATUS];
    s->substeps = (long)h[SNAPSHOT_SUBSTEPS];
    const double *cursor = h + SNAPSHOT_HEADER_LENGTH;
    memcpy(s->x, cursor, (size_t)s->nx * sizeof(double));
    cursor += s->nx;
    memcpy(s->u, cursor, (size_t)s->nu * sizeof(double));
    cursor += s->nu;
    memcpy(s->p, cursor, (size_t)s->np * sizeof(double));
    cursor += s->np;
    memcpy(s->u0, cursor, (size_t)s->nu * sizeof(double));
    core_invalidate_parameters(s);
    return CORE_OK;
}

void core_free_state(CoreInstance *instance, void *snapshot) {
    if (snapshot != NULL) instance->release(snapshot);
}

CoreStatus core_serialize_state(CoreInstance *s, const void *snapshot, unsigned char *bytes,
                                size_t size) {
    if (snapshot == NULL || bytes == NULL) {
        core_log_error(s, "SerializeFMUState: the FMU state or the byte buffer is NULL");
        return CORE_ERROR;
    }
    if (size < core_serialized_state_size(s)) {
        core_log_error(s, "SerializeFMUState: buffer of %zu bytes is too small (%zu needed)", size,
                       core_serialized_state_size(s));
        return CORE_ERROR;
    }
    if (!check_snapshot(s, snapshot, "SerializeFMUState")) return CORE_ERROR;
    const size_t length = snapshot_length(s) * sizeof(double);
    memcpy(bytes, snapshot, length);
    write_checksum(bytes + length, fnv1a(bytes, length));
    return CORE_OK;
}

void *core_deserialize_state(CoreInstance *s, const unsigned char *bytes, size_t size,
                             void *previous) {
    const size_t expected = core_serialized_state_size(s);
    if (bytes == NULL || size != expected) {
        core_log_error(s, "DeserializeFMUState: expected %zu bytes, got %zu", expected,
                       bytes == NULL ? (size_t)0 : size);
        return NULL;
    }
    const size_t length = expected - CHECKSUM_BYTES;
    if (read_checksum(bytes + length) != fnv1a(bytes, length)) {
        core_log_error(s, "DeserializeFMUState: the serialized FMU state is corrupted (its "
                       "checksum does not match its %zu bytes)", length);
        return NULL;
    }
    double *snapshot = s->allocate(snapshot_length(s), sizeof(double));
    if (snapshot == NULL) {
        core_log_error(s, "DeserializeFMUState: out of memory");
        return NULL;
    }
    memcpy(snapshot, bytes, length);
    if (!check_snapshot(s, snapshot, "DeserializeFMUState")) {
        s->release(snapshot);
        return NULL;
    }
    if (previous != NULL) { /* reuse the importer's state only once the new one is sound */
        memcpy(previous, snapshot, length);
        s->release(snapshot);
        return previous;
    }
    return snapshot;
}
