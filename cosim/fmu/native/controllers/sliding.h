/*
 * sliding.h: the integral sliding surface and equivalent control shared by FFDL-ISMC and
 * FFDL-ISMPC (ffdl_ismc.c, ffdl_ismpc.c), the C twin of controllers/datadriven/laws.py
 * SlidingLaw (seed-001 eqs. 17-24):
 *
 *   s = e + k1 E(t-1) + b k2 F(t-1),  e = y - y_r,  E(t) = E + e,  F(t) = F + sig^alpha(e)
 *   (the units' departures from the mean sum removed: common_integral)
 *   du_eq = K (s - k1 E(t) - b k2 F(t) - dd_hat + y_r(t+1) - y - Phi_1 dy) - share (...)
 *
 * and SlidingLaw._finish: the input clipped to the box, the sums E, F held when every unit is
 * pushed against its bound (anti-windup). b is rescaled to the units of y. The core's scalar
 * operations in its order (sig^alpha: libm pow, sqrt for alpha = 0.5 as numpy); matrix
 * products summed in index order: see tests/test_native_datadriven.py for the bound.
 * State (in the law's state array after the drive's): the estimator's (ffdl.h), then u,
 * E, F, s (n each): sliding_state_count() doubles.
 */
#ifndef ATO_SLIDING_H
#define ATO_SLIDING_H

#include "ffdl.h"

typedef struct sliding {
    ffdl_params f;
    double k1, k2, b, alpha, share, common;
    int anti_windup;
    ffdl_est est;
    double *u, *E, *F, *s;
    /* of the last sliding_equivalent: the candidate sums E(t), F(t), the truncated input
     * block M_r, its inverse K, and the kept singular values and right singular vectors of
     * Phi_2 (sv[kept], vt[kept x n], truncated_gain's sv and Vt) */
    double E_next[DD_N], F_next[DD_N], M[DD_N * DD_N], K[DD_N * DD_N];
    double sv[DD_N], vt[DD_N * DD_N];
    int kept;
} sliding;

/* the surface's and estimator's parameters of the FMU (values by value reference) */
void sliding_read(sliding* c, const double* v);
int sliding_state_count(const sliding* c);
/* point the estimator and u, E, F, s into the state at `at` and set their initial values */
void sliding_bind(sliding* c, double* at);
/* The sample's inputs at t into smp (dd_sample_inputs); at a holding sample SlidingLaw.hold
 * (the holding input imposed, the sums and s zeroed) and 0; otherwise SlidingLaw.equivalent
 * (observe y(t); s(t) into c->s, du_eq into du) and 1: the law then ends the sample with
 * sliding_finish */
int sliding_sample(sliding* c, const dd_drive* d, double t, const double* in, dd_sample* smp,
                   double* du);
/* SlidingLaw._finish: u = clip(want, lo, hi) applied, the sums committed unless held */
void sliding_finish(sliding* c, const double* want, const dd_sample* smp);

#endif
