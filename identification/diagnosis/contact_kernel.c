/* The switched recursion of a unilateral contact, compiled
 * (panto.identification.diagnosis.contact_kernel; the NumPy functions _run_switched and _within of
 * panto.identification.diagnosis.unilateral_contact are the reference, step for step).
 *
 * Row-major arrays; n states, m inputs, width = n + 2 m (state, input, input slope), count = M
 * sub-steps per sample. tables[6 * mode + t], mode 0 in contact and 1 in flight, t:
 *   0 maps    (M, n, width)  x((j + 1) h) = maps[j] z
 *   1 rows    (M, width)     c_F maps[j]
 *   2 rows_x  (n, M)         the state part of rows, transposed
 *   3 offsets (N - 1, M)     the rest of the force at the sub-step instants of each sample
 *   4 drive   (N - 1, n)     the whole sample's input part
 * offsets and drive may be NULL: then the rows needed are computed from maps, rows, u and slope
 * (only in the samples the recursion visits in that mode: the flight's few).
 *   5 kick    (n, 2)         b_c and A b_c
 * states (N, n) holds on entry the whole run in contact (also passed unchanged as `bilateral`);
 * rows start + 1 .. N - 1 are overwritten. Contact stretches of `stretch` samples from the
 * bilateral run and Phi^j (powers), flight stretches of `flight_stretch` samples from Phi_f^j and
 * the convolution of the drive, as the NumPy code; each stretch is checked sample by sample (the
 * samples up to the first switch do not depend on the later ones). Compile in ISO C without
 * fused multiply-adds and with libm's pow kept (-ffp-contract=off -fno-builtin): the arithmetic is
 * the NumPy code's operation by operation, up to the summation order of its matrix products.
 * Returns 0, or -1 when the workspace cannot be allocated. */
#include <math.h>
#include <stddef.h>
#include <stdlib.h>
#include <string.h>

#define IN_CONTACT 0
#define IN_FLIGHT 1

struct problem {
    size_t n, m, width, count;
    const double *c_force, *d_force;
    double h;
    const double *const *tables;
    const double *u, *slope;
};

static double dot(const double *a, const double *b, size_t length)
{
    double sum = 0.0;
    size_t i;
    for (i = 0; i < length; ++i) {
        sum += a[i] * b[i];
    }
    return sum;
}

static const double *table(const struct problem *p, int mode, int which)
{
    return p->tables[6 * mode + which];
}

/* The force g = c_F x + d_F u of z = [x, u, ...]. */
static double force(const struct problem *p, const double *z)
{
    return dot(p->c_force, z, p->n) + dot(p->d_force, z + p->n, p->m);
}

/* First index i < length with g[i] on the wrong side for `mode`, or length. */
static size_t first_wrong(const double *g, size_t length, int mode)
{
    size_t i;
    for (i = 0; i < length; ++i) {
        if (mode == IN_CONTACT ? g[i] < 0.0 : g[i] >= 0.0) {
            return i;
        }
    }
    return length;
}

/* _within: one sample across its switches from z (width, overwritten), its force g (count,
 * overwritten) at the sub-step instants and the first wrong index; x (n) and the new mode out. */
