/*
 * ffdl.h: the FFDL pseudo-Jacobian estimator (seed 001 eqs. 8-16), the C twin of
 * controllers/common/ffdl.py FfdlEstimator, with the seed-001 core's rescaling of its
 * thresholds (controllers/datadriven/emu_control.py rescaled), for ffdl_mfac.c and
 * sliding.c (ffdl_ismc.c, ffdl_ismpc.c).
 *
 * Its state is ffdl_state_count() doubles of the law's state array, in the order of
 * FfdlEstimator.state_fields: phi (n x n(L_y + L_u), row-major), y_prev (n), dy_hist (L_y x n,
 * newest first), du_hist (L_u x n), u_prev (n), dH_prev (n(L_y + L_u)), dd_hat (n),
 * dd_hat_prev (n), resets, started (0/1).
 */
#ifndef ATO_FFDL_H
#define ATO_FFDL_H

#include "datadriven.h"

typedef struct ffdl_params {
    double mu, step, phi1_init, phi2_init, reset_threshold, excitation, eps, cutoff;
    int L_y, L_u, innovation_dd_hat, disturbance;
} ffdl_params;

typedef struct ffdl_est {
    double *phi, *y_prev, *dy_hist, *du_hist, *u_prev, *dH_prev, *dd_hat, *dd_hat_prev;
    double *resets, *started;
} ffdl_est;

/* the estimator's parameters of the FMU (rescaled: gy = output_scale / 3.6, gu =
 * input_scale); disturbance: the law's use of dd_hat */
void ffdl_params_read(ffdl_params* f, const double* v, int disturbance);
int ffdl_state_count(const ffdl_params* f);
/* point e into the law's state at `at` and set the initial state */
void ffdl_bind(ffdl_est* e, const ffdl_params* f, double* at);
void ffdl_init(const ffdl_est* e, const ffdl_params* f);
void ffdl_observe(const ffdl_est* e, const ffdl_params* f, const double* y, int adapt);
void ffdl_applied(const ffdl_est* e, const ffdl_params* f, const double* u);
void ffdl_free_response(const ffdl_est* e, const ffdl_params* f, double* out);
/* Phi_2, the block multiplying du(t) (n x n) */
void ffdl_input_block(const ffdl_est* e, const ffdl_params* f, double* m);

#endif
