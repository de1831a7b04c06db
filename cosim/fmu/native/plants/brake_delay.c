/*
 * brake_delay.c: native model of BrakeDelayTrain, the C twin of plants/brake_delay.py
 * (seed 000, eqs. 1-7): first-order brake lag plus exact dead time, single-mass train.
 *
 *   da_c/dt = -a_c / tau + (1 / tau) a_t(t - Td),   a_t = -c u
 *   dv/dt   = a_c - a_r(v, s) - a_d(t),   ds/dt = v,
 *   a_r = (a + (b + c v) v) / m + g_scale g i(s) / 1000
 *
 * a_d, the unknown resistance, is held over each communication step from its start: uniform in
 * [-A, A], numpy's default_rng([disturbance_seed, k]).uniform(-A, A) of the interval k holding
 * the step's start (numpy_random.c), as BrakeDelayTrain.disturbance_at.
 *
 * The same floating-point operations in the same order as the Python core (sub-steps on the
 * absolute integer-nanosecond grid of max_step, split where the delayed command changes; exact
 * ZOH lag; RK4 for v and s; grade changes and the stopping instant located by the same Newton
 * iterations), so with the same libm exp the results are equal bit for bit.
 *
 * The FMI side (variables, ranges, calling sequence, FMU state) is the generic plant backend
 * plant_backend.c; this file defines ATO_MODEL. The route parameter names a bundled route
 * whose step profiles the build exported to resources/routes/<name>.profiles (plant_common.c).
 */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "ato_model_decl.h"
#include "numpy_random.h"
#include "plant_common.h"

#define BEFORE_START (-(1LL << 62))

typedef struct { int64_t tick; double value; } cmd;

typedef struct {
    /* parameters, fixed while the core lives */
    double mass, da, db, dc, gain, tau, grade_scale;
    double amplitude, interval; /* the disturbance a_d: bound (m/s2), holding time (s) */
    uint64_t seed;
    int64_t delay_ticks, grid_ticks;
    ato_route route;
    /* state (BrakeDelayTrain.state_fields) */
    int64_t t_ticks;
    double a_c, v, s;
    int n_hist, cap_hist;
    cmd* hist;
    double a_d;               /* the disturbance over the current communication step (m/s2) */
    int64_t draw_index;       /* the interval whose a_d draw_value is (-1: none yet) */
    double draw_value;
} bd;

/* -- route -------------------------------------------------------------------------------- */
static double grade_at(const bd* c, double s) { return ato_profile_at(&c->route.grade, s); }
static double grade_accel(const bd* c, double s) {
    return c->grade_scale * (ATO_GRAVITY * grade_at(c, s) / 1000.0);
}
static double next_grade_change(const bd* c) {
    int i = ato_profile_index(&c->route.grade, c->s) + 1; /* bisect_right(starts, s) */
    return i < c->route.grade.n ? c->route.grade.starts[i] : INFINITY;
}

/* a_d of the interval holding t (s): BrakeDelayTrain.disturbance_at */
static double disturbance_at(bd* c, double t) {
    if (c->amplitude == 0.0) return 0.0;
    int64_t k = (int64_t)floor(t / c->interval + 1e-9);
    if (c->draw_index != k) {
        uint64_t ints[2] = {c->seed, (uint64_t)k};
        ato_pcg64 g;
        ato_pcg64_seed(&g, ints, 2);
        /* Generator.uniform(low, high): low + (high - low) * next_double */
        c->draw_value = -c->amplitude + (c->amplitude - -c->amplitude) * ato_pcg64_double(&g);
        c->draw_index = k;
    }
    return c->draw_value;
}

/* -- dead time ---------------------------------------------------------------------------- */
static void record(bd* c, int64_t tick, double value) {
    if (value != c->hist[c->n_hist - 1].value) {
        if (c->n_hist == c->cap_hist) {
            c->cap_hist *= 2;
            c->hist = realloc(c->hist, c->cap_hist * sizeof(cmd));
        }
        c->hist[c->n_hist].tick = tick;
        c->hist[c->n_hist].value = value;
        c->n_hist++;
    }
}
static double delayed(const bd* c, int64_t tick) {
    int64_t target = tick - c->delay_ticks;
    double value = c->hist[0].value;
    for (int i = 0; i < c->n_hist; i++) {
        if (c->hist[i].tick > target) break;
        value = c->hist[i].value;
    }
    return value;
}
static void prune(bd* c, int64_t tick) {
    int64_t target = tick - c->delay_ticks;
    int drop = 0;
    while (c->n_hist - drop > 1 && c->hist[drop + 1].tick <= target) drop++;
    if (drop) {
        memmove(c->hist, c->hist + drop, (c->n_hist - drop) * sizeof(cmd));
        c->n_hist -= drop;
    }
}