static int within(const struct problem *p, int mode, double *z, double *g, size_t first,
                  double *work, double *x)
{
    const size_t n = p->n, m = p->m, width = p->width, count = p->count;
    const double h = p->h;
    double *u_start = work + width, *slope = u_start + m;
    size_t i, j = 0;
    memcpy(u_start, z + n, 2 * m * sizeof(double));
    for (;;) {
        const double before = first == 0 ? force(p, z) : g[first - 1];
        const double share = before != g[first] ? before / (before - g[first]) : 1.0;
        const size_t steps = first + 1;
        const double rest = (1.0 - share) * h, rate = (g[first] - before) / h;
        const double *map = table(p, mode, 0) + (steps - 1) * n * width;
        const double *kick = table(p, 1 - mode, 5);
        const double sign = mode == IN_CONTACT ? 1.0 : -1.0;
        const double square = pow(rest, 2.0) / 2, cube = pow(rest, 3.0) / 6;
        double factor, ramp, wire;
        size_t left;
        for (i = 0; i < n; ++i) {
            work[i] = dot(map + i * width, z, width);
        }
        for (i = 0; i < m; ++i) {
            z[n + i] = u_start[i] + slope[i] * ((double)(j + steps) * h);
            z[n + m + i] = slope[i];
        }
        factor = sign * rate;
        for (i = 0; i < n; ++i) {
            z[i] = work[i] + factor * (kick[2 * i] * square + kick[2 * i + 1] * cube);
        }
        j += steps;
        if (j >= count) {
            memcpy(x, z, n * sizeof(double));
            return force(p, z) >= 0.0 ? IN_CONTACT : IN_FLIGHT;
        }
        mode = 1 - mode;
        left = count - j;
        ramp = dot(p->d_force, slope, m) * h;
        wire = dot(p->d_force, z + n, m);
        for (i = 0; i < left; ++i) {
            g[i] = dot(table(p, mode, 1) + i * width, z, width) + ramp * (double)(i + 1) + wire;
        }
        first = first_wrong(g, left, mode);
        if (first == left) {
            map = table(p, mode, 0) + (left - 1) * n * width;
            for (i = 0; i < n; ++i) {
                x[i] = dot(map + i * width, z, width);
            }
            return mode;
        }
    }
}

/* The rest of the force at the sub-step instants of sample k where the mode's table is NULL:
 * u_k (rows[i, n:n+m] + d_F) + s_k rows[i, n+m:] + (s_k d_F) (i + 1) h, as _prepare. */
static const double *offsets_row(const struct problem *p, int mode, size_t k, double *out)
{
    const size_t n = p->n, m = p->m;
    const double *rows = table(p, mode, 1), *u = p->u + k * m, *slope = p->slope + k * m;
    const double ramp = dot(slope, p->d_force, m);
    size_t i, l;
    for (i = 0; i < p->count; ++i) {
        const double *row = rows + i * p->width;
        double input = 0.0, rate = 0.0;
        for (l = 0; l < m; ++l) {
            input += u[l] * (row[n + l] + p->d_force[l]);
        }
        for (l = 0; l < m; ++l) {
            rate += slope[l] * row[n + m + l];
        }
        out[i] = (input + rate) + ramp * ((double)(i + 1) * p->h);
    }
    return out;
}

/* The whole sample's input part of sample k where the mode's table is NULL:
 * maps[M - 1][:, n:n+m] u_k + maps[M - 1][:, n+m:] s_k, as _prepare. */
static void drive_row(const struct problem *p, int mode, size_t k, double *out)
{
    const size_t n = p->n, m = p->m;
    const double *map = table(p, mode, 0) + (p->count - 1) * n * p->width;
    size_t a;
    for (a = 0; a < n; ++a) {
        const double *row = map + a * p->width;
        out[a] = dot(p->u + k * m, row + n, m) + dot(p->slope + k * m, row + n + m, m);
    }
}

/* g[i] = c_F x((i + 1) h) = rows_x[i] x + offsets[i], i < count, with rows_x given transposed
 * (n, count): the sum over the states in the order of dot(), vectorised across the instants. */
static void sub_step_forces(const double *rows_t, const double *x, const double *offsets,
                            size_t n, size_t count, double *g)
{
    size_t i, l;
    for (i = 0; i < count; ++i) {
        g[i] = 0.0;
    }
    for (l = 0; l < n; ++l) {
        const double *column = rows_t + l * count;
        const double value = x[l];
        for (i = 0; i < count; ++i) {
            g[i] += column[i] * value;
        }
    }
    for (i = 0; i < count; ++i) {
        g[i] += offsets[i];
    }
}

/* run[j] of the stretch from sample k: in contact bilateral[k + j] + Phi^j diff, in flight
 * Phi_f^j x0 + sum_{i < j} Phi_f^(j - 1 - i) drive[i] (drive from sample k on). */
