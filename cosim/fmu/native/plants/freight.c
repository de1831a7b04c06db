/*
 * freight.c: native backend of FreightTrain, the C twin of plants/freight.py (seed 002:
 * HXD1 + 108 loaded C80, one mass per vehicle, draft-gear couplers, traction lag with dead
 * time, brake-pipe wave and brake-cylinder filling; equations in plants/freight.py).
 *
 * The Python core advances a communication step in one call of its compiled kernel
 * (plants.kernels.freight_steps, numba); this backend does what the core does around that call
 * (FreightTrain.advance and _advance_compiled: command histories, the sub-step grid on the
 * absolute integer-nanosecond grid of max_step split where a delayed traction change acts,
 * delayed demand per sub-step, brake-pipe arrivals per vehicle) and calls the same kernel in C
 * (freight_kernel.c, the same operations in the same order). The train is built from the
 * parameters with the core's operations (FreightTrain.__init__), and the outputs are computed
 * as FreightTrain.outputs computes them; the one sum whose order differs is the total air-brake
 * force (numpy's dot product there, a loop here; docs/native_fmus.md states the bound).
 *
 * The FMI side (variables, ranges, calling sequence, FMU state) is the generic plant backend
 * plant_backend.c; this file defines ATO_MODEL. Variables come from the generated
 * FreightTrain_decl.h: the number of vehicles is the number of v[i] outputs, the pressure
 * outputs p_cyl[i] name their vehicles.
 * The route parameter names a bundled route whose profiles the build exported to
 * resources/routes/<name>.grade, .speed_limit and .additional (two floats a line).
 */
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "bundled.h"
#include "plant_backend.h"
#include "ato_model_decl.h"
#include "numpy_random.h"
#include "freight_kernel.h"

#define BEFORE_START (-(1LL << 62))
#define GRAVITY 9.81
#define KMH (1.0 / 3.6)
#define MAX_PRESSURE_OUTPUTS 64

typedef struct { int64_t tick; double value; } tcmd;   /* traction demand history (N) */
typedef struct { double t, value; } bcmd;             /* brake-pipe history (s, Pa) */
typedef struct { int n; double *starts, *values; } steps; /* a step profile / knot table */

typedef struct {
    /* the train, fixed while the core lives */
    int n;
    double *m_eff, *length, *res_a, *res_b, *res_c, *wpk, *brake_scale, *apply_delay,
        *release_delay;
    double cp[N_CONST];
    double slack, k, c;
    int64_t grid_ticks, delay_ticks;
    steps grade, limit, additional; /* additional: knots xs (starts) and integral (values) */
    double* slopes;
    int64_t *hint_f, *hint_r; /* kernel search hints (speed only: results do not depend) */
    double* work;
    /* state (FreightTrain.state_fields) */
    int64_t t_ticks;
    double *x, *v, *pres;
    double traction_force, energy, peak_draft, peak_buff, accel;
    int held;
    int n_th, cap_th;
    tcmd* th;
    int n_bh, cap_bh;
    bcmd* bh;
    /* the outputs v[1..n] (from vr_v1) and p_cyl[i] (value references, vehicles) */
    int vr_v1, n_pressure;
    int pressure_vr[MAX_PRESSURE_OUTPUTS], pressure_vehicle[MAX_PRESSURE_OUTPUTS];
} train;

static void* grow(void* p, int* cap, int need, size_t size) {
    if (need <= *cap) return p;
    while (*cap < need) *cap = *cap ? 2 * *cap : 8;
    return realloc(p, (size_t)*cap * size);
}

/* -- route ------------------------------------------------------------------------------ */
static void free_steps(steps* s) {
    free(s->starts);
    free(s->values);
    s->starts = s->values = NULL;
    s->n = 0;
}

/* resources/routes/<route>.<kind>: "a b" lines, '#' comments */
static int read_table(ato_inst* m, const char* route, const char* kind, steps* out) {
    char err[512];
    FILE* f = ato_open_bundled(m->resources, "routes", route, kind, "route", err, sizeof err);
    if (!f) {
        ATO_ERROR(m, "bad parameter: %s", err);
        return 0;
    }
    int cap = 0, k = 0;
    out->starts = out->values = NULL;
    char line[256];
    while (fgets(line, sizeof line, f)) {
        double a, b;
        if (line[0] == '#' || sscanf(line, "%lf %lf", &a, &b) != 2) continue;
        int cap2 = cap;
        out->starts = grow(out->starts, &cap, k + 1, sizeof(double));
        out->values = grow(out->values, &cap2, k + 1, sizeof(double));
        out->starts[k] = a;
        out->values[k] = b;
        k++;
    }
    fclose(f);
    out->n = k;
    if (k == 0) {
        ATO_ERROR(m, "bad parameter: route = '%s': its bundled %s table has no rows", route,
                  kind);
        return 0;
    }
    return 1;
}

