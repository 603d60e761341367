/*
 * The contract between one generated model (model.c, written by fmu_src.codegen from the SymPy
 * equations) and the hand-written runtime shared by all models (fmu_core.c, fmi2_functions.c,
 * fmi3_functions.c).
 *
 * Every model is a mechanical system in generalised coordinates q (NQ of them) with velocities v:
 *
 *     dq/dt = v,      M(q) dv/dt = r(q, v, u),      y = h(q, v, u)
 *
 * The state vector seen by FMI is x = [q; v] (2*NQ values). Inputs u (NU), outputs y (NY) and the
 * parameter vector p (NP, Booleans stored as 0.0/1.0) are in the order of the ModelSpec.
 *
 * Matrices are row-major. Every function returns 0 on success and non-zero on failure, in which
 * case it has written a human-readable message (at most MODEL_MESSAGE_LENGTH bytes, terminated)
 * into `message`, e.g. "linkage cannot close at phi1 = 1.2 rad (thrust rod too short)".
 */
#ifndef MODEL_INTERFACE_H
#define MODEL_INTERFACE_H

#include <stddef.h>

#define MODEL_MESSAGE_LENGTH 512

/* model.c defines these constants (as `const int` / `const char *`). */
extern const int MODEL_NQ;               /* number of generalised coordinates */
extern const int MODEL_NU;               /* number of inputs */
extern const int MODEL_NY;               /* number of outputs */
extern const int MODEL_NP;               /* number of parameters (Real and Boolean) */
extern const char *MODEL_IDENTIFIER;     /* e.g. "Pantograph" */

/* Refuse an impossible parameter set (negative mass, linkage that cannot close, ...). */
int model_check_parameters(const double *p, char *message);

/* M(q): NQ x NQ, symmetric positive definite for admissible q. */
int model_mass_matrix(const double *p, const double *q, double *M, char *message);

/* dM/dq: NQ blocks of NQ x NQ; dM_dq[k*NQ*NQ + i*NQ + j] = d M_ij / d q_k. */
int model_mass_matrix_derivative(const double *p, const double *q, double *dM_dq, char *message);

/* r(q, v, u): generalised forces minus velocity-product (Coriolis/centrifugal) terms, NQ values. */
int model_forces(const double *p, const double *q, const double *v, const double *u,
                 double *r, char *message);

/* Exact partial derivatives of r: dr_dq (NQ x NQ), dr_dv (NQ x NQ), dr_du (NQ x NU). */
int model_forces_jacobian(const double *p, const double *q, const double *v, const double *u,
                          double *dr_dq, double *dr_dv, double *dr_du, char *message);

/* y = h(q, v, u), NY values. */
int model_outputs(const double *p, const double *q, const double *v, const double *u,
                  double *y, char *message);

/* Exact partial derivatives of h: dy_dq (NY x NQ), dy_dv (NY x NQ), dy_du (NY x NU). */
int model_outputs_jacobian(const double *p, const double *q, const double *v, const double *u,
                           double *dy_dq, double *dy_dv, double *dy_du, char *message);

/* Event indicators z(q, v, u): the importer locates where one changes sign (contact loss and
 * re-contact). Called only if model_config.h declares MODEL_NUMBER_OF_EVENT_INDICATORS > 0, so
 * hand-written models without events need not define it. */
int model_event_indicators(const double *p, const double *q, const double *v, const double *u,
                           double *z, char *message);

/* A starting point for the static-equilibrium Newton solve r(q, 0, u) = 0 (NQ values). */
int model_initial_guess(const double *p, const double *u, double *q, char *message);

#endif
