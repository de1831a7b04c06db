/*
 * crh3.c: native model of Crh3Train, the C twin of plants/crh3.py (seed 003, eqs. 1-9):
 * single-mass CRH3 with a first-order traction/brake lag, the traction and brake envelopes
 * and the energy account of eq. 9.
 *
 *   M (1 + gamma) dv/dt = F - W0(v) - M g (w_r + w_s + w_g) / 1000,   ds/dt = v
 *   F: the demand clipped to (-F_b, F_t), lagged (tau_t while the target is >= 0, else
 *      tau_b) and clipped to the envelope min(F_t, P_t / v) (none above max_speed) /
 *      min(F_b, P_b / v) at the present speed
 *   energy_traction = int(max(F, 0) v dt) / eta_M, energy_regen = eta_b int(max(-F, 0) v dt),
 *   energy_aux = e0 (t - t0), energy_net = traction - regen + aux, brake_work = int(max(-F, 0) v dt)
 *
 * The same floating-point operations in the same order as the Python core: sub-steps on the
 * absolute integer-nanosecond grid of max_step (ato_substep_ends), the lag solved exactly,
 * RK4 for v, s and the work integrals, the stopping instant by the same Newton iterations,
 * the same start-from-rest test; grade and curve + tunnel resistance at the train position
 * (point mass) or averaged over `length`. With the same libm exp the outputs are equal bit
 * for bit.
 */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "plant_common.h"
#include "ato_model_decl.h"

typedef struct {
    /* parameters */
    double mass, m_eff, mg, da, db, dc, f_t, p_t, v_max, f_b, p_b, tau_t, tau_b, eta_m,
        eta_b, aux, length;
    int64_t grid, t0;
    ato_route route;
    ato_profile other; /* curve + tunnel resistance (N/kN) */
    ato_cumulative grade_cum, other_cum;
    /* state (Crh3Train.state_fields) */
    int64_t t;
    double v, s, force, command;
    int32_t held;
    double w_traction, w_brake, w_resistance, w_grade;
} crh3;

static double rest(double x) { return x > 0.0 ? x : 0.0; }

static double grade_of(const crh3* c, double s) {
    return c->length > 0.0 ? ato_mean_over(&c->grade_cum, s, c->length)
                           : ato_profile_at(&c->route.grade, s);
}
static double other_of(const crh3* c, double s) {
    return c->length > 0.0 ? ato_mean_over(&c->other_cum, s, c->length)
                           : ato_profile_at(&c->other, s);
}

static double traction_limit(const crh3* c, double v) {
    if (fabs(v) > c->v_max) return 0.0;
    return ato_envelope(c->f_t, c->p_t, v);
}
static double brake_limit(const crh3* c, double v) { return ato_envelope(c->f_b, c->p_b, v); }

static double envelope(const crh3* c, double force, double v) {
    if (force >= 0.0) return ato_min(force, traction_limit(c, v));
    return ato_max(force, -brake_limit(c, v));
}

/* (dv/dt, ds/dt, traction, brake, resistance and grade power) */
static void rates(const crh3* c, double force, double v, double s, double k[6]) {
    double vp = rest(v);
    double applied = envelope(c, force, vp);
    double grade = c->mg * grade_of(c, s);
    double other = c->mg * other_of(c, s);
    double resist = ato_davis(c->da, c->db, c->dc, vp) + other;
    double acc = (applied - resist - grade) / c->m_eff;
    if (v <= 0.0 && acc < 0.0) acc = 0.0;
    k[0] = acc;
    k[1] = vp;
    k[2] = rest(applied) * vp;
    k[3] = rest(-applied) * vp;
    k[4] = resist * vp;
    k[5] = grade * vp;
}

static double lagged(const crh3* c, double target, double dt) {
    double tau = target >= 0.0 ? c->tau_t : c->tau_b;
    return target + (c->force - target) * exp(-dt / tau);
}

/* (v, s, dW_t, dW_b, dW_r, dW_g) after h from the present state */
static void rk4(const crh3* c, double target, double h, double out[6]) {
    double v = c->v, s = c->s;
    double f0 = c->force, fm = lagged(c, target, 0.5 * h), f1 = lagged(c, target, h);
    double k1[6], k2[6], k3[6], k4[6];
    rates(c, f0, v, s, k1);
    rates(c, fm, v + 0.5 * h * k1[0], s + 0.5 * h * k1[1], k2);
    rates(c, fm, v + 0.5 * h * k2[0], s + 0.5 * h * k2[1], k3);
    rates(c, f1, v + h * k3[0], s + h * k3[1], k4);
    double d[6];
    for (int i = 0; i < 6; i++) d[i] = h / 6.0 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i]);
    out[0] = v + d[0];
    out[1] = s + d[1];
    for (int i = 2; i < 6; i++) out[i] = d[i];
}

