/*
 * The co-simulation integrator: the linearly implicit Rosenbrock method RODAS4 of Hairer &
 * Wanner ("Solving Ordinary Differential Equations II", 2nd ed., Springer 1996, §IV.7), order 4,
 * L-stable and stiffly accurate, with an embedded order-3 solution for error control. It uses
 * the exact Jacobian J = df/dx of the runtime, so a stiff contact spring costs no stability.
 *
 * With the inputs held constant over a communication step the system dx/dt = f(x) is
 * autonomous. One sub-step of size h from x, with gamma = 1/4 and the method's coefficients
 * a_ij, c_ij, m_j (below):
 *
 *     W = I / (h gamma) - J
 *     for i = 1..6:   W k_i = f(x + sum_{j<i} a_ij k_j) + sum_{j<i} (c_ij / h) k_j
 *     x+ = x + sum_j m_j k_j,        error estimate  e = k_6
 *
 * A sub-step is accepted if max_i |e_i| / (tol (1 + max(|x_i|, |x+_i|))) <= 1; the next size is
 * h * clamp(0.9 err^(-1/4)). A sub-step on which the model fails (for instance a trial point where
 * a linkage cannot close) is rejected and retried four times shorter; the step fails when h
 * underflows.
 *
 * A step that meets a numerical limit (the tolerance cannot be met above the smallest sub-step
 * the time allows, or too many sub-steps) is discarded (FMI 2.0.4 section 4.2.2, fmi2Discard: the
 * step was completed only up to the last successful time, where the states are valid; a shorter
 * communication step or a larger solver_tolerance may succeed after restoring an FMU state). A
 * model that fails at a state it reached, or at every trial point down to the smallest sub-step,
 * cannot go on: that is an error.
 */
#include <math.h>
#include <string.h>

#include "fmu_core.h"

#define STAGES 6
#define GAMMA 0.25
#define MAX_SUBSTEPS_PER_STEP 1000000L
#define SAFETY 0.9
#define MAX_GROWTH 6.0
#define MIN_SHRINK 0.2

/* RODAS4 coefficients (Hairer & Wanner, routine RODAS, METH = 1), strictly lower triangular. */
static const double A[STAGES][STAGES] = {
    {0},
    {1.544},
    {0.9466785280815826, 0.2557011698983284},
    {3.314825187068521, 2.896124015972201, 0.9986419139977817},
    {1.221224509226641, 6.019134481288629, 12.53708332932087, -0.6878860361058950},
    {1.221224509226641, 6.019134481288629, 12.53708332932087, -0.6878860361058950, 1.0}};
static const double C[STAGES][STAGES] = {
    {0},
    {-5.6688},
    {-2.430093356833875, -0.2063599157091915},
    {-0.1073529058151375, -9.594562251023355, -20.47028614809616},
    {7.496443313967647, -10.24680431464352, -33.99990352819905, 11.70890893206160},
    {8.083246795921522, -7.981132988064893, -31.52159432874371, 16.31930543123136,
     -6.058818238834054}};
static const double M[STAGES] = {1.221224509226641, 6.019134481288629, 12.53708332932087,
                                 -0.6878860361058950, 1.0, 1.0};

static double effective_tolerance(const CoreInstance *s) {
    double tolerance = s->solver_tolerance;
    if (s->experiment_tolerance > 0.0 && s->experiment_tolerance < tolerance) {
        tolerance = s->experiment_tolerance;
    }
    return tolerance < CORE_MINIMUM_TOLERANCE ? CORE_MINIMUM_TOLERANCE : tolerance;
}

/* Weighted RMS norm of v with weights tol (1 + |x|). */
static double scaled_norm(const double *v, const double *x, int n, double tolerance) {
    double sum = 0.0;
    for (int i = 0; i < n; i++) {
        const double e = v[i] / (tolerance * (1.0 + fabs(x[i])));
        sum += e * e;
    }
    return n > 0 ? sqrt(sum / n) : 0.0;
}

/* Hairer, Norsett & Wanner's starting step: 1 % of the time for f to change x noticeably. */
static double initial_step_size(CoreInstance *s, double step, double tolerance) {
    if (core_evaluate(s, s->x, s->work.rhs, NULL) != CORE_OK) return step;
    const double d0 = scaled_norm(s->x, s->x, s->nx, tolerance);
    const double d1 = scaled_norm(s->work.rhs, s->x, s->nx, tolerance);
    double h = (d0 < 1e-5 || d1 < 1e-5) ? 1e-6 : 0.01 * d0 / d1;
    return h < step ? h : step;
}

/* W = I / (h gamma) - J from the top-left NX x NX block of work.jacobian, factorised. */
static int factor_w(CoreInstance *s, double h) {
    const int nx = s->nx, ld = s->nx + s->nu;
    double *W = s->work.w_matrix;
    for (int i = 0; i < nx; i++) {
        for (int k = 0; k < nx; k++) {
            W[i * nx + k] = (i == k ? 1.0 / (h * GAMMA) : 0.0) - s->work.jacobian[i * ld + k];
        }
    }
    return core_lu_factor(W, nx, s->work.w_pivots);
}

