/* Coulomb friction on one coordinate of a discretised linear model, stepped sample by sample
 * (panto.identification.diagnosis.stick_slip, whose NumPy loop _step_numpy is the reference).
 *
 * states: (samples x n), row-major; on entry states[0] = x_start and states[k + 1] = drive[k];
 * on return states[k + 1] = drive[k] + Phi states[k] + column * clip(f, level), with
 * f = -(drive[k] + Phi states[k])[joint] / gain (0 when gain == 0) and clip reproducing
 * Python's min(level, max(-level, f)) (a NaN f gives -level).
 * Compile without -ffast-math and in ISO C mode (no FMA contraction): the arithmetic is the
 * NumPy loop's, operation by operation, up to the summation order of the matrix product. */
#include <stddef.h>

int stick_slip_step(double *states, const double *phi, const double *column,
                    size_t samples, size_t n, size_t joint, double gain,
                    double level)
{
    size_t k, i, j;
    if (joint >= n) {
        return -1;
    }
    for (k = 0; k + 1 < samples; ++k) {
        const double *x = states + k * n;
        double *row = states + (k + 1) * n;
        double f, clipped;
        for (i = 0; i < n; ++i) {
            const double *phi_row = phi + i * n;
            double sum = 0.0;
            for (j = 0; j < n; ++j) {
                sum += phi_row[j] * x[j];
            }
            row[i] += sum;
        }
        f = gain != 0.0 ? -row[joint] / gain : 0.0;
        clipped = -level;      /* max(-level, f): f replaces -level only when f > -level */
        if (f > clipped) {
            clipped = f;
        }
        if (!(clipped < level)) { /* min(level, .): replaces level only when smaller */
            clipped = level;
        }
        for (i = 0; i < n; ++i) {
            row[i] += column[i] * clipped;
        }
    }
    return 0;
}