static int load_route(ato_inst* m, train* c, const char* route) {
    if (!read_table(m, route, "grade", &c->grade) ||
        !read_table(m, route, "speed_limit", &c->limit) ||
        !read_table(m, route, "additional", &c->additional))
        return 0;
    if (c->additional.n < 2) {
        ATO_ERROR(m, "route '%s': additional profile needs 2 knots", route);
        return 0;
    }
    int nx = c->additional.n;
    c->slopes = malloc((size_t)(nx - 1) * sizeof(double));
    for (int i = 0; i < nx - 1; i++) /* np.diff(cum) / np.diff(xs) */
        c->slopes[i] = (c->additional.values[i + 1] - c->additional.values[i]) /
                       (c->additional.starts[i + 1] - c->additional.starts[i]);
    return 1;
}

/* StepProfile.at: values[bisect_right(starts, s) - 1] (starts[0] = -inf) */
static double step_at(const steps* p, double s) {
    int lo = 0, hi = p->n;
    while (lo < hi) {
        int mid = (lo + hi) / 2;
        if (s < p->starts[mid]) hi = mid; else lo = mid + 1;
    }
    return p->values[lo > 0 ? lo - 1 : 0];
}

/* -- command histories -------------------------------------------------------------------- */
/* dead_time.delayed: the demand delay_ticks before tick */
static double delayed(const train* c, int64_t tick) {
    int64_t target = tick - c->delay_ticks;
    double value = c->th[0].value;
    for (int i = 0; i < c->n_th; i++) {
        if (c->th[i].tick > target) break;
        value = c->th[i].value;
    }
    return value;
}

/* -- the train -------------------------------------------------------------------------------- */
static void destroy(void* core) {
    train* c = core;
    double* arrays[] = {c->m_eff, c->length, c->res_a, c->res_b, c->res_c, c->wpk,
                        c->brake_scale, c->apply_delay, c->release_delay, c->slopes, c->work,
                        c->x, c->v, c->pres};
    for (size_t i = 0; i < sizeof arrays / sizeof *arrays; i++) free(arrays[i]);
    free_steps(&c->grade);
    free_steps(&c->limit);
    free_steps(&c->additional);
    free(c->hint_f);
    free(c->hint_r);
    free(c->th);
    free(c->bh);
    free(c);
}

/* FreightParams.check_relations, and the one declared bound the variable table cannot hold
 * (max_traction_force is declared above 0, exclusive; the table's min is inclusive). Every
 * other declared range (min/max, the integer traction_model in [0, 1]) is enforced where the
 * value is set (set_number, from the generated ATO_VARS). Messages name the parameter. */
static int check_parameters(ato_inst* m) {
    const double* r = m->r;
    if (r[ATO_VR_disturbance_seed] < 0) {
        ATO_ERROR(m, "bad parameter: disturbance_seed = %.17g must be >= 0 (numpy "
                  "SeedSequence)", r[ATO_VR_disturbance_seed]);
        return 0;
    }
    if (!(r[ATO_VR_max_traction_force] > 0)) {
        ATO_ERROR(m, "bad parameter: max_traction_force = %.17g: must be greater than 0",
                  r[ATO_VR_max_traction_force]);
        return 0;
    }
    if (r[ATO_VR_coupler_slack] > 0) {
        double lighter = r[ATO_VR_loco_mass] < r[ATO_VR_wagon_mass] ? r[ATO_VR_loco_mass]
                                                                    : r[ATO_VR_wagon_mass];
        double h = r[ATO_VR_max_step];
        double stiffness = r[ATO_VR_coupler_stiffness] * (h * h) / (0.5 * lighter);
        if (stiffness > 0.5) {
            ATO_ERROR(m, "bad parameter: coupler_stiffness = %.17g with slack needs max_step "
                      "<= %.2g s (contact too stiff for the sub-step)",
                      r[ATO_VR_coupler_stiffness], sqrt(0.5 / stiffness) * h);
            return 0;
        }
    }
    return 1;
}

