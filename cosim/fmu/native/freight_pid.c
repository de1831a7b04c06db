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

#include "ato_law_common.h"
#include "freight_tracker.h"
#include "ato_model.h"

typedef struct {
    ft_state base;
    double integral, prev_speed, derivative, demand, error; /* SpeedPid */
    int has_prev;
} pid_state;

struct law_core {
    double kp, ki, kd, derivative_filter, accel_min, accel_max, rate_limit, sample_time;
    int feedforward, resistance_feedforward;
    double preview_time;
    ft_const base;
    pid_state st;
};

law_core* law_make(const ato_values* p, double t0, char* err, size_t n) {
    (void)t0;
    const double* v = p->v;
    law_core* c = calloc(1, sizeof *c);
    if (!c) {
        snprintf(err, n, "out of memory");
        return NULL;
    }
    c->kp = v[ATO_VR_kp];
    c->ki = v[ATO_VR_ki];
    c->kd = v[ATO_VR_kd];
    c->derivative_filter = v[ATO_VR_derivative_filter];
    c->accel_min = v[ATO_VR_accel_min];
    c->accel_max = v[ATO_VR_accel_max];
    c->rate_limit = v[ATO_VR_rate_limit];
    c->feedforward = v[ATO_VR_feedforward] != 0.0;
    c->sample_time = v[ATO_VR_sample_time];
    c->resistance_feedforward = v[ATO_VR_resistance_feedforward] != 0.0;
    c->preview_time = v[ATO_VR_preview_time];
    if (!ato_check_less("accel_min", c->accel_min, "accel_max", c->accel_max, err, n)) {
        free(c); /* SpeedPidParams.check_relations */
        return NULL;
    }
    if (!ft_make(&c->base, p, err, n)) {
        ft_free(&c->base);
        free(c);
        return NULL;
    }
    ft_reset(&c->st.base);
    return c;
}

void law_free(law_core* c) {
    ft_free(&c->base);
    free(c);
}
ATO_LAW_PLAIN_STATE(st)

/* SpeedPid.update */
static double update(law_core* c, double v, double v_ref, double a_ref, double a_res,
                     double a_lo, double a_hi) {
    pid_state* st = &c->st;
    double T = c->sample_time;
    double lo = ft_max(c->accel_min, a_lo);
    double hi = ft_min(c->accel_max, a_hi);
    lo = ft_min(lo, hi); /* inconsistent limits: the upper one wins */
    if (c->rate_limit > 0) {
        double step = c->rate_limit * T;
        double lo2 = ft_min(ft_max(lo, st->demand - step), hi);
        double hi2 = ft_max(ft_min(hi, st->demand + step), lo);
        lo = lo2;
        hi = hi2;
    }
    double error = v_ref - v;
    if (st->has_prev) {
        double raw = (v - st->prev_speed) / T;
        if (c->derivative_filter > 0) {
            double alpha = T / (c->derivative_filter + T);
            st->derivative += alpha * (raw - st->derivative);
        } else {
            st->derivative = raw;
        }
    }
    st->prev_speed = v;
    st->has_prev = 1;
    double integral = st->integral + error * T;
    double ff = (c->feedforward ? a_ref : 0.0) + a_res;
    double unclamped = ff + c->kp * error + c->ki * integral - c->kd * st->derivative;
    double demand = ft_min(ft_max(unclamped, lo), hi);
    int pushing_out = (unclamped > hi && error > 0) || (unclamped < lo && error < 0);
    if (!pushing_out) st->integral = integral;
    st->demand = demand;
    st->error = error;
    return demand;
}

static double accel_demand(void* law, ft_state* b, double t, double v, double s, double a_res,
                           double lo, double hi) {
    (void)t;
    law_core* c = law;
    b->a_ref = ft_reference_feedforward(&c->base, v, s, c->preview_time);
    return update(c, b->v_feedback, b->v_ref, b->a_ref,
                  c->resistance_feedforward ? a_res : 0.0, lo, hi);
}

void law_outputs(const law_core* c, double* out) { ft_outputs(&c->st.base, out); }

int law_compute(law_core* c, double t, const ato_values* p, double* out, char* err, size_t n) {
    if (!ft_compute(&c->base, &c->st.base, t, p->v[ATO_VR_v], p->v[ATO_VR_s], accel_demand, c,
                    err, n))
        return 0;
    law_outputs(c, out);
    return 1;
}
