/*
 * ffdl_mfac.c: online law of EmuMfac3, the C twin of controllers/datadriven/laws.py Mfac
 * behind emu_control.py EmuMfac (seed-001 FFDL-MFAC baseline):
 *
 *   du = rho (delta I + Phi_2' Phi_2)^-1 Phi_2' (y_r(t+1) - y(t) - Phi_1 dy(t))
 *        - share (dev - K Phi_2r dev),   u = clip(u(t-1) + du, lo, hi)
 *
 * (K, Phi_2r: the truncated regularised inverse of linalg.h; dev = u(t-1) - mean). The
 * core's scalar operations in its order; matrix products summed in index order and the 3 x 3
 * solve by Gaussian elimination, where numpy calls BLAS and LAPACK: see
 * tests/test_native_datadriven.py for the bound. State: the drive's (datadriven.h), the
 * estimator's (ffdl.h), then u (n).
 */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "ffdl.h"
#include "linalg.h"

#define N DD_N

struct law_core {
    dd_drive drive;
    ffdl_params f;
    double delta, rho, share;
    int count;
    double* st;
    ffdl_est est;
    double* u;
};

law_core* law_make(const ato_values* p, double t0, char* err, size_t n) {
    (void)t0;
    law_core* c = calloc(1, sizeof *c);
    if (!dd_drive_make(&c->drive, p, err, n)) {
        free(c);
        return NULL;
    }
    ffdl_params_read(&c->f, p->v, 0);
    c->delta = p->v[ATO_VR_delta];
    c->rho = p->v[ATO_VR_rho];
    c->share = p->v[ATO_VR_share_gain];
    c->count = DD_DRIVE_STATE + ffdl_state_count(&c->f) + N;
    c->st = calloc(c->count, sizeof(double));
    ffdl_bind(&c->est, &c->f, c->st + DD_DRIVE_STATE);
    ffdl_init(&c->est, &c->f);
    c->u = c->st + DD_DRIVE_STATE + ffdl_state_count(&c->f);
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
    dd_sample s;
    dd_sample_inputs(&c->drive, t, p->v, &s);
    if (s.holding) { /* Law.hold */
        ffdl_observe(&c->est, &c->f, s.y, 0);
        apply(c, s.hold);
    } else {
        ffdl_observe(&c->est, &c->f, s.y, 1);
        double M[N * N], A[N * N], target[N], rhs[N], du[N], fr[N];
        ffdl_input_block(&c->est, &c->f, M);
        ffdl_free_response(&c->est, &c->f, fr);
        for (int i = 0; i < N; i++) target[i] = (s.y_r_next - s.y[i]) - fr[i];
        for (int i = 0; i < N; i++) {
            for (int j = 0; j < N; j++) {
                double sum = 0.0;
                for (int r = 0; r < N; r++) sum += M[r * N + i] * M[r * N + j];
                A[i * N + j] = (i == j ? c->delta * 1.0 : c->delta * 0.0) + sum;
            }
            double sum = 0.0;
            for (int r = 0; r < N; r++) sum += M[r * N + i] * target[r];
            rhs[i] = sum;
        }
        if (!ato_solve(A, rhs, N, du)) {
            snprintf(err, n, "MFAC: delta I + Phi_2' Phi_2 is singular (Singular matrix)");
            return 0;
        }
        for (int i = 0; i < N; i++) du[i] = c->rho * du[i];
        if (c->share > 0) {
            double Mr[N * N], K[N * N], sh[N];
            int kept;
            ato_truncated_gain(M, N, c->f.eps, c->f.cutoff, Mr, K, &kept);
            ato_null_space_share(c->u, Mr, K, N, c->share, sh);
            for (int i = 0; i < N; i++) du[i] = du[i] - sh[i];
        }
        double u[N];
        for (int i = 0; i < N; i++) u[i] = ato_npclip(c->u[i] + du[i], s.lo[i], s.hi[i]);
        apply(c, u);
    }
    dd_commit(&s, c->u, c->st);
    dd_outputs(c->st, out);
    return 1;
}
