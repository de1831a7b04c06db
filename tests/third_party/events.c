/* Time events inside a communication step: at every t_k = k period crossed in (t, t + h] the
 * FMU samples its input (held over the step) into q and counts the event in n. */
#define NR 3 /* period (par), u (in), q (out) */
#define NI 1 /* n (out) */
#define NB 0
#define NS 0
#include "fmi2_common.c"

static void model_defaults(Inst *m) { m->r[0] = 0.1; m->r[1] = 0.0; m->r[2] = 0.0; m->i[0] = 0; }
static void model_outputs(Inst *m) { (void)m; }

static fmi2Status model_step(Inst *m, fmi2Real t, fmi2Real h) {
    fmi2Integer last = (fmi2Integer)floor((t + h) / m->r[0] + 1e-9);
    while (m->i[0] < last) {
        m->i[0] += 1;
        m->r[2] = m->r[1] + m->i[0]; /* what the event computed: input plus event number */
    }
    return fmi2OK;
}