static void stretch_state(const struct problem *p, int mode, const double *powers,
                          const double *bilateral, const double *drive, const double *origin,
                          size_t k, size_t j, double *run)
{
    const size_t n = p->n;
    const double *power = powers + j * n * n;
    size_t a, i;
    for (a = 0; a < n; ++a) {
        const double part = dot(power + a * n, origin, n);
        if (mode == IN_CONTACT) {
            run[a] = bilateral[(k + j) * n + a] + part;
        } else {
            double sum = 0.0;
            for (i = 0; i < j; ++i) {
                const double *lagged = powers + (j - 1 - i) * n * n + a * n;
                size_t b;
                for (b = 0; b < n; ++b) {
                    sum += lagged[b] * drive[i * n + b];
                }
            }
            run[a] = j == 0 ? part : part + sum;
        }
    }
}

int contact_switched(double *states, const double *bilateral, const double *u,
                     const double *slope, size_t samples, size_t n, size_t m, size_t count,
                     size_t start, const double *c_force, const double *d_force, double h,
                     const double *powers, size_t stretch, const double *flight_powers,
                     size_t flight_stretch, const double *const *tables)
{
    const struct problem p = {n, m, n + 2 * m, count, c_force, d_force, h, tables, u, slope};
    const size_t last = samples - 1, width = n + 2 * m;
    const size_t longest = stretch > flight_stretch ? stretch : flight_stretch;
    double *work = malloc((3 * width + 3 * n + 2 * count + longest * n) * sizeof(double));
    double *x, *origin, *run, *z, *g, *scratch, *lazy_offsets, *lazy_drive;
    size_t k = start, i;
    int mode;
    if (work == NULL) {
        return -1;
    }
    x = work; origin = x + n; run = origin + n; z = run + n; g = z + width; scratch = g + count;
    lazy_offsets = scratch + 2 * width; lazy_drive = lazy_offsets + count;
    memcpy(x, states + start * n, n * sizeof(double));
    mode = dot(c_force, x, n) + dot(d_force, u + start * m, m) >= 0.0 ? IN_CONTACT : IN_FLIGHT;
    while (k < last) {
        const double *rows_x = table(&p, mode, 2), *offsets = table(&p, mode, 3);
        const double *drive = table(&p, mode, 4) != NULL ? table(&p, mode, 4) + k * n
                              : lazy_drive;
        const size_t end = k + (mode == IN_CONTACT ? stretch : flight_stretch) < last
                           ? k + (mode == IN_CONTACT ? stretch : flight_stretch) : last;
        size_t j, next = end;
        for (i = 0; i < n; ++i) {
            origin[i] = mode == IN_CONTACT ? x[i] - bilateral[k * n + i] : x[i];
        }
        for (j = 0; j <= end - k; ++j) {
            size_t wrong;
            if (j > 0 && drive == lazy_drive) {
                drive_row(&p, mode, k + j - 1, lazy_drive + (j - 1) * n);
            }
            stretch_state(&p, mode, mode == IN_CONTACT ? powers : flight_powers, bilateral,
                          drive, origin, k, j, run);
            if (j > 0) {
                memcpy(states + (k + j) * n, run, n * sizeof(double));
            }
            if (j == end - k) {
                memcpy(x, run, n * sizeof(double));
                break;
            }
            sub_step_forces(rows_x, run, offsets != NULL ? offsets + (k + j) * count
                            : offsets_row(&p, mode, k + j, lazy_offsets), n, count, g);
            wrong = first_wrong(g, count, mode);
            if (wrong < count) {
                memcpy(z, run, n * sizeof(double));
                memcpy(z + n, u + (k + j) * m, m * sizeof(double));
                memcpy(z + n + m, slope + (k + j) * m, m * sizeof(double));
                mode = within(&p, mode, z, g, wrong, scratch, x);
                next = k + j + 1;
                memcpy(states + next * n, x, n * sizeof(double));
                break;
            }
        }
        k = next;
    }
    free(work);
    return 0;
}

/* The run in contact, sample by sample: states[k + 1] = Phi states[k] + drive[k], states (N, n)
 * with states[0] set on entry, drive (N - 1, n). */
void contact_propagate(double *states, const double *phi, const double *drive, size_t samples,
                       size_t n)
{
    size_t k, i;
    for (k = 0; k + 1 < samples; ++k) {
        const double *x = states + k * n;
        double *next = states + (k + 1) * n;
        for (i = 0; i < n; ++i) {
            next[i] = dot(phi + i * n, x, n) + drive[k * n + i];
        }
    }
}
