/*
 * crh3_gpc.c: online law of Crh3Gpc, the C twin of controllers/eco/gpc.py Crh3Gpc over
 * controllers/eco/tracking.py EcoTracker (seed-003 GPC baseline): the GPC of gpc.h on
 * y = v (m/s), u (m/s^2), one output and one input, tracking a target profile.
 *
 * The profile (controllers/common/speed_profiles.py) is planned at build time, not here:
 * its searches (the eco rule's bisection, Brent's method for the cruise speed and the fixed
 * family, the optimum's CSV) are a function of parameters only, so the build runs the Python
 * planner and ships its result (positions, speeds, times, step accelerations, the phase
 * boundaries) in resources/eco_profiles/<route>/<profile>.profile (the optimum of profile
 * "pmp": <route>/pmp/<optimum>.profile) with the parameter values it was planned with; a
 * parameter set to another value is refused at instantiation, naming it (the Python FMU
 * plans any). This file samples the profile as SpeedProfile.at_time / at_position /
 * phase_at_time do and forms the references, input box, holding brake and outputs of
 * EcoTracker.compute in its operations and order. The RLS model starts from the identified
 * ARX model at departure (model_start "identified": resources/eco_profiles/identified.arx,
 * the model set's a[0], b[0] and the gravity of the unit change) or from a_init, b_init.
 *
 * State (doubles): EcoTracker.tracker_state (force, u, v_ref, a_ref, s_ref, speed_error,
 * phase, holding 0/1), then Gpc.state_fields (gpc.h).
 */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "bundled.h"
#include "gpc.h"
#include "law_common.h"
#include "linalg.h"
#include "profile.h"
#include "ato_model.h"

#define TRACKER_STATE 8
#define PHASE_RUN 2.0
#define PHASE_BRAKE 3.0

typedef struct {
    int n;
    double *s, *v, *t, *accel;
    double accelerate_end_time, brake_start_position, brake_start_time;
} eco_profile;

struct law_core {
    gpc_core gpc;
    eco_profile prof;
    double t0, m_eff, accel_min, accel_max, limit_speed, position_gain, max_correction;
    double stop_speed, hold_accel, sample_time;
    int count;
    double* st; /* force, u, v_ref, a_ref, s_ref, speed_error, phase, holding, then the GPC's */
};

/* the parameters a profile is planned with (EcoTrackingParams.planning_fields and
 * scheduled_time): a shipped profile is used only when they hold the values it was planned
 * with */
static const struct { const char* name; int vr; } PLANNED[] = {
    {"mass", ATO_VR_mass}, {"rotating_mass_factor", ATO_VR_rotating_mass_factor},
    {"cruise_speed", ATO_VR_cruise_speed}, {"limit_speed", ATO_VR_limit_speed},
    {"accel_max", ATO_VR_accel_max}, {"brake_decel", ATO_VR_brake_decel},
    {"traction_share", ATO_VR_traction_share}, {"scheduled_time", ATO_VR_scheduled_time}};

static void profile_free(eco_profile* p) {
    free(p->s); free(p->v); free(p->t); free(p->accel);
    memset(p, 0, sizeof *p);
}