/* FreightTrain.from_parameters / __init__: the same operations per vehicle */
static void* create(ato_inst* m) {
    if (!check_parameters(m)) return NULL;
    const double* r = m->r;
    train* c = calloc(1, sizeof(train)); /* destroy releases whatever was allocated */
    if (!load_route(m, c, m->str[ATO_VR_route])) {
        destroy(c);
        return NULL;
    }
    int n = 0;
    c->vr_v1 = -1;
    c->n_pressure = 0;
    for (int i = 0; i < ATO_N_VARS; i++) {
        int vehicle;
        if (sscanf(ATO_VARS[i].name, "v[%d]", &vehicle) == 1) {
            if (c->vr_v1 < 0) c->vr_v1 = i;
            n++;
        } else if (sscanf(ATO_VARS[i].name, "p_cyl[%d]", &vehicle) == 1 &&
                   c->n_pressure < MAX_PRESSURE_OUTPUTS) {
            c->pressure_vr[c->n_pressure] = i;
            c->pressure_vehicle[c->n_pressure++] = vehicle - 1;
        }
    }
    c->n = n;
    size_t bytes = (size_t)n * sizeof(double);
    double** arrays[] = {&c->m_eff, &c->length, &c->res_a, &c->res_b, &c->res_c, &c->wpk,
                         &c->brake_scale, &c->apply_delay, &c->release_delay, &c->x, &c->v,
                         &c->pres};
    for (size_t i = 0; i < sizeof arrays / sizeof *arrays; i++) *arrays[i] = calloc(n, bytes);
    c->work = calloc((size_t)N_WORK * n, sizeof(double));
    c->hint_f = calloc(n, sizeof(int64_t));
    c->hint_r = calloc(n, sizeof(int64_t));
    /* plants.freight.resistance_factors: exp(spread z - spread^2 / 2), z the vehicles' draws
     * of np.random.default_rng(disturbance_seed).standard_normal(n); ones for spread = 0 */
    double spread = r[ATO_VR_resistance_spread];
    ato_pcg64 rng;
    uint64_t seed = (uint64_t)r[ATO_VR_disturbance_seed];
    if (spread != 0.0) ato_pcg64_seed(&rng, &seed, 1);
    double fill_front = 0.0; /* -cumsum(length[:-1]), sequential as np.cumsum */
    for (int i = 0; i < n; i++) {
        int loco = i == 0;
        double mass = loco ? r[ATO_VR_loco_mass] : r[ATO_VR_wagon_mass];
        double length = loco ? r[ATO_VR_loco_length] : r[ATO_VR_wagon_length];
        double gamma = loco ? r[ATO_VR_loco_rotating_mass_factor]
                            : r[ATO_VR_wagon_rotating_mass_factor];
        double ra = loco ? r[ATO_VR_loco_resistance_a] : r[ATO_VR_wagon_resistance_a];
        double rb = loco ? r[ATO_VR_loco_resistance_b] : r[ATO_VR_wagon_resistance_b];
        double rc = loco ? r[ATO_VR_loco_resistance_c] : r[ATO_VR_wagon_resistance_c];
        if (spread != 0.0) { /* coeffs *= factors[:, None] */
            double factor = exp(spread * ato_standard_normal(&rng) - 0.5 * (spread * spread));
            ra *= factor;
            rb *= factor;
            rc *= factor;
        }
        double theta = loco ? r[ATO_VR_loco_braking_ratio] : r[ATO_VR_wagon_braking_ratio];
        double weight = mass * GRAVITY;
        c->length[i] = length;
        c->m_eff[i] = mass * (1.0 + gamma);
        c->res_a[i] = ra * weight / 1e3;
        c->res_b[i] = rb * weight / 1e3 / KMH;
        c->res_c[i] = rc * weight / 1e3 / (KMH * KMH); /* KMH**2: the same double */
        c->wpk[i] = weight / 1e3;
        c->brake_scale[i] = theta * weight / r[ATO_VR_max_cylinder_pressure];
        double front = i == 0 ? -0.0 : -fill_front; /* -concatenate(([0.0], cumsum)) */
        double centre = -front + 0.5 * length;
        c->apply_delay[i] = r[ATO_VR_brake_apply_delay] + centre /
                            r[ATO_VR_brake_propagation_speed];
        c->release_delay[i] = r[ATO_VR_brake_release_delay] + centre /
                              r[ATO_VR_brake_release_propagation_speed];
        c->x[i] = r[ATO_VR_s0] + front;
        c->v[i] = r[ATO_VR_v0];
        fill_front = i == 0 ? length : fill_front + length;
    }
    double* cp = c->cp;
    cp[C_STICTION] = r[ATO_VR_stiction_speed];
    cp[C_K] = c->k = r[ATO_VR_coupler_stiffness];
    cp[C_C] = c->c = r[ATO_VR_coupler_damping];
    cp[C_SLACK] = c->slack = r[ATO_VR_coupler_slack];
    cp[C_MODEL] = r[ATO_VR_traction_model];
    cp[C_TAU] = r[ATO_VR_traction_time_constant];
    cp[C_RAMP_RATE] = 0.8 * r[ATO_VR_max_traction_force] / r[ATO_VR_traction_ramp_time];
    cp[C_F_MAX] = r[ATO_VR_max_traction_force];
    cp[C_P_MAX] = r[ATO_VR_max_traction_power];
    cp[C_ED_MAX] = r[ATO_VR_max_ed_force];
    cp[C_ED_P_MAX] = r[ATO_VR_max_ed_power];
    cp[C_ED_FADE] = r[ATO_VR_ed_fade_speed];
    cp[C_PMAX] = r[ATO_VR_max_cylinder_pressure];
    cp[C_FILL_T] = r[ATO_VR_brake_fill_time];
    cp[C_FILL_E] = r[ATO_VR_brake_fill_exponent];
    cp[C_REL_T] = r[ATO_VR_brake_release_time];
    cp[C_REL_E] = r[ATO_VR_brake_release_exponent];
    cp[C_R_FULL] = r[ATO_VR_full_service_reduction];
    cp[C_R_MIN] = r[ATO_VR_min_reduction];
    c->grid_ticks = ato_to_ticks(r[ATO_VR_max_step]);
    c->delay_ticks = ato_to_ticks(r[ATO_VR_traction_delay]);
    c->t_ticks = m->start_ticks;
    c->th = grow(NULL, &c->cap_th, 1, sizeof(tcmd));
    c->th[0].tick = BEFORE_START;
    c->th[0].value = 0.0;
    c->n_th = 1;
    c->bh = grow(NULL, &c->cap_bh, 1, sizeof(bcmd));
    c->bh[0].t = -1e18;
    c->bh[0].value = 0.0;
    c->n_bh = 1;
    return c;
}

