/* Every FMI 2.0 type: parameters, inputs and outputs of type Real, Integer, Boolean, String
 * and Enumeration (through the Integer functions). No direct feedthrough: doStep computes the
 * outputs from the inputs it was given and the end time of the step. */
#define NR 3 /* gain (par), u (in), y (out) */
#define NI 6 /* offset (par), ui (in), yi (out), mode (in, Enumeration), next_mode (out, Enum.),
              level (par, Enumeration) */
#define NB 3 /* invert (par), ub (in), yb (out) */
#define NS 3 /* label (par), us (in), ys (out) */
#include "fmi2_common.c"

static void model_defaults(Inst *m) {
    m->r[0] = 2.0; m->r[1] = 0.5; m->r[2] = 0.0;
    m->i[0] = 10; m->i[1] = 1; m->i[2] = 0; m->i[3] = 1; m->i[4] = 1; m->i[5] = 1;
    m->b[0] = fmi2False; m->b[1] = fmi2False; m->b[2] = fmi2False;
    snprintf(m->s[0], 64, "tag"); snprintf(m->s[1], 64, "in"); m->s[2][0] = 0;
}

static void model_outputs(Inst *m) { (void)m; }

static fmi2Status model_step(Inst *m, fmi2Real t, fmi2Real h) {
    m->r[2] = m->r[0] * m->r[1] + (t + h);
    m->i[2] = m->i[0] + m->i[1] + (fmi2Integer)floor((t + h) * 4.0 + 1e-9) + 100 * (m->i[5] - 1);
    m->i[4] = m->i[3] % 3 + 1; /* Mode items 1, 2, 3: the next one */
    m->b[2] = m->b[0] ? !m->b[1] : m->b[1];
    snprintf(m->s[2], 64, "%.20s:%.20s", m->s[0], m->s[1]);
    return fmi2OK;
}