/* "<key> <value>" lines, then "points <n>" and n lines "s v t accel"; 0 after a message */
static int profile_read(eco_profile* p, FILE* f, const char* what, const double* v, char* err,
                        size_t n) {
    char line[512], key[64];
    double value;
    memset(p, 0, sizeof *p);
    int k = -1;
    while (fgets(line, sizeof line, f)) {
        if (line[0] == '#') continue;
        if (k >= 0) {
            if (k == p->n) break;
            if (sscanf(line, "%lf %lf %lf %lf", &p->s[k], &p->v[k], &p->t[k], &p->accel[k]) != 4)
                break;
            k++;
            continue;
        }
        if (sscanf(line, "%63s %lf", key, &value) != 2) continue;
        if (strcmp(key, "points") == 0) {
            p->n = (int)value;
            p->s = malloc(sizeof(double) * (p->n > 0 ? p->n : 1));
            p->v = malloc(sizeof(double) * (p->n > 0 ? p->n : 1));
            p->t = malloc(sizeof(double) * (p->n > 0 ? p->n : 1));
            p->accel = malloc(sizeof(double) * (p->n > 0 ? p->n : 1));
            k = 0;
        } else if (strcmp(key, "accelerate_end_time") == 0) {
            p->accelerate_end_time = value;
        } else if (strcmp(key, "brake_start_position") == 0) {
            p->brake_start_position = value;
        } else if (strcmp(key, "brake_start_time") == 0) {
            p->brake_start_time = value;
        } else {
            for (size_t i = 0; i < sizeof PLANNED / sizeof PLANNED[0]; i++)
                if (strcmp(key, PLANNED[i].name) == 0 && !(v[PLANNED[i].vr] == value)) {
                    char a[40], b[40];
                    snprintf(err, n, "%s = %s: the native build ships %s planned with %s = %s "
                             "(the profile is planned at build time); another value needs the "
                             "Python FMU", key, ato_repr(v[PLANNED[i].vr], a), what, key,
                             ato_repr(value, b));
                    return 0;
                }
        }
    }
    if (k < 2 || k != p->n) {
        snprintf(err, n, "%s: its bundled file has %d of its %d points (at least 2)", what,
                 k < 0 ? 0 : k, p->n);
        return 0;
    }
    return 1;
}

/* the bundled profile of the parameters in p; 0 after a message naming the parameter */
static int profile_load(eco_profile* prof, const ato_values* p, char* err, size_t n) {
    const char *kind = p->s[ATO_VR_profile], *route = p->s[ATO_VR_route];
    char folder[512], what[600];
    int pmp = strcmp(kind, "pmp") == 0;
    if (strpbrk(route, "/\\.")) {
        snprintf(err, n, "route = '%s': the native build reads bundled routes only; a file "
                 "path needs the Python FMU", route);
        return 0;
    }
    snprintf(folder, sizeof folder, pmp ? "eco_profiles/%s/pmp" : "eco_profiles/%s", route);
    const char* name = pmp ? p->s[ATO_VR_optimum] : kind;
    FILE* f = ato_open_bundled(p->resources, folder, name, "profile", pmp ? "optimum" : "profile",
                               err, n);
    if (!f) {
        if (!pmp && !strpbrk(kind, "/\\.")) /* the kinds and routes shipped: resources */
            snprintf(err, n, "profile = '%s', route = '%s': no profile of that kind and line "
                     "is planned in this native build (resources/eco_profiles/<route>/"
                     "<profile>.profile); the Python FMU plans any", kind, route);
        return 0;
    }
    if (pmp)
        snprintf(what, sizeof what, "the optimum '%s' on route '%s'", name, route);
    else
        snprintf(what, sizeof what, "the '%s' profile of route '%s'", kind, route);
    int ok = profile_read(prof, f, what, p->v, err, n);
    fclose(f);
    if (!ok) profile_free(prof);
    return ok;
}

/* SpeedProfile.at_time: (s_ref, v_ref, a_ref) at t after departure */
static void at_time(const eco_profile* p, double t, double* s, double* v, double* a) {
    int last = p->n - 1;
    if (t <= 0.0) {
        *s = p->s[0];
        *v = p->v[0];
        *a = t == 0 ? p->accel[0] : 0.0;
        return;
    }
    if (t >= p->t[last]) {
        *s = p->s[last];
        *v = 0.0;
        *a = 0.0;
        return;
    }
    int i = ato_min(ato_max(ato_bisect_right(p->t, p->n, t) - 1, 0), last - 1);
    double acc = p->accel[i], tau = t - p->t[i];
    *v = ato_max(p->v[i] + acc * tau, 0.0);
    *s = ato_min(p->s[i] + p->v[i] * tau + 0.5 * acc * tau * tau, p->s[i + 1]);
    *a = acc;
}

