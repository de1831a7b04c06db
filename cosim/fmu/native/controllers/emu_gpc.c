/*
 * emu_gpc.c: online law of EmuGpc3, the C twin of controllers/datadriven/laws.py GpcLaw over
 * controllers/common/gpc.py Gpc behind emu_control.py EmuGpc (seed-001 GPC baseline): the GPC
 * of gpc.h on the n units' speeds (n outputs, n inputs), references R extrapolated
 * linearly from y_r(t), y_r(t+1) and clipped at 0; optional null-space force sharing on B_1
 * (truncated inverse of linalg.h with SHARE_INVERSE's eps and cutoff); u clipped to the
 * input box. See tests/test_native_datadriven.py.
 * State: the drive's (datadriven.h), then Gpc.state_fields (gpc.h); then GpcLaw's u
 * (n).
 */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "datadriven.h"
#include "gpc.h"
#include "linalg.h"

#define N DD_N

struct law_core {
    dd_drive drive;
    gpc_core gpc;
    double share;
    int count;
    double* st;
    double* u;
};

static double npmax(double a, double b) { return isnan(a) || isnan(b) ? a + b : (b > a ? b : a); }

law_core* law_make(const ato_values* p, double t0, char* err, size_t n) {
    (void)t0;
    const double* v = p->v;
    gpc_params gp = GPC_PARAMS(v, N, N);
    if (!gpc_check(&gp, err, n)) return NULL;
    law_core* c = calloc(1, sizeof *c);
    if (!dd_drive_make(&c->drive, p, err, n)) {
        free(c);
        return NULL;
    }
    c->share = v[ATO_VR_share_gain];
    int law = gpc_state_count(&gp);
    c->count = DD_DRIVE_STATE + law + N;
    c->st = calloc(c->count, sizeof(double));
    gpc_make(&c->gpc, &gp, c->st + DD_DRIVE_STATE);
    c->u = c->st + DD_DRIVE_STATE + law;
    return c;
}

void law_free(law_core* c) {
    dd_drive_free(&c->drive);
    gpc_free(&c->gpc);
    free(c->st);
    free(c);
}
DD_LAW_FLAT_STATE

int law_compute(law_core* c, double t, const ato_values* p, double* out, char* err, size_t n) {
    dd_sample smp;
    dd_sample_inputs(&c->drive, t, p->v, &smp);
    gpc_core* g = &c->gpc;
    if (smp.holding) {
        gpc_observe(g, smp.y, 0);
        gpc_applied(g, smp.hold);
        memcpy(c->u, smp.hold, sizeof(double) * N);
    } else {
        gpc_observe(g, smp.y, 1);
        for (int r = 0; r < g->p.Ny * N; r++) { /* R = max(y_r + j (y_r(t+1) - y_r), 0) */
            double ref = npmax(smp.y_r + (double)(r / N + 1) * (smp.y_r_next - smp.y_r), 0.0);
            g->refs[r] = ref * 1.0;
        }
        double u[N];
        if (!gpc_plan(g, g->refs, u)) {
            snprintf(err, n, "GPC: G'G + w I is singular (Singular matrix)");
            return 0;
        }
        if (c->share > 0) {
            double M[N * N], Mr[N * N], K[N * N], sh[N];
            int kept, ka = N * g->p.na;
            for (int i = 0; i < N; i++)
                for (int j = 0; j < N; j++) M[i * N + j] = g->theta[i * g->nreg + ka + j];
            ato_truncated_gain(M, N, DD_SHARE_EPS, DD_SHARE_CUTOFF, Mr, K, &kept);
            ato_null_space_share(c->u, Mr, K, N, c->share, sh);
            for (int i = 0; i < N; i++) u[i] = u[i] - sh[i];
        }
        for (int i = 0; i < N; i++) c->u[i] = ato_npclip(u[i], smp.lo[i], smp.hi[i]);
        gpc_applied(g, c->u);
    }
    dd_commit(&smp, c->u, c->st);
    dd_outputs(c->st, out);
    return 1;
}