static int can_start(const crh3* c, double force) {
    double drive = envelope(c, force, 0.0) - c->mg * (grade_of(c, c->s) + other_of(c, c->s));
    return drive > c->da;
}

static void substep(crh3* c, double h, double target) {
    if (c->held) {
        if (!can_start(c, c->force)) {
            c->force = lagged(c, target, h);
            return;
        }
        c->held = 0;
    }
    double r[6];
    rk4(c, target, h, r);
    if (r[0] < 0.0) { /* stops inside the sub-step: Newton on v(dt) = 0 */
        double s1 = r[1], dt = h * c->v / (c->v - r[0]), k[6];
        for (int i = 0; i < 3; i++) {
            rk4(c, target, dt, r);
            rates(c, lagged(c, target, dt), ato_max(r[0], 1e-12), s1, k);
            double acc = k[0];
            if (acc >= 0.0) break;
            dt = ato_min(ato_max(dt - r[0] / acc, 0.0), h);
        }
        rk4(c, target, dt, r);
        r[0] = 0.0;
        c->held = 1;
    }
    c->v = r[0];
    c->s = r[1];
    c->w_traction += r[2];
    c->w_brake += r[3];
    c->w_resistance += r[4];
    c->w_grade += r[5];
    c->force = lagged(c, target, h); /* the lag runs on through a stop */
}

static int step(ato_inst* m, void* core, int64_t t, int64_t h) {
    crh3* c = core;
    if (t != c->t) {
        ATO_ERROR(m, "doStep at t=%.17g s but plant is at t=%.17g s", ato_to_seconds(t),
                  ato_to_seconds(c->t));
        return 0;
    }
    c->command = m->r[ATO_VR_force];
    double target = ato_min(ato_max(c->command, -c->f_b), c->f_t);
    int64_t* cuts;
    size_t n = ato_substep_ends(t, h, &c->grid, 1, &cuts);
    int64_t now = t;
    for (size_t i = 0; i < n; i++) {
        substep(c, ato_to_seconds(cuts[i] - now), target);
        now = cuts[i];
    }
    free(cuts);
    c->t = now;
    return 1;
}

static void outputs(ato_inst* m, void* core) {
    crh3* c = core;
    double* r = m->r;
    double applied;
    if (c->held && !can_start(c, c->force))
        applied = c->force >= 0.0 ? 0.0 : envelope(c, c->force, 0.0);
    else
        applied = envelope(c, c->force, c->v);
    double k[6];
    double acc = 0.0;
    if (!c->held) {
        rates(c, c->force, c->v, c->s, k);
        acc = k[0];
    }
    double v = c->v;
    double trac = c->w_traction / c->eta_m;
    double regen = c->eta_b * c->w_brake;
    double aux = c->aux * ato_to_seconds(c->t - c->t0);
    r[ATO_VR_v] = v;
    r[ATO_VR_s] = c->s;
    r[ATO_VR_a] = acc;
    r[ATO_VR_applied_force] = applied;
    r[ATO_VR_traction_limit] = traction_limit(c, v);
    r[ATO_VR_brake_limit] = brake_limit(c, v);
    r[ATO_VR_speed_limit] = ato_profile_at(&c->route.speed_limit, c->s);
    r[ATO_VR_grade] = grade_of(c, c->s);
    r[ATO_VR_power] = rest(applied) * v / c->eta_m - c->eta_b * rest(-applied) * v + c->aux;
    r[ATO_VR_energy_traction] = trac;
    r[ATO_VR_energy_regen] = regen;
    r[ATO_VR_energy_aux] = aux;
    r[ATO_VR_energy_net] = trac - regen + aux;
    r[ATO_VR_brake_work] = c->w_brake;
}

static void destroy(void* core) {
    crh3* c = core;
    ato_route_free(&c->route);
    ato_profile_free(&c->other);
    ato_cumulative_free(&c->grade_cum);
    ato_cumulative_free(&c->other_cum);
    free(c);
}