/* the exponent of CPython's float ** 2, which calls libm's pow (it differs from x * x by
 * an ulp in about one case in a thousand); volatile, so gcc does not fold pow(x, 2.0) into
 * x * x */
static volatile double SQUARE = 2.0;

/* SpeedProfile.at_position: (v_ref, a_ref) at position s (v^2 linear in each step) */
static void at_position(const eco_profile* p, double s, double* v, double* a) {
    int last = p->n - 1;
    if (s >= p->s[last]) {
        *v = 0.0;
        *a = 0.0;
        return;
    }
    if (s <= p->s[0]) {
        *v = p->v[0];
        *a = p->accel[0];
        return;
    }
    int i = ato_bisect_right(p->s, p->n, s) - 1;
    double acc = p->accel[i];
    *v = sqrt(ato_max(pow(p->v[i], SQUARE) + 2.0 * acc * (s - p->s[i]), 0.0));
    *a = acc;
}

/* SpeedProfile.phase_at_time */
static double phase_at_time(const eco_profile* p, double t) {
    if (t < p->accelerate_end_time) return 1.0;
    if (t < p->brake_start_time) return PHASE_RUN;
    return PHASE_BRAKE;
}

static double npmax(double a, double b) { return isnan(a) || isnan(b) ? a + b : (b > a ? b : a); }

law_core* law_make(const ato_values* p, double t0, char* err, size_t n) {
    const double* v = p->v;
    gpc_params gp = GPC_PARAMS(v, 1, 1);
    if (!gpc_check(&gp, err, n)) return NULL;
    const char* start = p->s[ATO_VR_model_start];
    int identified = strcmp(start, "identified") == 0;
    if (!identified && strcmp(start, "cold") != 0) {
        snprintf(err, n, "model_start = '%s': must be one of 'identified', 'cold'", start);
        return NULL;
    }
    law_core* c = calloc(1, sizeof *c);
    if (!profile_load(&c->prof, p, err, n)) {
        free(c);
        return NULL;
    }
    double gamma = v[ATO_VR_rotating_mass_factor];
    if (identified) { /* Crh3Gpc: the identified ARX model at departure, b in m/s per m/s^2 */
        double a = NAN, b = NAN, gravity = NAN, value;
        char line[256], key[64];
        FILE* f = ato_open_bundled(p->resources, "eco_profiles", "identified", "arx",
                                   "model_start", err, n);
        if (!f) {
            profile_free(&c->prof);
            free(c);
            return NULL;
        }
        while (fgets(line, sizeof line, f)) {
            if (sscanf(line, "%63s %lf", key, &value) != 2) continue;
            if (strcmp(key, "a") == 0) a = value;
            if (strcmp(key, "b") == 0) b = value;
            if (strcmp(key, "gravity") == 0) gravity = value;
        }
        fclose(f);
        double to_unit = 100.0 * (1.0 + gamma) / gravity;
        gp.a_init = a;
        gp.b_init = b * to_unit / 3.6;
    }
    c->t0 = t0;
    c->m_eff = v[ATO_VR_mass] * (1.0 + gamma);
    c->accel_min = v[ATO_VR_accel_min];
    c->accel_max = v[ATO_VR_accel_max];
    c->limit_speed = v[ATO_VR_limit_speed];
    c->position_gain = v[ATO_VR_position_gain];
    c->max_correction = v[ATO_VR_max_correction];
    c->stop_speed = v[ATO_VR_stop_speed];
    c->hold_accel = v[ATO_VR_hold_accel];
    c->sample_time = v[ATO_VR_sample_time];
    c->count = TRACKER_STATE + gpc_state_count(&gp);
    c->st = calloc(c->count, sizeof(double));
    c->st[6] = 1.0; /* phase: accelerate */
    gpc_make(&c->gpc, &gp, c->st + TRACKER_STATE);
    return c;
}

