/* freight_kernel.h: the freight sub-step kernel's interface (freight_kernel.c, the C twin of
 * plants/kernels.py's freight_steps), written once for its callers: the native FreightTrain
 * (freight.c) and, through ctypes, benchmarks/bench_kernels.py (same argument layout). */
#ifndef FREIGHT_KERNEL_H
#define FREIGHT_KERNEL_H

#include <stdint.h>

/* the constants cp[], the scalars sc[] and the rows of the work array, by index */
enum { C_STICTION, C_K, C_C, C_SLACK, C_MODEL, C_TAU, C_RAMP_RATE, C_F_MAX, C_P_MAX, C_ED_MAX,
       C_ED_P_MAX, C_ED_FADE, C_PMAX, C_FILL_T, C_FILL_E, C_REL_T, C_REL_E, C_R_FULL, C_R_MIN,
       N_CONST };
enum { S_TRACTION, S_ENERGY, S_PEAK_DRAFT, S_PEAK_BUFF, S_ACCEL, S_FIRST, S_HELD, N_SCALARS };
enum { W_START, W_MEAN_P, W_Y, W_W, W_DIAG, W_CPRIME, W_RPRIME, W_V1, N_WORK };

/* Arguments as plants.kernels.freight_steps; n vehicles, n_sub sub-steps, K commands, nx
 * route knots; arrivals is K x n (C order), work N_WORK x n, targets K doubles of scratch. */
void freight_steps(int64_t n, int64_t n_sub, int64_t K, int64_t nx, double *x, double *v,
                   double *pres, double *sc, const double *hs, const double *t0s,
                   const double *t1s, const double *demands, const double *arrivals,
                   const double *values, const double *m_eff, const double *length,
                   const double *res_a, const double *res_b, const double *res_c,
                   const double *wpk, const double *brake_scale, const double *xs,
                   const double *cum, const double *slopes, int64_t *hint_f, int64_t *hint_r,
                   const double *cp, double *work, double *targets);

#endif
