/*
 * stop_pid.c: online law of StopPid, the C twin of controllers/pid/stop_pid.py (seed 000
 * baseline): PID tracking of the stopping curve v_ref(s) = sqrt(2 a0 max(s_stop - s, 0)),
 *
 *   e = v - v_ref,   u = u_ff + kp e + ki int(e) + kd de/dt,   u_ff = a0 / c before s_stop
 *
 * or, with resistance_feedforward, u_ff = (a0 - a_r(v, s)) / c, a_r = the Davis force / mass
 * + the bundled route's grade (resources/routes/<route>.grade, grade.c), as the MPCs.
 *
 * clamped to [u_min, u_max], conditional-integration anti-windup, backward-difference
 * derivative over the sample time, full brake u_max at or past the stop point with
 * hold_at_stop_point. The core's floating-point operations in its order (sqrt is correctly
 * rounded in IEEE 754, so it equals Python's math.sqrt).
 */
#include <math.h>
#include <stdio.h>

#include "grade.h"
#include "law_common.h"
#include "vars.h"
#include "ato_model.h"

typedef struct {
    double integral, prev_error, command;
    int has_prev;
} pid_state;

struct law_core {
    ato_pid_gains pid;
    double ref_decel, stop_point, brake_gain, u_min, u_max;
    int hold_at_stop_point, resistance_feedforward;
    double mass, da, db, dc; /* the known resistance of the feedforward */
    ato_grade grade;
    pid_state st;
};

law_core* law_make(const ato_values* p, double t0, char* err, size_t n) {
    (void)t0;
    const double* v = p->v;
    law_core c;
    memset(&c, 0, sizeof c);
    c.pid = ATO_PID_GAINS(v);
    c.ref_decel = v[ATO_VR_ref_decel];
    c.stop_point = v[ATO_VR_stop_point];
    c.brake_gain = v[ATO_VR_brake_gain];
    c.u_min = v[ATO_VR_u_min];
    c.u_max = v[ATO_VR_u_max];
    c.hold_at_stop_point = v[ATO_VR_hold_at_stop_point] != 0.0;
    c.resistance_feedforward = v[ATO_VR_resistance_feedforward] != 0.0;
    c.mass = v[ATO_VR_mass];
    c.da = v[ATO_VR_davis_a];
    c.db = v[ATO_VR_davis_b];
    c.dc = v[ATO_VR_davis_c];
    /* StopPidParams.check_relations (the declared ranges: controller_backend.c) */
    if (!ato_check_less("u_min", c.u_min, "u_max", c.u_max, err, n)) return NULL;
    if (c.resistance_feedforward &&
        !ato_grade_load(p->resources, p->s[ATO_VR_route], &c.grade, err, n))
        return NULL;
    return ato_law_on_heap(&c, sizeof c);
}

void law_free(law_core* c) {
    if (c->resistance_feedforward) ato_grade_free(&c->grade);
    free(c);
}

/* StopPid.resistance: Davis force / mass + the route's grade (m/s2) */
static double resistance(const law_core* c, double v, double s) {
    v = ato_max(v, 0.0);
    return (c->da + (c->db + c->dc * v) * v) / c->mass + ato_grade_accel(&c->grade, s);
}
ATO_LAW_PLAIN_STATE(st)

int law_compute(law_core* c, double t, const ato_values* p, double* out, char* err, size_t n) {
    (void)t; (void)err; (void)n;
    double v = p->v[ATO_VR_v], s = p->v[ATO_VR_s];
    double v_ref = sqrt(2.0 * c->ref_decel * ato_max(c->stop_point - s, 0.0));
    double error = v - v_ref;
    double u_ff = 0.0;
    if (c->pid.feedforward && s < c->stop_point) {
        double a_r = c->resistance_feedforward ? resistance(c, v, s) : 0.0;
        u_ff = (c->ref_decel - a_r) / c->brake_gain;
    }
    if (c->hold_at_stop_point && (s >= c->stop_point || (v_ref == 0.0 && v <= 0.0)))
        u_ff = c->u_max; /* at or past the stop point: hold the train */
    double derivative =
        c->st.has_prev ? (error - c->st.prev_error) / c->pid.sample_time : 0.0;
    c->st.prev_error = error;
    c->st.has_prev = 1;
    double u = ato_pid_step(&c->st.integral, &c->pid, u_ff, c->pid.kd * derivative, error,
                            c->u_min, c->u_max);
    c->st.command = u;
    out[ATO_VR_brake_command] = u;
    out[ATO_VR_v_ref] = v_ref;
    out[ATO_VR_speed_error] = error;
    return 1;
}

void law_outputs(const law_core* c, double* out) {
    out[ATO_VR_brake_command] = c->st.command;
    out[ATO_VR_v_ref] = 0.0;
    out[ATO_VR_speed_error] = 0.0;
}
