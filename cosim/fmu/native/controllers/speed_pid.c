/*
 * speed_pid.c: online law of EmuSpeedPid3 / EmuSpeedPid8, the C twin of
 * controllers/pid/speed_pid.py (DistributedSpeedPid over SpeedPid; seeds 001, 004):
 *
 *   e = v_ref - v,   a_dem = a_ref + kp e + ki int(e) dt - kd dv_f/dt,   F = M a_dem
 *
 * clamped to the summed envelope over M (and [accel_min, accel_max], rate limit), conditional
 * integration, derivative on the measured speed (first-order filter); F shared over the units
 * in proportion to the force each can give now; the holding brake at the final stop. The
 * core's floating-point operations in its order. Units: ATO_OPTION_units of the generated
 * header; the reference profile: a bundled name (resources/references).
 */
#include <math.h>
#include <stdio.h>

#include "law_common.h"
#include "profile.h"
#include "vars.h"
#include "ato_model.h"

#define UNITS ATO_OPTION_units

typedef struct {
    ato_speed_pid_state pid; /* SpeedPid */
    double forces[UNITS], v_ref, a_ref;
} pid_state;

struct law_core {
    ato_speed_pid pid;
    double mass, hold_accel, stop_speed;
    ato_profile profile;
    pid_state st;
};

law_core* law_make(const ato_values* p, double t0, char* err, size_t n) {
    (void)t0;
    const double* v = p->v;
    law_core c;
    memset(&c, 0, sizeof c);
    c.pid.pid = ATO_PID_GAINS(v);
    c.pid.derivative_filter = v[ATO_VR_derivative_filter];
    c.pid.accel_min = v[ATO_VR_accel_min];
    c.pid.accel_max = v[ATO_VR_accel_max];
    c.pid.rate_limit = v[ATO_VR_rate_limit];
    c.mass = v[ATO_VR_mass];
    c.hold_accel = v[ATO_VR_hold_accel];
    c.stop_speed = v[ATO_VR_stop_speed];
    /* DistributedSpeedPidParams.check_relations (the declared ranges: controller_backend.c) */
    if (!ato_check_less("accel_min", c.pid.accel_min, "accel_max", c.pid.accel_max, err, n))
        return NULL;
    if (!ato_profile_load(&c.profile, p->resources, p->s[ATO_VR_reference], err, n))
        return NULL;
    return ato_law_on_heap(&c, sizeof c);
}

void law_free(law_core* c) {
    ato_profile_free(&c->profile);
    free(c);
}
ATO_LAW_PLAIN_STATE(st)

/* SpeedPid.update with a_res = 0 and the limits a_lo, a_hi */
static double update(law_core* c, double v, double v_ref, double a_ref, double a_lo,
                     double a_hi) {
    double ff = (c->pid.pid.feedforward ? a_ref : 0.0) + 0.0;
    return ato_speed_pid_update(&c->pid, &c->st.pid, v, v_ref, ff, a_lo, a_hi);
}

void law_outputs(const law_core* c, double* out) {
    const pid_state* st = &c->st;
    for (int i = 0; i < UNITS; i++) out[ATO_VR_force_1 + i] = st->forces[i];
    out[ATO_VR_force_demand] = c->mass * st->pid.demand;
    out[ATO_VR_accel_demand] = st->pid.demand;
    out[ATO_VR_v_ref] = st->v_ref;
    out[ATO_VR_a_ref] = st->a_ref;
    out[ATO_VR_speed_error] = -st->pid.error;
}

int law_compute(law_core* c, double t, const ato_values* p, double* out, char* err, size_t n) {
    (void)err; (void)n;
    pid_state* st = &c->st;
    const double* in = p->v;
    double x = c->profile.distance ? in[ATO_VR_s] : t;
    double v_ref = st->v_ref = ato_profile_speed(&c->profile, x);
    double a_ref = st->a_ref = ato_profile_accel(&c->profile, x);
    double v = in[ATO_VR_v];
    double trac[UNITS], brake[UNITS], total_trac = 0.0, total_brake = 0.0;
    for (int i = 0; i < UNITS; i++) {
        trac[i] = ato_max(in[ATO_VR_traction_limit_1 + i], 0.0);
        brake[i] = ato_max(in[ATO_VR_brake_limit_1 + i], 0.0);
    }
    for (int i = 0; i < UNITS; i++) total_trac += trac[i];
    for (int i = 0; i < UNITS; i++) total_brake += brake[i];
    double demand = update(c, v, v_ref, a_ref, -total_brake / c->mass, total_trac / c->mass);
    if (v_ref <= 0.0 && a_ref <= 0.0 && v < c->stop_speed) {
        demand = ato_max(c->hold_accel, -total_brake / c->mass); /* hold at the stop */
        st->pid.demand = demand;
    }
    double force = c->mass * demand;
    const double* share;
    double total;
    static const double none[UNITS];
    if (force >= 0.0) {
        share = total_trac > 0 ? trac : none;
        total = total_trac;
    } else {
        share = brake;
        total = total_brake;
    }
    for (int i = 0; i < UNITS; i++) st->forces[i] = total > 0 ? force * share[i] / total : 0.0;
    law_outputs(c, out);
    return 1;
}