/* -- physics ---------------------------------------------------------------------------- */
static double accel(const bd* c, double a_c, double v, double g) {
    double a = a_c - ato_davis(c->da, c->db, c->dc, ato_max(v, 0.0)) / c->mass - g;
    if (v <= 0.0 && a <= 0.0) return 0.0;
    return a;
}
static double lag(const bd* c, double a_c0, double a_t, double dt) {
    return a_t + (a_c0 - a_t) * exp(-dt / c->tau);
}
static void rk4(const bd* c, double a_t, double g, double h, double* v_out, double* s_out) {
    double a_c0 = c->a_c, v = c->v, s = c->s;
    double a_mid = lag(c, a_c0, a_t, 0.5 * h);
    double a_end = lag(c, a_c0, a_t, h);
    double k1v = accel(c, a_c0, v, g);
    double k2v = accel(c, a_mid, v + 0.5 * h * k1v, g);
    double k3v = accel(c, a_mid, v + 0.5 * h * k2v, g);
    double k4v = accel(c, a_end, v + h * k3v, g);
    double k1s = v, k2s = v + 0.5 * h * k1v, k3s = v + 0.5 * h * k2v, k4s = v + h * k3v;
    *v_out = v + h / 6.0 * (k1v + 2 * k2v + 2 * k3v + k4v);
    *s_out = s + h / 6.0 * (k1s + 2 * k2s + 2 * k3s + k4s);
}
static void substep(bd* c, double h, double a_t) {
    double remaining = h;
    while (remaining > 0.0) {
        double g = grade_accel(c, c->s) + c->a_d;
        double boundary = next_grade_change(c);
        double dt = remaining, v1, s1, unused;
        rk4(c, a_t, g, dt, &v1, &s1);
        if (s1 > boundary && c->v >= 0.0) {
            dt = remaining * (boundary - c->s) / (s1 - c->s);
            for (int i = 0; i < 4; i++) {
                rk4(c, a_t, g, dt, &v1, &s1);
                dt = ato_min(ato_max(dt - (s1 - boundary) / ato_max(v1, 1e-9), 0.0), remaining);
            }
            rk4(c, a_t, g, dt, &v1, &unused);
            s1 = boundary;
        }
        if (v1 < 0.0) {
            dt = dt * c->v / (c->v - v1);
            for (int i = 0; i < 4; i++) {
                rk4(c, a_t, g, dt, &v1, &s1);
                double a1 = accel(c, lag(c, c->a_c, a_t, dt), ato_max(v1, 1e-12), g);
                if (a1 >= 0.0) break;
                dt = ato_min(ato_max(dt - v1 / a1, 0.0), remaining);
            }
            rk4(c, a_t, g, dt, &unused, &s1);
            v1 = 0.0;
            if (dt <= 0.0) dt = remaining;
        }
        c->a_c = lag(c, c->a_c, a_t, dt);
        c->v = v1;
        c->s = s1;
        remaining -= dt;
    }
}

static int step(ato_inst* m, void* core, int64_t t, int64_t h) {
    bd* c = core;
    if (t != c->t_ticks) {
        ATO_ERROR(m, "doStep at t=%.17g s but plant is at t=%.17g s", ato_to_seconds(t),
                  ato_to_seconds(c->t_ticks));
        return 0;
    }
    record(c, t, m->r[ATO_VR_brake_command]);
    c->a_d = disturbance_at(c, ato_to_seconds(t));
    int64_t* acts = malloc((size_t)c->n_hist * sizeof(int64_t)); /* a delayed command acts */
    for (int i = 0; i < c->n_hist; i++) acts[i] = c->hist[i].tick + c->delay_ticks;
    int64_t* cuts;
    size_t n = ato_substep_ends_acting(t, h, &c->grid_ticks, 1, acts, (size_t)c->n_hist, &cuts);
    free(acts);
    int64_t now = t;
    for (size_t i = 0; i < n; i++) {
        double a_t = -c->gain * delayed(c, now);
        substep(c, ato_to_seconds(cuts[i] - now), a_t);
        now = cuts[i];
    }
    free(cuts);
    c->t_ticks = now;
    prune(c, now);
    return 1;
}

static void destroy(void* core) {
    bd* c = core;
    ato_route_free(&c->route);
    free(c->hist);
    free(c);
}

