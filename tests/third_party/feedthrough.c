/* Direct feedthrough: y = k u at the same instant (computed on every read from the current
 * input); z = integral of u (no feedthrough). */
#define NR 4 /* k (par), u (in), y (out, feedthrough), z (out, state) */
#define NI 0
#define NB 0
#define NS 0
#include "fmi2_common.c"

static void model_defaults(Inst *m) { m->r[0] = 3.0; m->r[1] = 0.0; m->r[2] = 0.0; m->r[3] = 0.0; }
static void model_outputs(Inst *m) { m->r[2] = m->r[0] * m->r[1]; }

static fmi2Status model_step(Inst *m, fmi2Real t, fmi2Real h) {
    (void)t;
    m->r[3] += m->r[1] * h;
    return fmi2OK;
}
