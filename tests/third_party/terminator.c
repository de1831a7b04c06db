/* Ends the simulation itself: the doStep that would pass stop_at advances to stop_at and returns
 * fmi2Discard with fmi2Terminated true and fmi2LastSuccessfulTime = stop_at (FMI 2.0.4 4.2.2). */
#define NR 2 /* stop_at (par), x (out, = time) */
#define NI 1 /* steps (out) */
#define NB 0
#define NS 0
#include "fmi2_common.c"

static void model_defaults(Inst *m) { m->r[0] = 0.75; m->r[1] = 0.0; m->i[0] = 0; }
static void model_outputs(Inst *m) { (void)m; }

static fmi2Status model_step(Inst *m, fmi2Real t, fmi2Real h) {
    m->i[0] += 1;
    if (t + h > m->r[0] + 1e-12) {
        m->time = m->last_successful = m->r[1] = m->r[0];
        m->terminated = fmi2True;
        logf_(m, fmi2OK, "end of simulation reached at t = %g", m->r[0]);
        return fmi2Discard;
    }
    m->r[1] = t + h;
    return fmi2OK;
}
