/*
 * ffdl_ismc.c: online law of EmuIsmc3, the C twin of controllers/datadriven/laws.py Ismc
 * (SlidingLaw) behind emu_control.py EmuIsmc (seed-001 FFDL-ISMC, eqs. 17-27):
 *
 *   s = e + k1 E(t-1) + b k2 F(t-1),  e = y - y_r,  E(t) = E + e,  F(t) = F + sig^alpha(e)
 *   (the units' departures from the mean sum removed: common_integral)
 *   du_eq = K (s - k1 E(t) - b k2 F(t) - dd_hat + y_r(t+1) - y - Phi_1 dy) - share (...)
 *   u = clip(u(t-1) + du_eq - K beta sat(s / Delta), lo, hi)
 *
 * with anti-windup (E, F held when every unit is pushed against its bound), b and Delta
 * rescaled to the units of y. The core's scalar operations in its order (sig^alpha: libm pow,
 * sqrt for alpha = 0.5 as numpy); matrix products summed in index order: see
 * tests/test_native_datadriven.py for the bound. State: the drive's (ato_datadriven.h), the
 * estimator's (ato_ffdl.h), then u, E, F, s (n each).
 */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "ato_ffdl.h"
#include "ato_linalg.h"

#define N DD_N

struct law_core {
    dd_drive drive;
    ffdl_params f;
    double k1, k2, b, alpha, share, common, beta, layer;
    int anti_windup, count;
    double* st;
    ffdl_est est;
    double *u, *E, *F, *s;
};

static double npclip(double x, double lo, double hi) {
    double a = isnan(x) || isnan(lo) ? x + lo : (lo > x ? lo : x);
    return isnan(a) || isnan(hi) ? a + hi : (hi < a ? hi : a);
}

/* sig^alpha(x) = sign(x) |x|^alpha (numpy: x ** 0.5 is sqrt) */
static double sig(double x, double alpha) {
    double sign = isnan(x) ? x : x > 0 ? 1.0 : x < 0 ? -1.0 : 0.0;
    double mag = alpha == 0.5 ? sqrt(fabs(x)) : pow(fabs(x), alpha);
    return sign * mag;
}

law_core* law_make(const ato_values* p, double t0, char* err, size_t n) {
    (void)t0;
    const double* v = p->v;
    law_core* c = calloc(1, sizeof *c);
    if (!dd_drive_make(&c->drive, p, err, n)) {
        free(c);
        return NULL;
    }
    ffdl_params_read(&c->f, v, v[ATO_VR_disturbance_estimate] != 0.0);
    double gy = v[ATO_VR_output_scale] / DD_KMH_PER_MPS; /* rescaled() */
    c->k1 = v[ATO_VR_k1];
    c->k2 = v[ATO_VR_k2];
    c->alpha = v[ATO_VR_alpha];
    c->b = v[ATO_VR_b] * pow(gy, 1.0 - c->alpha);
    c->share = v[ATO_VR_share_gain];
    c->common = v[ATO_VR_common_integral];
    c->anti_windup = v[ATO_VR_anti_windup] != 0.0;
    c->beta = v[ATO_VR_beta];
    c->layer = v[ATO_VR_boundary_layer] * gy;
    int est = ffdl_state_count(&c->f);
    c->count = DD_DRIVE_STATE + est + 4 * N;
    c->st = calloc(c->count, sizeof(double));
    ffdl_bind(&c->est, &c->f, c->st + DD_DRIVE_STATE);
    ffdl_init(&c->est, &c->f);
    c->u = c->st + DD_DRIVE_STATE + est;
    c->E = c->u + N;
    c->F = c->E + N;
    c->s = c->F + N;
    return c;
}

void law_free(law_core* c) {
    dd_drive_free(&c->drive);
    free(c->st);
    free(c);
}
DD_LAW_FLAT_STATE

static void apply(law_core* c, const double* u) {
    ffdl_applied(&c->est, &c->f, u);
    memmove(c->u, u, sizeof(double) * N);
}

int law_compute(law_core* c, double t, const ato_values* p, double* out, char* err, size_t n) {
    (void)err; (void)n;
    dd_sample smp;
    dd_sample_inputs(&c->drive, t, p->v, &smp);
    const double* y = smp.y;
    if (smp.holding) { /* SlidingLaw.hold */
        ffdl_observe(&c->est, &c->f, y, 0);
        apply(c, smp.hold);
        for (int i = 0; i < N; i++) c->E[i] = c->F[i] = c->s[i] = 0.0;
    } else {
        /* SlidingLaw.equivalent */
        ffdl_observe(&c->est, &c->f, y, 1);
        double e[N], s[N], E[N], F[N], M[N * N], Mr[N * N], K[N * N], fr[N], r[N], du[N];
        double bk2 = c->b * c->k2;
        for (int i = 0; i < N; i++) {
            e[i] = y[i] - smp.y_r;
            s[i] = (e[i] + c->k1 * c->E[i]) + bk2 * c->F[i];
            E[i] = c->E[i] + e[i];
            F[i] = c->F[i] + sig(e[i], c->alpha);
        }
        if (c->common > 0) { /* the units' speed differences integrate to coupler stretch */
            double mE = dd_sum(E, N) / N, mF = dd_sum(F, N) / N;
            for (int i = 0; i < N; i++) {
                E[i] = E[i] - c->common * (E[i] - mE);
                F[i] = F[i] - c->common * (F[i] - mF);
            }
        }
        ffdl_input_block(&c->est, &c->f, M);
        int kept;
        ato_truncated_gain(M, N, c->f.eps, c->f.cutoff, Mr, K, &kept);
        ffdl_free_response(&c->est, &c->f, fr);
        for (int i = 0; i < N; i++)
            r[i] = (((((s[i] - c->k1 * E[i]) - bk2 * F[i]) - c->est.dd_hat[i]) + smp.y_r_next)
                    - y[i]) - fr[i];
        ato_matvec(K, N, N, r, du);
        if (c->share > 0) {
            double sh[N];
            ato_null_space_share(c->u, Mr, K, N, c->share, sh);
            for (int i = 0; i < N; i++) du[i] = du[i] - sh[i];
        }
        memcpy(c->s, s, sizeof s);
        /* Ismc.step: du_sw = -K beta sat(s / Delta) */
        double sat[N], sw[N], negK[N * N], want[N], u[N];
        for (int i = 0; i < N; i++) sat[i] = c->beta * npclip(s[i] / c->layer, -1.0, 1.0);
        for (int i = 0; i < N * N; i++) negK[i] = -K[i];
        ato_matvec(negK, N, N, sat, sw);
        for (int i = 0; i < N; i++) want[i] = (c->u[i] + du[i]) + sw[i];
        /* SlidingLaw._finish */
        int all_pushed = 1;
        for (int i = 0; i < N; i++) {
            u[i] = npclip(want[i], smp.lo[i], smp.hi[i]);
            int pushed = (want[i] >= smp.hi[i] - DD_BOUND_TOL && c->s[i] < 0)
                         || (want[i] <= smp.lo[i] + DD_BOUND_TOL && c->s[i] > 0);
            all_pushed &= pushed;
        }
        if (!(c->anti_windup && all_pushed)) {
            memcpy(c->E, E, sizeof E);
            memcpy(c->F, F, sizeof F);
        }
        apply(c, u);
    }
    dd_commit(&smp, c->u, c->st);
    dd_outputs(c->st, out);
    return 1;
}