/* FreightTrain.coupler_forces, coupler j (between vehicles j and j+1) */
static double coupler_force(const train* c, int j) {
    double gap = c->x[j] - c->length[j] - c->x[j + 1];
    double dv = c->v[j] - c->v[j + 1];
    if (c->slack > 0) {
        double half = 0.5 * c->slack;
        double on = (gap > half || gap < -half) ? 1.0 : 0.0;
        double offset = gap > half ? half : (gap < -half ? -half : 0.0);
        return on * (c->k * (gap - offset) + c->c * dv);
    }
    return c->k * gap + c->c * dv;
}

/* shoe friction coefficient (plants.kernels.shoe_friction), v in km/h */
static double shoe_friction(double kmh) { return 0.322 * (kmh + 150.0) / (2.0 * kmh + 150.0); }

/* FreightTrain.outputs into m->r */
static void outputs(ato_inst* m, void* core) {
    const train* c = core;
    double* r = m->r;
    int n = c->n;
    double fmax = 0.0, fmin = 0.0;
    for (int j = 0; j < n - 1; j++) {
        double f = coupler_force(c, j);
        if (j == 0 || f > fmax) fmax = f;
        if (j == 0 || f < fmin) fmin = f;
    }
    double air = 0.0;
    int braked = 0;
    for (int i = 0; i < n; i++) braked |= c->pres[i] != 0.0;
    if (braked) /* np.dot(brake_scale * pressure, friction_coefficient(v)), summed in order */
        for (int i = 0; i < n; i++)
            air += (c->brake_scale[i] * c->pres[i]) * shoe_friction(fabs(c->v[i]) / KMH);
    r[ATO_VR_v] = c->v[0];
    r[ATO_VR_s] = c->x[0];
    r[ATO_VR_v_tail] = c->v[n - 1];
    r[ATO_VR_s_tail] = c->x[n - 1] - c->length[n - 1];
    r[ATO_VR_a] = c->accel;
    r[ATO_VR_traction_force] = c->traction_force;
    r[ATO_VR_traction_power] = c->traction_force * c->v[0];
    r[ATO_VR_traction_energy] = c->energy;
    r[ATO_VR_applied_demand] = delayed(c, c->t_ticks);
    r[ATO_VR_draft_force_max] = n > 1 ? ato_max(fmax, 0.0) : 0.0;
    r[ATO_VR_buff_force_max] = n > 1 ? ato_max(-fmin, 0.0) : 0.0;
    r[ATO_VR_draft_force_peak] = c->peak_draft;
    r[ATO_VR_buff_force_peak] = c->peak_buff;
    r[ATO_VR_air_brake_force] = air;
    r[ATO_VR_grade] = step_at(&c->grade, c->x[0]);
    r[ATO_VR_speed_limit] = step_at(&c->limit, c->x[0]);
    r[ATO_VR_brake_pipe_reduction] = c->bh[c->n_bh - 1].value;
    for (int i = 0; i < n; i++) r[c->vr_v1 + i] = c->v[i];
    for (int k = 0; k < c->n_pressure; k++)
        r[c->pressure_vr[k]] = c->pressure_vehicle[k] < n ? c->pres[c->pressure_vehicle[k]]
                                                          : NAN;
}

