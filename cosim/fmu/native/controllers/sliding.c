/* sliding.c: see sliding.h. */
#include <math.h>
#include <string.h>

#include "linalg.h"
#include "sliding.h"

#define N DD_N

/* sig^alpha(x) = sign(x) |x|^alpha (numpy: x ** 0.5 is sqrt) */
static double sig(double x, double alpha) {
    double sign = isnan(x) ? x : x > 0 ? 1.0 : x < 0 ? -1.0 : 0.0;
    double mag = alpha == 0.5 ? sqrt(fabs(x)) : pow(fabs(x), alpha);
    return sign * mag;
}

void sliding_read(sliding* c, const double* v) {
    ffdl_params_read(&c->f, v, v[ATO_VR_disturbance_estimate] != 0.0);
    double gy = v[ATO_VR_output_scale] / DD_KMH_PER_MPS; /* rescaled() */
    c->k1 = v[ATO_VR_k1];
    c->k2 = v[ATO_VR_k2];
    c->alpha = v[ATO_VR_alpha];
    c->b = v[ATO_VR_b] * pow(gy, 1.0 - c->alpha);
    c->share = v[ATO_VR_share_gain];
    c->common = v[ATO_VR_common_integral];
    c->anti_windup = v[ATO_VR_anti_windup] != 0.0;
}

int sliding_state_count(const sliding* c) { return ffdl_state_count(&c->f) + 4 * N; }

void sliding_bind(sliding* c, double* at) {
    ffdl_bind(&c->est, &c->f, at);
    ffdl_init(&c->est, &c->f);
    c->u = at + ffdl_state_count(&c->f);
    c->E = c->u + N;
    c->F = c->E + N;
    c->s = c->F + N;
}

static void apply(sliding* c, const double* u) {
    ffdl_applied(&c->est, &c->f, u);
    memmove(c->u, u, sizeof(double) * N);
}

int sliding_sample(sliding* c, const dd_drive* d, double t, const double* in, dd_sample* smp,
                   double* du) {
    dd_sample_inputs(d, t, in, smp);
    const double* y = smp->y;
    if (smp->holding) {
        ffdl_observe(&c->est, &c->f, y, 0);
        apply(c, smp->hold);
        for (int i = 0; i < N; i++) c->E[i] = c->F[i] = c->s[i] = 0.0;
        return 0;
    }
    ffdl_observe(&c->est, &c->f, y, 1);
    double e[N], s[N], *E = c->E_next, *F = c->F_next, M[N * N], fr[N], r[N];
    double bk2 = c->b * c->k2;
    for (int i = 0; i < N; i++) {
        e[i] = y[i] - smp->y_r;
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
    ato_truncated_svd(M, N, c->f.eps, c->f.cutoff, c->M, c->K, c->sv, c->vt, &c->kept);
    ffdl_free_response(&c->est, &c->f, fr);
    for (int i = 0; i < N; i++)
        r[i] = (((((s[i] - c->k1 * E[i]) - bk2 * F[i]) - c->est.dd_hat[i]) + smp->y_r_next)
                - y[i]) - fr[i];
    ato_matvec(c->K, N, N, r, du);
    if (c->share > 0) {
        double sh[N];
        ato_null_space_share(c->u, c->M, c->K, N, c->share, sh);
        for (int i = 0; i < N; i++) du[i] = du[i] - sh[i];
    }
    memcpy(c->s, s, sizeof s);
    return 1;
}

void sliding_finish(sliding* c, const double* want, const dd_sample* smp) {
    double u[N];
    int all_pushed = 1;
    for (int i = 0; i < N; i++) {
        u[i] = ato_npclip(want[i], smp->lo[i], smp->hi[i]);
        int pushed = (want[i] >= smp->hi[i] - DD_BOUND_TOL && c->s[i] < 0)
                     || (want[i] <= smp->lo[i] + DD_BOUND_TOL && c->s[i] > 0);
        all_pushed &= pushed;
    }
    if (!(c->anti_windup && all_pushed)) {
        memcpy(c->E, c->E_next, sizeof c->E_next);
        memcpy(c->F, c->F_next, sizeof c->F_next);
    }
    apply(c, u);
}