/* Stage i: k_i = W^-1 (f(x + sum a_ij k_j) + sum c_ij / h k_j). */
static CoreStatus compute_stage(CoreInstance *s, const double *x, double h, int i) {
    CoreWorkspace *w = &s->work;
    const int nx = s->nx;
    memcpy(w->stage, x, (size_t)nx * sizeof(double));
    for (int j = 0; j < i; j++) {
        for (int n = 0; n < nx; n++) w->stage[n] += A[i][j] * w->k[j][n];
    }
    if (core_evaluate(s, w->stage, w->k[i], NULL) != CORE_OK) return CORE_ERROR;
    for (int j = 0; j < i; j++) {
        for (int n = 0; n < nx; n++) w->k[i][n] += C[i][j] / h * w->k[j][n];
    }
    core_lu_solve(w->w_matrix, nx, w->w_pivots, w->k[i]);
    return CORE_OK;
}

/* One RODAS4 sub-step of size h from x into work.x_new; returns the scaled error estimate
 * (HUGE_VAL if the model failed on the way or the result is not finite). */
static double attempt_substep(CoreInstance *s, const double *x, double h, double tolerance) {
    CoreWorkspace *w = &s->work;
    const int nx = s->nx;
    if (factor_w(s, h) != 0) return HUGE_VAL;
    for (int i = 0; i < STAGES; i++) {
        if (compute_stage(s, x, h, i) != CORE_OK) return HUGE_VAL;
    }
    double error = 0.0;
    for (int n = 0; n < nx; n++) {
        w->x_new[n] = x[n];
        for (int j = 0; j < STAGES; j++) w->x_new[n] += M[j] * w->k[j][n];
        if (!isfinite(w->x_new[n])) return HUGE_VAL;
        const double scale = tolerance * (1.0 + fmax(fabs(x[n]), fabs(w->x_new[n])));
        error = fmax(error, fabs(w->k[STAGES - 1][n]) / scale);
    }
    return error;
}

static double step_factor(double error, int accepted) {
    if (!isfinite(error)) return 0.25;
    double factor = error > 0.0 ? SAFETY * pow(error, -0.25) : MAX_GROWTH;
    const double largest = accepted ? MAX_GROWTH : 0.5;
    if (factor > largest) factor = largest;
    if (factor < MIN_SHRINK) factor = MIN_SHRINK;
    return factor;
}

static CoreStatus fail_step(CoreInstance *s, double t, const char *reason) {
    s->errors_suppressed = 0;
    core_log_error(s, "DoStep: integration of model %s stopped at t = %.17g: %s", MODEL_IDENTIFIER,
                   t, reason);
    s->time = t;
    s->last_successful_time = t;
    s->cache_valid = 0;
    return CORE_ERROR;
}

/* The step ends early at t, where the states are valid (see the file header). */
static CoreStatus discard_step(CoreInstance *s, double t, const char *reason) {
    s->errors_suppressed = 0;
    core_log(s, CORE_DISCARD, "logStatusDiscard",
             "DoStep: integration of model %s discarded at t = %.17g (the last successful time): "
             "%s; restore an FMU state, then retry with a shorter communication step or a larger "
             "solver_tolerance", MODEL_IDENTIFIER, t, reason);
    s->time = t;
    s->last_successful_time = t;
    s->step_size = 0.0;
    s->cache_valid = 0;
    return CORE_DISCARD;
}

/* Sub-steps from s->time to end (states in s->x); see the file header. */
static CoreStatus integrate(CoreInstance *s, double end, double tolerance) {
    double t = s->time;
    double h = s->step_size > 0.0 ? s->step_size : initial_step_size(s, end - t, tolerance);
    int jacobian_current = 0;
    for (long substep = 0; t < end; substep++) {
        if (substep >= MAX_SUBSTEPS_PER_STEP) return discard_step(s, t, "too many sub-steps");
        const int last = 1.1 * h >= end - t; /* rather one longer step than a tiny last one */
        const double h_used = last ? end - t : h;
        if (!jacobian_current) {
            s->errors_suppressed = 0; /* the Jacobian at an accepted state must exist */
            if (core_evaluate_jacobian(s, s->x) != CORE_OK) return fail_step(s, t, s->last_error);
            s->errors_suppressed = 1;
            jacobian_current = 1;
        }
        const double error = attempt_substep(s, s->x, h_used, tolerance);
        const int accepted = error <= 1.0;
        double h_next = h_used * step_factor(error, accepted);
        if (accepted) {
            t = last ? end : t + h_used;
            s->time = t; /* so that messages name the time reached */
            memcpy(s->x, s->work.x_new, (size_t)s->nx * sizeof(double));
            s->substeps++;
            jacobian_current = 0;
            if (last && h_used < h && h_next < h) h_next = h; /* a clipped step proves little */
        } else if (h_next <= 1e-14 * fmax(1.0, fabs(t))) {
            if (isfinite(error)) return discard_step(s, t, "step size too small for the tolerance");
            return fail_step(s, t, s->last_error);
        }
        h = h_next;
    }
    s->step_size = h;
    return CORE_OK;
}

CoreStatus core_do_step(CoreInstance *s, double current_time, double step) {
    const double end = current_time + step;
    s->errors_suppressed = 0;
    s->cache_valid = 0;
    if (core_prepare(s) != CORE_OK) return CORE_ERROR;
    if (step <= 0.0) return CORE_OK;
    const CoreStatus status = integrate(s, end, effective_tolerance(s));
    s->errors_suppressed = 0;
    if (status != CORE_OK) return status;
    s->time = end;
    if (core_update_cache(s) != CORE_OK) { /* outputs at the end of the step must be numbers */
        s->cache_valid = 0;
        return CORE_ERROR;
    }
    s->last_successful_time = end;
    core_log(s, CORE_OK, "logSolver", "DoStep to t = %g: %ld sub-steps so far, next h = %g", end,
             s->substeps, s->step_size);
    return CORE_OK;
}