/* FreightTrain.advance + _advance_compiled */
static int step(ato_inst* m, void* core, int64_t t, int64_t h) {
    train* c = core;
    int n = c->n;
    double demand = m->r[ATO_VR_force_demand], reduction = m->r[ATO_VR_pipe_reduction];
    if (t != c->t_ticks) {
        ATO_ERROR(m, "doStep at t=%.17g s but plant is at t=%.17g s", ato_to_seconds(t),
                  ato_to_seconds(c->t_ticks));
        return 0;
    }
    if (demand != c->th[c->n_th - 1].value) { /* dead_time.record */
        c->th = grow(c->th, &c->cap_th, c->n_th + 1, sizeof(tcmd));
        c->th[c->n_th].tick = t;
        c->th[c->n_th++].value = demand;
    }
    if (reduction != c->bh[c->n_bh - 1].value) {
        c->bh = grow(c->bh, &c->cap_bh, c->n_bh + 1, sizeof(bcmd));
        c->bh[c->n_bh].t = ato_to_seconds(t);
        c->bh[c->n_bh++].value = reduction;
    }
    /* dead_time.substep_ends: grid multiples, instants a delayed demand acts, the end */
    int64_t end = t + h;
    int64_t* acts = malloc((size_t)c->n_th * sizeof(int64_t));
    for (int i = 0; i < c->n_th; i++) acts[i] = c->th[i].tick + c->delay_ticks;
    int64_t* cuts;
    size_t n_sub = ato_substep_ends_acting(t, h, &c->grid_ticks, 1, acts, (size_t)c->n_th,
                                           &cuts);
    free(acts);
    double* hs = malloc(4 * n_sub * sizeof(double));
    double *t0s = hs + n_sub, *t1s = hs + 2 * n_sub, *demands = hs + 3 * n_sub;
    int64_t now = t;
    for (size_t s = 0; s < n_sub; s++) {
        t0s[s] = ato_to_seconds(now);
        t1s[s] = ato_to_seconds(cuts[s]);
        hs[s] = ato_to_seconds(cuts[s] - now);
        demands[s] = delayed(c, now);
        now = cuts[s];
    }
    /* brake-pipe commands and their arrival at each vehicle (FreightTrain._arrivals) */
    int K = c->n_bh;
    double* arrivals = calloc((size_t)K * n, sizeof(double));
    double* values = malloc((size_t)K * sizeof(double) * 2);
    double* targets = values + K;
    for (int k = 0; k < K; k++) values[k] = c->bh[k].value;
    if (K > 1)
        for (int k = 0; k < K; k++) {
            int rising = k == 0 || values[k] >= values[k - 1];
            const double* delay = rising ? c->apply_delay : c->release_delay;
            for (int i = 0; i < n; i++) arrivals[(size_t)k * n + i] = c->bh[k].t + delay[i];
        }
    double sc[N_SCALARS] = {c->traction_force, c->energy, 0.0, 0.0, c->accel, 0.0,
                            (double)c->held};
    freight_steps(n, (int64_t)n_sub, K, c->additional.n, c->x, c->v, c->pres, sc, hs, t0s,
                  t1s, demands, arrivals, values, c->m_eff, c->length, c->res_a, c->res_b,
                  c->res_c, c->wpk, c->brake_scale, c->additional.starts, c->additional.values,
                  c->slopes, c->hint_f, c->hint_r, c->cp, c->work, targets);
    c->traction_force = sc[S_TRACTION];
    c->energy = sc[S_ENERGY];
    c->peak_draft = sc[S_PEAK_DRAFT];
    c->peak_buff = sc[S_PEAK_BUFF];
    c->accel = sc[S_ACCEL];
    c->held = sc[S_HELD] != 0.0;
    int forget = (int)sc[S_FIRST]; /* commands every vehicle has passed */
    if (forget > 0) {
        memmove(c->bh, c->bh + forget, (size_t)(c->n_bh - forget) * sizeof(bcmd));
        c->n_bh -= forget;
    }
    free(cuts);
    free(hs);
    free(arrivals);
    free(values);
    c->t_ticks = end;
    /* dead_time.prune */
    int64_t target = end - c->delay_ticks;
    int drop = 0;
    while (c->n_th - drop > 1 && c->th[drop + 1].tick <= target) drop++;
    if (drop) {
        memmove(c->th, c->th + drop, (size_t)(c->n_th - drop) * sizeof(tcmd));
        c->n_th -= drop;
    }
    return 1;
}