void law_free(law_core* c) {
    gpc_free(&c->gpc);
    profile_free(&c->prof);
    free(c->st);
    free(c);
}

size_t law_state_size(const law_core* c) { return c->count * sizeof(double); }
void law_get_state(const law_core* c, void* out) { memcpy(out, c->st, law_state_size(c)); }
void law_set_state(law_core* c, const void* in) { memcpy(c->st, in, law_state_size(c)); }

void law_outputs(const law_core* c, double* out) {
    const double* st = c->st;
    out[ATO_VR_force] = st[0];
    out[ATO_VR_accel_demand] = st[1];
    out[ATO_VR_v_ref] = st[2];
    out[ATO_VR_a_ref] = st[3];
    out[ATO_VR_s_ref] = st[4];
    out[ATO_VR_speed_error] = st[5];
    out[ATO_VR_phase] = st[6];
}

/* EcoTracker.references: refs[j] = r(k + 1 + j), j < Ny, into the GPC's refs; sets v_ref,
 * a_ref, s_ref and phase in st */
static void references(law_core* c, double t, double s, double* refs, double* st) {
    const eco_profile* prof = &c->prof;
    double T = c->sample_time, tau = t - c->t0, s_p, v_p, a_p;
    int Ny = c->gpc.p.Ny;
    if (s >= prof->brake_start_position) { /* final braking: in distance */
        double v_d, a_d;
        at_position(prof, s, &v_d, &a_d);
        st[2] = v_d;
        st[3] = a_d;
        at_time(prof, tau, &s_p, &v_p, &a_p);
        st[4] = s_p;
        st[6] = PHASE_BRAKE;
        for (int j = 1; j <= Ny; j++) refs[j - 1] = npmax(v_d + a_d * (double)j * T, 0.0);
        return;
    }
    at_time(prof, tau, &s_p, &v_p, &a_p);
    st[2] = v_p;
    st[3] = a_p;
    st[4] = s_p;
    st[6] = ato_min(phase_at_time(prof, tau), PHASE_RUN);
    double corr = ato_npclip(c->position_gain * (s_p - s), -c->max_correction,
                             c->max_correction);
    for (int j = 1; j <= Ny; j++) {
        double s_k, v_k, a_k;
        at_time(prof, tau + (double)j * T, &s_k, &v_k, &a_k);
        refs[j - 1] = ato_npclip(v_k + corr, 0.0, c->limit_speed);
    }
}

int law_compute(law_core* c, double t, const ato_values* p, double* out, char* err, size_t n) {
    double* st = c->st;
    double v = p->v[ATO_VR_v], s = p->v[ATO_VR_s];
    /* EcoTracker.input_box */
    double hi = ato_min(c->accel_max, ato_max(p->v[ATO_VR_traction_limit], 0.0) / c->m_eff);
    double lo = ato_max(c->accel_min, -ato_max(p->v[ATO_VR_brake_limit], 0.0) / c->m_eff);
    lo = ato_min(lo, hi);
    gpc_core* g = &c->gpc;
    references(c, t, s, g->refs, st);
    int holding = st[6] == PHASE_BRAKE && st[2] <= 0.0 && v < c->stop_speed;
    double u;
    if (holding) { /* Crh3Gpc.law_hold */
        u = ato_min(ato_max(c->hold_accel, lo), hi);
        gpc_observe(g, &v, 0);
        gpc_applied(g, &u);
    } else { /* Crh3Gpc.law_control */
        gpc_observe(g, &v, 1);
        if (!gpc_plan(g, g->refs, &u)) {
            snprintf(err, n, "GPC: G'G + w I is singular (Singular matrix)");
            return 0;
        }
        u = ato_npclip(u, lo, hi);
        gpc_applied(g, &u);
    }
    st[7] = holding;
    st[1] = u;
    st[0] = c->m_eff * u;
    st[5] = v - st[2];
    law_outputs(c, out);
    return 1;
}
