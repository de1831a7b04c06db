/*
 * freight_pid.c: online law of FreightPid, the C twin of controllers/pid/freight_pid.py
 * (SpeedPid on the fed-back speed of the shared base, freight_tracker.c):
 *
 *   a_dem = a_ref(s + max(v, 0) t_p) + a_res + kp e + ki int(e) dt - kd dv_f/dt,  e = v_ref - v_f
 *
 * within the blending's limits and [accel_min, accel_max], jerk limit, conditional
 * integration; the core's floating-point operations in its order.
 */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "law_common.h"
#include "freight_tracker.h"
#include "ato_model.h"

typedef struct {
    ft_state base;
    ato_speed_pid_state pid; /* SpeedPid */
} pid_state;

struct law_core {
    ato_speed_pid pid;
    int resistance_feedforward;
    double preview_time;
    ft_const base;
    pid_state st;
};

law_core* law_make(const ato_values* p, double t0, char* err, size_t n) {
    (void)t0;
    const double* v = p->v;
    law_core* c = ft_new(sizeof *c, err, n);
    if (!c) return NULL;
    c->pid.pid = ATO_PID_GAINS(v);
    c->pid.derivative_filter = v[ATO_VR_derivative_filter];
    c->pid.accel_min = v[ATO_VR_accel_min];
    c->pid.accel_max = v[ATO_VR_accel_max];
    c->pid.rate_limit = v[ATO_VR_rate_limit];
    c->resistance_feedforward = v[ATO_VR_resistance_feedforward] != 0.0;
    c->preview_time = v[ATO_VR_preview_time];
    if (!ato_check_less("accel_min", c->pid.accel_min, "accel_max", c->pid.accel_max, err,
                        n)) {
        free(c); /* SpeedPidParams.check_relations */
        return NULL;
    }
    if (!ft_start(&c->base, &c->st.base, p, err, n)) {
        free(c);
        return NULL;
    }
    return c;
}

FT_LAW_PLAIN(st)

/* SpeedPid.update */
static double update(law_core* c, double v, double v_ref, double a_ref, double a_res,
                     double a_lo, double a_hi) {
    double ff = (c->pid.pid.feedforward ? a_ref : 0.0) + a_res;
    return ato_speed_pid_update(&c->pid, &c->st.pid, v, v_ref, ff, a_lo, a_hi);
}

static double accel_demand(void* law, ft_state* b, double t, double v, double s, double a_res,
                           double lo, double hi) {
    (void)t;
    law_core* c = law;
    b->a_ref = ft_reference_feedforward(&c->base, v, s, c->preview_time);
    return update(c, b->v_feedback, b->v_ref, b->a_ref,
                  c->resistance_feedforward ? a_res : 0.0, lo, hi);
}

FT_LAW_COMPUTE(accel_demand)