/* -- the core's state: counts, time, positions, speeds, pressures, scalars, histories ------- */
static void save(const void* core, ato_buf* b) {
    const train* c = core;
    int32_t counts[3] = {c->n, c->n_th, c->n_bh};
    ato_put(b, counts, sizeof counts);
    ato_put(b, &c->t_ticks, sizeof c->t_ticks);
    ato_put(b, c->x, (size_t)c->n * sizeof(double));
    ato_put(b, c->v, (size_t)c->n * sizeof(double));
    ato_put(b, c->pres, (size_t)c->n * sizeof(double));
    double scalars[6] = {c->traction_force, c->energy, c->peak_draft, c->peak_buff, c->accel,
                         (double)c->held};
    ato_put(b, scalars, sizeof scalars);
    ato_put(b, c->th, (size_t)c->n_th * sizeof(tcmd));
    ato_put(b, c->bh, (size_t)c->n_bh * sizeof(bcmd));
}

static int load(void* core, ato_rd* r) {
    train* c = core;
    int32_t counts[3] = {0, 0, 0};
    ato_take(r, counts, sizeof counts);
    if (!r->ok || counts[0] != c->n || counts[1] < 1 || counts[2] < 1 ||
        (size_t)counts[1] > r->n || (size_t)counts[2] > r->n)
        return 0;
    ato_take(r, &c->t_ticks, sizeof c->t_ticks);
    ato_take(r, c->x, (size_t)c->n * sizeof(double));
    ato_take(r, c->v, (size_t)c->n * sizeof(double));
    ato_take(r, c->pres, (size_t)c->n * sizeof(double));
    double scalars[6];
    ato_take(r, scalars, sizeof scalars);
    c->th = grow(c->th, &c->cap_th, counts[1], sizeof(tcmd));
    c->bh = grow(c->bh, &c->cap_bh, counts[2], sizeof(bcmd));
    c->n_th = counts[1];
    c->n_bh = counts[2];
    ato_take(r, c->th, (size_t)c->n_th * sizeof(tcmd));
    ato_take(r, c->bh, (size_t)c->n_bh * sizeof(bcmd));
    if (!r->ok) return 0;
    c->traction_force = scalars[0];
    c->energy = scalars[1];
    c->peak_draft = scalars[2];
    c->peak_buff = scalars[3];
    c->accel = scalars[4];
    c->held = scalars[5] != 0.0;
    return 1;
}

const ato_model ATO_MODEL = {
    {ATO_MODEL_IDENTIFIER, ATO_GUID, "ATO-" ATO_MODEL_IDENTIFIER "-state-1", ATO_N_VARS,
     ATO_VARS},
    create, destroy, step, outputs, save, load,
};
