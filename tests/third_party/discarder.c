/* Refuses (fmi2Discard, not terminated) any communication step longer than max_step; otherwise
 * integrates x' = u exactly (u is held over the step). */
#define NR 3 /* max_step (par), u (in), x (out) */
#define NI 0
#define NB 0
#define NS 0
#include "fmi2_common.c"

static void model_defaults(Inst *m) { m->r[0] = 0.125; m->r[1] = 1.0; m->r[2] = 0.0; }
static void model_outputs(Inst *m) { (void)m; }

static fmi2Status model_step(Inst *m, fmi2Real t, fmi2Real h) {
    if (h > m->r[0] * (1.0 + 1e-12)) {
        m->last_successful = t;
        logf_(m, fmi2Discard, "step %g at t = %g is longer than max_step = %g", h, t, m->r[0]);
        return fmi2Discard;
    }
    m->r[2] += m->r[1] * h;
    return fmi2OK;
}