/* BrakeDelayTrain.__init__ with BrakeDelayParams.check: messages name the parameter */
static void* create(ato_inst* m) {
    const double* r = m->r;
    const struct { const char* name; int vr; } positive[] = {
        {"mass", ATO_VR_mass}, {"brake_time_constant", ATO_VR_brake_time_constant},
        {"max_step", ATO_VR_max_step}, {"brake_gain", ATO_VR_brake_gain}};
    for (size_t i = 0; i < sizeof positive / sizeof positive[0]; i++)
        if (!(r[positive[i].vr] > 0)) {
            ATO_ERROR(m, "bad parameter: %s = %.17g must be > 0", positive[i].name,
                      r[positive[i].vr]);
            return NULL;
        }
    if (!(r[ATO_VR_brake_delay] >= 0)) {
        ATO_ERROR(m, "bad parameter: brake_delay = %.17g must be >= 0", r[ATO_VR_brake_delay]);
        return NULL;
    }
    if (!(r[ATO_VR_disturbance_amplitude] >= 0)) {
        ATO_ERROR(m, "bad parameter: disturbance_amplitude = %.17g must be >= 0",
                  r[ATO_VR_disturbance_amplitude]);
        return NULL;
    }
    if (!(r[ATO_VR_disturbance_interval] > 0)) {
        ATO_ERROR(m, "bad parameter: disturbance_interval = %.17g must be > 0",
                  r[ATO_VR_disturbance_interval]);
        return NULL;
    }
    if (r[ATO_VR_disturbance_seed] < 0) {
        ATO_ERROR(m, "bad parameter: disturbance_seed = %.17g must be >= 0 (numpy "
                  "SeedSequence)", r[ATO_VR_disturbance_seed]);
        return NULL;
    }
    if (r[ATO_VR_v0] < 0) {
        ATO_ERROR(m, "bad parameter: v0 = %.17g must be >= 0", r[ATO_VR_v0]);
        return NULL;
    }
    bd* c = calloc(1, sizeof(bd));
    if (!ato_route_load(m, m->str[ATO_VR_route], &c->route)) {
        free(c);
        return NULL;
    }
    c->mass = r[ATO_VR_mass];
    c->da = r[ATO_VR_davis_a];
    c->db = r[ATO_VR_davis_b];
    c->dc = r[ATO_VR_davis_c];
    c->gain = r[ATO_VR_brake_gain];
    c->tau = r[ATO_VR_brake_time_constant];
    c->grade_scale = r[ATO_VR_grade_scale];
    c->amplitude = r[ATO_VR_disturbance_amplitude];
    c->interval = r[ATO_VR_disturbance_interval];
    c->seed = (uint64_t)r[ATO_VR_disturbance_seed];
    c->draw_index = -1;
    c->delay_ticks = ato_to_ticks(r[ATO_VR_brake_delay]);
    c->grid_ticks = ato_to_ticks(r[ATO_VR_max_step]);
    c->t_ticks = m->start_ticks;
    c->v = r[ATO_VR_v0];
    c->s = r[ATO_VR_s0];
    c->a_c = -c->gain * r[ATO_VR_initial_command];
    c->cap_hist = 8;
    c->n_hist = 1;
    c->hist = malloc(c->cap_hist * sizeof(cmd));
    c->hist[0].tick = BEFORE_START;
    c->hist[0].value = r[ATO_VR_initial_command];
    return c;
}

static void outputs(ato_inst* m, void* core) {
    const bd* c = core;
    double* r = m->r;
    r[ATO_VR_v] = c->v;
    r[ATO_VR_s] = c->s;
    r[ATO_VR_a] = accel(c, c->a_c, c->v, grade_accel(c, c->s) + c->a_d);
    r[ATO_VR_a_c] = c->a_c;
    r[ATO_VR_applied_command] = delayed(c, c->t_ticks);
    r[ATO_VR_grade] = c->grade_scale * grade_at(c, c->s);
}

static void save(const void* core, ato_buf* b) {
    const bd* c = core;
    ato_put(b, &c->t_ticks, sizeof c->t_ticks);
    ato_put(b, &c->a_c, sizeof c->a_c);
    ato_put(b, &c->v, sizeof c->v);
    ato_put(b, &c->s, sizeof c->s);
    ato_put(b, &c->a_d, sizeof c->a_d);
    int32_t nh = c->n_hist;
    ato_put(b, &nh, sizeof nh);
    ato_put(b, c->hist, (size_t)nh * sizeof(cmd));
}

static int load(void* core, ato_rd* r) {
    bd* c = core;
    int32_t nh = 0;
    ato_take(r, &c->t_ticks, sizeof c->t_ticks);
    ato_take(r, &c->a_c, sizeof c->a_c);
    ato_take(r, &c->v, sizeof c->v);
    ato_take(r, &c->s, sizeof c->s);
    ato_take(r, &c->a_d, sizeof c->a_d);
    ato_take(r, &nh, sizeof nh);
    if (!r->ok || nh < 1 || (size_t)nh * sizeof(cmd) > r->n - r->at) return 0;
    c->cap_hist = nh;
    c->hist = realloc(c->hist, (size_t)nh * sizeof(cmd));
    c->n_hist = nh;
    ato_take(r, c->hist, (size_t)nh * sizeof(cmd));
    return r->ok;
}

const ato_model ATO_MODEL = {
    {ATO_MODEL_IDENTIFIER, ATO_GUID, "ATO-" ATO_MODEL_IDENTIFIER "-state-2", ATO_N_VARS,
     ATO_VARS},
    create, destroy, step, outputs, save, load,
};
