/*
 * law_common.h: what the online laws behind law.h share (stop_pid.c, speed_pid.c,
 * explicit_mpc.c): their state as one plain struct, the core moved to the heap, the order
 * check of two limits with the core's message, and the conditionally integrating PID step of
 * the controllers/pid cores.
 */
#ifndef ATO_LAW_COMMON_H
#define ATO_LAW_COMMON_H

#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "law.h"
#include "minmax.h"

/* law_state_size, law_get_state and law_set_state of a law whose whole state is the plain
 * struct member `field` of its law_core */
#define ATO_LAW_PLAIN_STATE(field)                                                          \
    size_t law_state_size(const law_core* c) { (void)c; return sizeof c->field; }          \
    void law_get_state(const law_core* c, void* out) {                                      \
        memcpy(out, &c->field, sizeof c->field);                                            \
    }                                                                                       \
    void law_set_state(law_core* c, const void* in) { memcpy(&c->field, in, sizeof c->field); }

/* a heap copy of the core built in *c (law_make's result) */
static inline law_core* ato_law_on_heap(const law_core* c, size_t size) {
    law_core* out = malloc(size);
    memcpy(out, c, size);
    return out;
}

/* the relation lo < hi of two parameters (the Params.check_relations of the core); 0 after
 * writing "<lo_name> = <lo> must be < <hi_name> = <hi>" (values as Python's repr) into err */
static inline int ato_check_less(const char* lo_name, double lo, const char* hi_name,
                                 double hi, char* err, size_t n) {
    if (lo < hi) return 1;
    char a[40], b[40];
    snprintf(err, n, "%s = %s must be < %s = %s", lo_name, ato_repr(lo, a), hi_name,
             ato_repr(hi, b));
    return 0;
}

/* the gains, sample time (s) and feedforward switch of a controllers/pid core */
typedef struct { double kp, ki, kd, sample_time; int feedforward; } ato_pid_gains;

/* the ato_pid_gains of the parameter values v of a law whose generated header declares kp,
 * ki, kd, sample_time and feedforward */
#define ATO_PID_GAINS(v)                                                                    \
    ((ato_pid_gains){(v)[ATO_VR_kp], (v)[ATO_VR_ki], (v)[ATO_VR_kd], (v)[ATO_VR_sample_time], \
                     (v)[ATO_VR_feedforward] != 0.0})

/* One step of the PID with conditional-integration anti-windup of controllers/pid: the
 * unclamped command ff + kp e + ki (I + e T) + d (d: the derivative term with its sign, added
 * last), clamped to [lo, hi]; the integral *I advances to I + e T unless the command is past
 * hi with e > 0 or past lo with e < 0. Returns the clamped command. */
static inline double ato_pid_step(double* integral, const ato_pid_gains* g, double ff,
                                  double d, double error, double lo, double hi) {
    double trial = *integral + error * g->sample_time;
    double unclamped = ff + g->kp * error + g->ki * trial + d;
    double u = ato_min(ato_max(unclamped, lo), hi);
    int pushing_out = (unclamped > hi && error > 0) || (unclamped < lo && error < 0);
    if (!pushing_out) *integral = trial;
    return u;
}

/* controllers/pid's SpeedPid (speed_pid.c, freight_pid.c): its parameters and its state (the
 * state's layout is part of the laws' FMU state) */
typedef struct {
    ato_pid_gains pid;
    double derivative_filter, accel_min, accel_max, rate_limit;
} ato_speed_pid;
typedef struct {
    double integral, prev_speed, derivative, demand, error;
    int has_prev;
} ato_speed_pid_state;

/* SpeedPid.update: the demand within [accel_min, accel_max], [a_lo, a_hi] and the rate limit
 * (inconsistent limits: the upper one wins), from the feedforward ff, PID on e = v_ref - v with
 * the derivative on the measured speed (first-order filter) and conditional integration */
static inline double ato_speed_pid_update(const ato_speed_pid* c, ato_speed_pid_state* st,
                                          double v, double v_ref, double ff, double a_lo,
                                          double a_hi) {
    double T = c->pid.sample_time;
    double lo = ato_max(c->accel_min, a_lo);
    double hi = ato_min(c->accel_max, a_hi);
    lo = ato_min(lo, hi); /* inconsistent limits: the upper one wins */
    if (c->rate_limit > 0) {
        double step = c->rate_limit * T;
        double lo2 = ato_min(ato_max(lo, st->demand - step), hi);
        double hi2 = ato_max(ato_min(hi, st->demand + step), lo);
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
    /* - kd D added as + (-(kd D)): the same double */
    double demand = ato_pid_step(&st->integral, &c->pid, ff, -(c->pid.kd * st->derivative),
                                 error, lo, hi);
    st->demand = demand;
    st->error = error;
    return demand;
}

#endif