/* Crh3Train.__init__ with Crh3Params.check: messages name the parameter */
static void* create(ato_inst* m) {
    const double* r = m->r;
    const struct { const char* name; int vr; } positive[] = {
        {"mass", ATO_VR_mass}, {"traction_time_constant", ATO_VR_traction_time_constant},
        {"brake_time_constant", ATO_VR_brake_time_constant}, {"max_step", ATO_VR_max_step},
        {"motor_efficiency", ATO_VR_motor_efficiency}};
    for (size_t i = 0; i < sizeof positive / sizeof positive[0]; i++)
        if (!(r[positive[i].vr] > 0)) {
            ATO_ERROR(m, "bad parameter: %s = %.17g must be > 0", positive[i].name,
                      r[positive[i].vr]);
            return NULL;
        }
    const struct { const char* name; int vr; } nonnegative[] = {
        {"rotating_mass_factor", ATO_VR_rotating_mass_factor},
        {"max_traction_force", ATO_VR_max_traction_force},
        {"max_traction_power", ATO_VR_max_traction_power},
        {"max_brake_force", ATO_VR_max_brake_force},
        {"max_brake_power", ATO_VR_max_brake_power}, {"aux_power", ATO_VR_aux_power},
        {"length", ATO_VR_length}, {"regen_efficiency", ATO_VR_regen_efficiency},
        {"max_speed", ATO_VR_max_speed}, {"v0", ATO_VR_v0}};
    for (size_t i = 0; i < sizeof nonnegative / sizeof nonnegative[0]; i++)
        if (!(r[nonnegative[i].vr] >= 0)) {
            ATO_ERROR(m, "bad parameter: %s = %.17g must be >= 0", nonnegative[i].name,
                      r[nonnegative[i].vr]);
            return NULL;
        }
    if (r[ATO_VR_motor_efficiency] > 1 || r[ATO_VR_regen_efficiency] > 1) {
        ATO_ERROR(m, "bad parameter: efficiencies (%.17g, %.17g) must be <= 1",
                  r[ATO_VR_motor_efficiency], r[ATO_VR_regen_efficiency]);
        return NULL;
    }
    crh3* c = calloc(1, sizeof(crh3));
    if (!ato_route_load(m, m->str[ATO_VR_route], &c->route)) {
        free(c);
        return NULL;
    }
    const ato_profile* parts[] = {&c->route.curve_resistance, &c->route.tunnel_resistance};
    ato_profile_sum(parts, 2, &c->other);
    ato_cumulative_of(&c->route.grade, &c->grade_cum);
    ato_cumulative_of(&c->other, &c->other_cum);
    c->mass = r[ATO_VR_mass];
    c->m_eff = c->mass * (1.0 + r[ATO_VR_rotating_mass_factor]);
    c->mg = c->mass * ATO_GRAVITY / 1000.0;
    c->da = r[ATO_VR_davis_a];
    c->db = r[ATO_VR_davis_b];
    c->dc = r[ATO_VR_davis_c];
    c->f_t = r[ATO_VR_max_traction_force];
    c->p_t = r[ATO_VR_max_traction_power];
    c->v_max = r[ATO_VR_max_speed];
    c->f_b = r[ATO_VR_max_brake_force];
    c->p_b = r[ATO_VR_max_brake_power];
    c->tau_t = r[ATO_VR_traction_time_constant];
    c->tau_b = r[ATO_VR_brake_time_constant];
    c->eta_m = r[ATO_VR_motor_efficiency];
    c->eta_b = r[ATO_VR_regen_efficiency];
    c->aux = r[ATO_VR_aux_power];
    c->length = r[ATO_VR_length];
    c->grid = ato_to_ticks(r[ATO_VR_max_step]);
    c->t0 = c->t = m->start_ticks;
    c->v = r[ATO_VR_v0];
    c->s = r[ATO_VR_s0];
    c->held = c->v <= 0.0;
    return c;
}

static void save(const void* core, ato_buf* b) {
    const crh3* c = core;
    ato_put(b, &c->t, sizeof c->t);
    double x[8] = {c->v, c->s, c->force, c->command, c->w_traction, c->w_brake,
                   c->w_resistance, c->w_grade};
    ato_put(b, x, sizeof x);
    ato_put(b, &c->held, sizeof c->held);
}

static int load(void* core, ato_rd* r) {
    crh3* c = core;
    double x[8];
    ato_take(r, &c->t, sizeof c->t);
    ato_take(r, x, sizeof x);
    ato_take(r, &c->held, sizeof c->held);
    if (!r->ok) return 0;
    c->v = x[0];
    c->s = x[1];
    c->force = x[2];
    c->command = x[3];
    c->w_traction = x[4];
    c->w_brake = x[5];
    c->w_resistance = x[6];
    c->w_grade = x[7];
    return 1;
}

const ato_model ATO_MODEL = {
    {ATO_MODEL_IDENTIFIER, ATO_GUID, "ATO-Crh3Train-state-1", ATO_N_VARS, ATO_VARS},
    create, destroy, step, outputs, save, load,
};
