/*
 * Numerics of the runtime: dense LU solve, the state derivative dx/dt = [v; M^-1 r], its exact
 * Jacobian, the static equilibrium r(q, 0, u) = 0, the linearised model and the directional and
 * adjoint derivatives. See fmu_core.h.
 *
 * Notation (model_interface.h): x = [q; v], dq/dt = v, M(q) dv/dt = r(q, v, u), y = h(q, v, u),
 * a = M^-1 r the accelerations. The Jacobian J of [dx/dt; y] with respect to [x; u] is
 *
 *     d(dq/dt)/dv   = I
 *     da/dq_k       = M^-1 (dr/dq_k - dM/dq_k a)
 *     da/dv         = M^-1 dr/dv,        da/du = M^-1 dr/du
 *     dy/d[q v u]   = the model's output Jacobian.
 *
 * Linearised models (MODEL_LINEARISED) use states dx = x - (q0, 0), where r(q0, 0, u0) = 0:
 *     d(dx)/dt = A dx + B (u - u0),   y = y0 + C dx + D (u - u0),   [A B; C D] = J(q0, 0, u0).
 */
#include <math.h>
#include <string.h>

#include "fmu_core.h"

#define NEWTON_MAX_ITERATIONS 100
#define NEWTON_MAX_HALVINGS 30
#define NEWTON_STEP_TOLERANCE 1e-10

/* ---- dense linear algebra -------------------------------------------------------------- */

int core_lu_factor(double *a, int n, int *pivots) {
    for (int k = 0; k < n; k++) {
        int pivot = k;
        for (int i = k + 1; i < n; i++) {
            if (fabs(a[i * n + k]) > fabs(a[pivot * n + k])) pivot = i;
        }
        pivots[k] = pivot;
        if (a[pivot * n + k] == 0.0 || !isfinite(a[pivot * n + k])) return -1;
        if (pivot != k) {
            for (int j = 0; j < n; j++) {
                const double t = a[k * n + j];
                a[k * n + j] = a[pivot * n + j];
                a[pivot * n + j] = t;
            }
        }
        for (int i = k + 1; i < n; i++) {
            const double factor = a[i * n + k] /= a[k * n + k];
            for (int j = k + 1; j < n; j++) a[i * n + j] -= factor * a[k * n + j];
        }
    }
    return 0;
}

void core_lu_solve(const double *lu, int n, const int *pivots, double *b) {
    for (int k = 0; k < n; k++) {
        const double t = b[k];
        b[k] = b[pivots[k]];
        b[pivots[k]] = t;
    }
    for (int i = 0; i < n; i++) {
        for (int j = 0; j < i; j++) b[i] -= lu[i * n + j] * b[j];
    }
    for (int i = n - 1; i >= 0; i--) {
        for (int j = i + 1; j < n; j++) b[i] -= lu[i * n + j] * b[j];
        b[i] /= lu[i * n + i];
    }
}

/* out = matrix (rows x cols, row-major, leading dimension ld) * vector */
static void multiply_add(const double *matrix, int rows, int cols, int ld, const double *vector,
                         double *out) {
    for (int i = 0; i < rows; i++) {
        double sum = 0.0;
        for (int j = 0; j < cols; j++) sum += matrix[i * ld + j] * vector[j];
        out[i] += sum;
    }
}

static double norm2(const double *v, int n) {
    double sum = 0.0;
    for (int i = 0; i < n; i++) sum += v[i] * v[i];
    return sqrt(sum);
}

/* ---- model calls ----------------------------------------------------------------------- */

static CoreStatus model_failed(CoreInstance *s, const char *function) {
    core_log_error(s, "model %s: %s failed at t = %g: %s", MODEL_IDENTIFIER, function, s->time,
                   s->model_message[0] ? s->model_message : "(no message)");
    return CORE_ERROR;
}

