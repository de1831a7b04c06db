/*
 * ffdl_ismc.c: online law of EmuIsmc3, the C twin of controllers/datadriven/laws.py Ismc
 * behind emu_control.py EmuIsmc (seed-001 FFDL-ISMC, eqs. 17-27): the sliding surface and
 * equivalent control of sliding.h, and the switching part of eq. 26 with the boundary
 * layer of eq. 27 (Delta rescaled to the units of y):
 *
 *   u = clip(u(t-1) + du_eq - K beta sat(s / Delta), lo, hi)
 *
 * State: the drive's (datadriven.h), then the sliding law's (sliding.h: estimator,
 * u, E, F, s).
 */
#include <stdlib.h>
#include <string.h>

#include "linalg.h"
#include "sliding.h"

#define N DD_N

struct law_core {
    dd_drive drive;
    sliding law;
    double beta, layer;
    int count;
    double* st;
};

law_core* law_make(const ato_values* p, double t0, char* err, size_t n) {
    (void)t0;
    const double* v = p->v;
    law_core* c = calloc(1, sizeof *c);
    if (!dd_drive_make(&c->drive, p, err, n)) {
        free(c);
        return NULL;
    }
    sliding_read(&c->law, v);
    c->beta = v[ATO_VR_beta];
    c->layer = v[ATO_VR_boundary_layer] * (v[ATO_VR_output_scale] / DD_KMH_PER_MPS);
    c->count = DD_DRIVE_STATE + sliding_state_count(&c->law);
    c->st = calloc(c->count, sizeof(double));
    sliding_bind(&c->law, c->st + DD_DRIVE_STATE);
    return c;
}

void law_free(law_core* c) {
    dd_drive_free(&c->drive);
    free(c->st);
    free(c);
}
DD_LAW_FLAT_STATE

int law_compute(law_core* c, double t, const ato_values* p, double* out, char* err, size_t n) {
    (void)err; (void)n;
    dd_sample smp;
    sliding* law = &c->law;
    double du[N];
    if (sliding_sample(law, &c->drive, t, p->v, &smp, du)) {
        double sat[N], sw[N], negK[N * N], want[N];
        /* Ismc.step: du_sw = -K beta sat(s / Delta) */
        for (int i = 0; i < N; i++)
            sat[i] = c->beta * ato_npclip(law->s[i] / c->layer, -1.0, 1.0);
        for (int i = 0; i < N * N; i++) negK[i] = -law->K[i];
        ato_matvec(negK, N, N, sat, sw);
        for (int i = 0; i < N; i++) want[i] = (law->u[i] + du[i]) + sw[i];
        sliding_finish(law, want, &smp);
    }
    dd_commit(&smp, law->u, c->st);
    dd_outputs(c->st, out);
    return 1;
}