#define CALL_MODEL(s, function, ...)                                            \
    do {                                                                        \
        (s)->model_message[0] = '\0';                                           \
        if (function(__VA_ARGS__, (s)->model_message) != 0) {                   \
            (s)->model_message[MODEL_MESSAGE_LENGTH - 1] = '\0';                \
            return model_failed((s), #function);                                \
        }                                                                       \
    } while (0)

/* a = M(q)^-1 r(q, v, u); leaves the LU factors of M in work.mass and r in work.forces. */
static CoreStatus compute_accelerations(CoreInstance *s, const double *x, const double *u) {
    CoreWorkspace *w = &s->work;
    const double *q = x, *v = x + s->nq;
    CALL_MODEL(s, model_mass_matrix, s->p, q, w->mass);
    if (core_lu_factor(w->mass, s->nq, w->pivots) != 0) {
        core_log_error(s, "model %s: the mass matrix M(q) is singular at t = %g (q[0] = %g)",
                       MODEL_IDENTIFIER, s->time, s->nq > 0 ? q[0] : 0.0);
        return CORE_ERROR;
    }
    CALL_MODEL(s, model_forces, s->p, q, v, u, w->forces);
    memcpy(w->acceleration, w->forces, (size_t)s->nq * sizeof(double));
    core_lu_solve(w->mass, s->nq, w->pivots, w->acceleration);
    return CORE_OK;
}

/* Exact Jacobian of the nonlinear model at (x, u) into work.jacobian (see the file header). */
static CoreStatus nonlinear_jacobian(CoreInstance *s, const double *x, const double *u) {
    CoreWorkspace *w = &s->work;
    const int nq = s->nq, nx = s->nx, nu = s->nu, ny = s->ny, ld = s->nx + s->nu;
    const double *q = x, *v = x + nq;
    double *J = w->jacobian;
    if (compute_accelerations(s, x, u) != CORE_OK) return CORE_ERROR;
    CALL_MODEL(s, model_mass_matrix_derivative, s->p, q, w->mass_derivative);
    CALL_MODEL(s, model_forces_jacobian, s->p, q, v, u, w->dr_dq, w->dr_dv, w->dr_du);
    memset(J, 0, (size_t)((nx + ny) * ld) * sizeof(double));
    for (int i = 0; i < nq; i++) J[i * ld + nq + i] = 1.0; /* dq/dt = v */
    for (int k = 0; k < nx + nu; k++) {                    /* column k of da/d[q v u] */
        for (int i = 0; i < nq; i++) {
            if (k < nq) {
                const double *dM_k = w->mass_derivative + k * nq * nq;
                double dM_a = 0.0;
                for (int j = 0; j < nq; j++) dM_a += dM_k[i * nq + j] * w->acceleration[j];
                w->column[i] = w->dr_dq[i * nq + k] - dM_a;
            } else if (k < nx) {
                w->column[i] = w->dr_dv[i * nq + (k - nq)];
            } else {
                w->column[i] = w->dr_du[i * nu + (k - nx)];
            }
        }
        core_lu_solve(w->mass, nq, w->pivots, w->column);
        for (int i = 0; i < nq; i++) J[(nq + i) * ld + k] = w->column[i];
    }
    if (ny == 0) return CORE_OK;
    CALL_MODEL(s, model_outputs_jacobian, s->p, q, v, u, w->dy_dq, w->dy_dv, w->dy_du);
    for (int o = 0; o < ny; o++) {
        double *row = J + (nx + o) * ld;
        for (int k = 0; k < nq; k++) {
            row[k] = w->dy_dq[o * nq + k];
            row[nq + k] = w->dy_dv[o * nq + k];
        }
        for (int j = 0; j < nu; j++) row[nx + j] = w->dy_du[o * nu + j];
    }
    return CORE_OK;
}

/* ---- static equilibrium ---------------------------------------------------------------- */

/* One damped Newton step on r(q, 0, u) = 0 from q (residual r, norm *norm). Returns the
 * accepted step length (0 if no decrease was found) and updates q, r and *norm. */
static double newton_step(CoreInstance *s, const double *u, double *q, double *r, double *norm,
                          CoreStatus *status) {
    CoreWorkspace *w = &s->work;
    const int nq = s->nq;
    *status = CORE_ERROR;
    s->model_message[0] = '\0';
    if (model_forces_jacobian(s->p, q, w->zeros, u, w->newton_matrix, w->dr_dv, w->dr_du,
                              s->model_message) != 0) {
        model_failed(s, "model_forces_jacobian");
        return 0.0;
    }
    if (core_lu_factor(w->newton_matrix, nq, w->pivots) != 0) {
        core_log_error(s, "static equilibrium of model %s: dr/dq is singular (the model has no "
                       "isolated equilibrium for these inputs and parameters)", MODEL_IDENTIFIER);
        return 0.0;
    }
    for (int i = 0; i < nq; i++) w->newton_step[i] = -r[i];
    core_lu_solve(w->newton_matrix, nq, w->pivots, w->newton_step);
    *status = CORE_OK;
    for (double lambda = 1.0; lambda > 0x1p-30; lambda *= 0.5) { /* backtracking */
        for (int i = 0; i < nq; i++) w->newton_trial[i] = q[i] + lambda * w->newton_step[i];
        if (model_forces(s->p, w->newton_trial, w->zeros, u, w->newton_residual,
                         s->model_message) != 0) {
            continue; /* e.g. the linkage cannot close there: shorten the step */
        }
        const double trial_norm = norm2(w->newton_residual, nq);
        if (trial_norm <= (1.0 - 1e-4 * lambda) * *norm || trial_norm == 0.0) {
            memcpy(q, w->newton_trial, (size_t)nq * sizeof(double));
            memcpy(r, w->newton_residual, (size_t)nq * sizeof(double));
            *norm = trial_norm;
            return lambda;
        }
    }
    return 0.0;
}

static int step_is_small(const CoreInstance *s, const double *q, double lambda) {
    for (int i = 0; i < s->nq; i++) {
        if (fabs(lambda * s->work.newton_step[i]) > NEWTON_STEP_TOLERANCE * (1.0 + fabs(q[i]))) {
            return 0;
        }
    }
    return 1;
}

/* q with r(q, 0, u) = 0 by damped Newton from model_initial_guess. */
static CoreStatus solve_equilibrium(CoreInstance *s, const double *u, double *q) {
    double *r = s->work.forces;
    CALL_MODEL(s, model_initial_guess, s->p, u, q);
    CALL_MODEL(s, model_forces, s->p, q, s->work.zeros, u, r);
    double norm = norm2(r, s->nq);
    for (int iteration = 1; iteration <= NEWTON_MAX_ITERATIONS; iteration++) {
        if (norm == 0.0) return CORE_OK;
        CoreStatus status;
        const double lambda = newton_step(s, u, q, r, &norm, &status);
        if (status != CORE_OK) return status;
        core_log(s, CORE_OK, "logNonlinearSystems",
                 "static equilibrium: iteration %d, step length %g, |r| = %g", iteration, lambda,
                 norm);
        /* converged: the (full or damped) Newton step no longer moves q */
        if (step_is_small(s, q, lambda > 0.0 ? lambda : 1.0)) return CORE_OK;
        if (lambda == 0.0) {
            core_log_error(s, "static equilibrium of model %s: damped Newton stalled at |r| = %g "
                           "(last model message: %s)", MODEL_IDENTIFIER, norm,
                           s->model_message[0] ? s->model_message : "none");
            return CORE_ERROR;
        }
    }
    core_log_error(s, "static equilibrium of model %s did not converge in %d Newton iterations "
                   "(|r| = %g)", MODEL_IDENTIFIER, NEWTON_MAX_ITERATIONS, norm);
    return CORE_ERROR;
}

/* ---- linearisation --------------------------------------------------------------------- */

static CoreStatus compute_linearisation(CoreInstance *s) {
    const int nq = s->nq, nx = s->nx, nu = s->nu, ny = s->ny, ld = s->nx + s->nu;
    if (solve_equilibrium(s, s->u0, s->q0) != CORE_OK) {
        core_log_error(s, "cannot linearise model %s: no static equilibrium at the operating "
                       "point: %s", MODEL_IDENTIFIER, s->last_error);
        return CORE_ERROR;
    }
    double *point = s->work.point;
    memset(point, 0, (size_t)nx * sizeof(double));
    memcpy(point, s->q0, (size_t)nq * sizeof(double));
    if (nonlinear_jacobian(s, point, s->u0) != CORE_OK) return CORE_ERROR;
    const double *J = s->work.jacobian;
    for (int i = 0; i < nx + ny; i++) {
        for (int k = 0; k < nx + nu; k++) {
            const double value = J[i * ld + k];
            if (i < nx && k < nx) s->a_matrix[i * nx + k] = value;
            else if (i < nx) s->b_matrix[i * nu + (k - nx)] = value;
            else if (k < nx) s->c_matrix[(i - nx) * nx + k] = value;
            else s->d_matrix[(i - nx) * nu + (k - nx)] = value;
        }
    }
    if (ny > 0) CALL_MODEL(s, model_outputs, s->p, s->q0, s->work.zeros, s->u0, s->y0);
    s->linearisation_valid = 1;
    return CORE_OK;
}

static CoreStatus check_and_linearise(CoreInstance *s) {
    if (!s->parameters_checked) {
        s->model_message[0] = '\0';
        if (model_check_parameters(s->p, s->model_message) != 0) {
            s->model_message[MODEL_MESSAGE_LENGTH - 1] = '\0';
            core_log_error(s, "model %s refuses the parameters: %s", MODEL_IDENTIFIER,
                           s->model_message);
            return CORE_ERROR;
        }
        s->parameters_checked = 1;
    }
    if (s->linearised && !s->linearisation_valid) return compute_linearisation(s);
    return CORE_OK;
}

CoreStatus core_prepare(CoreInstance *s) {
    if (s->prepare_failed) { /* logged when it happened: no second equilibrium solve, no log */
        memcpy(s->last_error, s->prepare_failure, sizeof(s->last_error));
        return CORE_ERROR;
    }
    const CoreStatus status = check_and_linearise(s);
    if (status != CORE_OK && !s->errors_suppressed) {
        memcpy(s->prepare_failure, s->last_error, sizeof(s->prepare_failure));
        s->prepare_failed = 1;
    }
    return status;
}

/* ---- dynamics and Jacobian ------------------------------------------------------------- */

static CoreStatus evaluate(CoreInstance *s, const double *x, double *dx, double *y);

/* Never a success with a value that is not a number: a finite but absurd state or input (a head
 * at -1e154 m) can overflow the model's expressions. */
CoreStatus core_evaluate(CoreInstance *s, const double *x, double *dx, double *y) {
    if (evaluate(s, x, dx, y) != CORE_OK) return CORE_ERROR;
    if (dx != NULL && !core_check_finite(s, "model evaluation", CORE_VARIABLE_DERIVATIVE, dx,
                                         (size_t)s->nx)) {
        return CORE_ERROR;
    }
    if (y != NULL && !core_check_finite(s, "model evaluation", CORE_VARIABLE_OUTPUT, y,
                                        (size_t)s->ny)) {
        return CORE_ERROR;
    }
    return CORE_OK;
}

static CoreStatus evaluate(CoreInstance *s, const double *x, double *dx, double *y) {
    const int nq = s->nq, nx = s->nx, nu = s->nu, ny = s->ny;
    if (core_prepare(s) != CORE_OK) return CORE_ERROR;
    if (s->linearised) {
        double *du = s->work.input_deviation;
        for (int j = 0; j < nu; j++) du[j] = s->u[j] - s->u0[j];
        if (dx) {
            memset(dx, 0, (size_t)nx * sizeof(double));
            multiply_add(s->a_matrix, nx, nx, nx, x, dx);
            multiply_add(s->b_matrix, nx, nu, nu, du, dx);
        }
        if (y) {
            memcpy(y, s->y0, (size_t)ny * sizeof(double));
            multiply_add(s->c_matrix, ny, nx, nx, x, y);
            multiply_add(s->d_matrix, ny, nu, nu, du, y);
        }
        return CORE_OK;
    }
    if (dx) {
        if (compute_accelerations(s, x, s->u) != CORE_OK) return CORE_ERROR;
        memcpy(dx, x + nq, (size_t)nq * sizeof(double));
        memcpy(dx + nq, s->work.acceleration, (size_t)nq * sizeof(double));
    }
    if (y && ny > 0) CALL_MODEL(s, model_outputs, s->p, x, x + nq, s->u, y);
    return CORE_OK;
}

CoreStatus core_evaluate_jacobian(CoreInstance *s, const double *x) {
    const int nx = s->nx, nu = s->nu, ny = s->ny, ld = s->nx + s->nu;
    if (core_prepare(s) != CORE_OK) return CORE_ERROR;
    if (!s->linearised) return nonlinear_jacobian(s, x, s->u);
    double *J = s->work.jacobian;
    for (int i = 0; i < nx + ny; i++) {
        for (int k = 0; k < nx + nu; k++) {
            J[i * ld + k] = i < nx ? (k < nx ? s->a_matrix[i * nx + k]
                                             : s->b_matrix[i * nu + (k - nx)])
                                   : (k < nx ? s->c_matrix[(i - nx) * nx + k]
                                             : s->d_matrix[(i - nx) * nu + (k - nx)]);
        }
    }
    return CORE_OK;
}

/* ---- initial state --------------------------------------------------------------------- */

/* Equilibrium of the linear model: v = 0 and the dv/dt rows A_vq dq + B_v (u - u0) = 0. */
static CoreStatus linear_equilibrium(CoreInstance *s, double *x) {
    const int nq = s->nq, nx = s->nx, nu = s->nu;
    double *matrix = s->work.newton_matrix;
    memset(x, 0, (size_t)nx * sizeof(double));
    for (int i = 0; i < nq; i++) {
        for (int k = 0; k < nq; k++) matrix[i * nq + k] = s->a_matrix[(nq + i) * nx + k];
        double b_du = 0.0;
        for (int j = 0; j < nu; j++) b_du += s->b_matrix[(nq + i) * nu + j] * (s->u[j] - s->u0[j]);
        x[i] = -b_du;
    }
    if (core_lu_factor(matrix, nq, s->work.pivots) != 0) {
        core_log_error(s, "equilibrium of the linearised model %s: the stiffness block of A is "
                       "singular", MODEL_IDENTIFIER);
        return CORE_ERROR;
    }
    core_lu_solve(matrix, nq, s->work.pivots, x);
    return CORE_OK;
}

CoreStatus core_compute_initial_state(CoreInstance *s, double *x) {
    if (core_prepare(s) != CORE_OK) return CORE_ERROR;
    if (s->linearised) return linear_equilibrium(s, x);
    memset(x, 0, (size_t)s->nx * sizeof(double));
    if (solve_equilibrium(s, s->u, x) != CORE_OK) {
        core_log_error(s, "cannot start model %s in static equilibrium: %s", MODEL_IDENTIFIER,
                       s->last_error);
        return CORE_ERROR;
    }
    return CORE_OK;
}

CoreStatus core_effective_state(CoreInstance *s, const double **x) {
    const int initialising = s->mode & (CORE_MODE_INSTANTIATED | CORE_MODE_INITIALIZATION);
    if (!(initialising && s->start_in_equilibrium)) {
        *x = s->x;
        return CORE_OK;
    }
    if (!s->initial_state_valid) {
        if (core_compute_initial_state(s, s->initial_x) != CORE_OK) return CORE_ERROR;
        s->initial_state_valid = 1;
    }
    *x = s->initial_x;
    return CORE_OK;
}

CoreStatus core_initialize(CoreInstance *s) {
    const double *x;
    if (core_effective_state(s, &x) != CORE_OK) return CORE_ERROR;
    if (x != s->x) memcpy(s->x, x, (size_t)s->nx * sizeof(double));
    s->cache_valid = 0;
    s->step_size = 0.0;
    s->last_successful_time = s->time;
    return core_evaluate(s, s->x, s->cached_derivatives, s->cached_outputs);
}

CoreStatus core_update_cache(CoreInstance *s) {
    if (s->cache_valid) return CORE_OK;
    const double *x;
    if (core_effective_state(s, &x) != CORE_OK) return CORE_ERROR;
    if (core_evaluate(s, x, s->cached_derivatives, s->cached_outputs) != CORE_OK) {
        return CORE_ERROR;
    }
    s->cache_valid = 1;
    return CORE_OK;
}

/* ---- directional and adjoint derivatives ----------------------------------------------- */

/* Row of J for an unknown (derivative or output), column for a known (state or input). */
static int jacobian_index(CoreInstance *s, const char *function, unsigned int vr, int unknown) {
    const CoreVariable *v = core_find_variable(s, function, vr);
    if (v == NULL) return -1;
    if (unknown && v->kind == CORE_VARIABLE_DERIVATIVE) return v->index;
    if (unknown && v->kind == CORE_VARIABLE_OUTPUT) return s->nx + v->index;
    if (!unknown && v->kind == CORE_VARIABLE_STATE) return v->index;
    if (!unknown && v->kind == CORE_VARIABLE_INPUT) return s->nx + v->index;
    core_log_error(s, "%s: '%s' (value reference %u) cannot be %s (%s)", function, v->name, vr,
                   unknown ? "an unknown" : "a known",
                   unknown ? "unknowns are state derivatives and outputs"
                           : "knowns are states and inputs");
    return -1;
}

CoreStatus core_directional_derivative(CoreInstance *s, const char *function,
                                       const unsigned int unknowns[], size_t n_unknowns,
                                       const unsigned int knowns[], size_t n_knowns,
                                       const double seed[], double sensitivity[], int adjoint) {
    const int ld = s->nx + s->nu;
    if ((n_unknowns > 0 && (unknowns == NULL || (adjoint ? seed : sensitivity) == NULL)) ||
        (n_knowns > 0 && (knowns == NULL || (adjoint ? sensitivity : seed) == NULL))) {
        core_log_error(s, "%s: an array argument is NULL", function);
        return CORE_ERROR;
    }
    for (size_t i = 0; i < n_unknowns; i++) {
        if (jacobian_index(s, function, unknowns[i], 1) < 0) return CORE_ERROR;
    }
    for (size_t j = 0; j < n_knowns; j++) {
        if (jacobian_index(s, function, knowns[j], 0) < 0) return CORE_ERROR;
    }
    const double *x;
    if (core_effective_state(s, &x) != CORE_OK || core_evaluate_jacobian(s, x) != CORE_OK) {
        return core_fail(s);
    }
    const double *J = s->work.jacobian;
    for (int i = 0; i < (s->nx + s->ny) * ld; i++) {
        if (isfinite(J[i])) continue;
        const int row = i / ld, column = i % ld;
        core_log_error(s, "%s: the partial derivative of %s with respect to %s is %g, not a "
                       "finite number, at t = %g", function,
                       row < s->nx ? core_variable_name(CORE_VARIABLE_DERIVATIVE, row)
                                   : core_variable_name(CORE_VARIABLE_OUTPUT, row - s->nx),
                       column < s->nx ? core_variable_name(CORE_VARIABLE_STATE, column)
                                      : core_variable_name(CORE_VARIABLE_INPUT, column - s->nx),
                       J[i], s->time);
        return core_fail(s);
    }
    const size_t n_out = adjoint ? n_knowns : n_unknowns;
    for (size_t i = 0; i < n_out; i++) sensitivity[i] = 0.0;
    for (size_t i = 0; i < n_unknowns; i++) {
        const int row = jacobian_index(s, function, unknowns[i], 1);
        for (size_t j = 0; j < n_knowns; j++) {
            const double entry = J[row * ld + jacobian_index(s, function, knowns[j], 0)];
            if (adjoint) sensitivity[j] += entry * seed[i];
            else sensitivity[i] += entry * seed[j];
        }
    }
    for (size_t i = 0; i < n_out; i++) { /* a finite Jacobian times a huge seed can overflow */
        if (!isfinite(sensitivity[i])) {
            core_log_error(s, "%s: sensitivity %zu = %g is not a finite number (seed too large?)",
                           function, i, sensitivity[i]);
            return CORE_ERROR;
        }
    }
    return CORE_OK;
}
