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
 * It is an FMI 2-shaped backend (cosim/fmu/front/ato_backend.h) linked into the FMI 2 front
 * (fmi2_front.c). Variables come from the generated FreightTrain_decl.h: the number of
 * vehicles is the number of v[i] outputs, the pressure outputs p_cyl[i] name their vehicles.
 * The route parameter names a bundled route whose profiles the build exported to
 * resources/routes/<name>.grade, .speed_limit and .additional (two floats a line).
 */
#include <math.h>
#include <stdarg.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "ato_backend.h"
#include "ato_vars.h"
#include "FreightTrain_decl.h"

#define BEFORE_START (-(1LL << 62))
#define GRAVITY 9.81
#define KMH (1.0 / 3.6)
#define STATE_MAGIC "ATO-FreightTrain-state-1"
#define MAX_PRESSURE_OUTPUTS 64

/* freight_kernel.c */
enum { C_STICTION, C_K, C_C, C_SLACK, C_MODEL, C_TAU, C_RAMP_RATE, C_F_MAX, C_P_MAX, C_ED_MAX,
       C_ED_P_MAX, C_ED_FADE, C_PMAX, C_FILL_T, C_FILL_E, C_REL_T, C_REL_E, C_R_FULL, C_R_MIN,
       N_CONST };
enum { S_TRACTION, S_ENERGY, S_PEAK_DRAFT, S_PEAK_BUFF, S_ACCEL, S_FIRST, S_HELD, N_SCALARS };
#define N_WORK 8
void freight_steps(int64_t n, int64_t n_sub, int64_t K, int64_t nx, double *x, double *v,
                   double *pres, double *sc, const double *hs, const double *t0s,
                   const double *t1s, const double *demands, const double *arrivals,
                   const double *values, const double *m_eff, const double *length,
                   const double *res_a, const double *res_b, const double *res_c,
                   const double *wpk, const double *brake_scale, const double *xs,
                   const double *cum, const double *slopes, int64_t *hint_f, int64_t *hint_r,
                   const double *cp, double *work, double *targets);

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
} core;

typedef struct {
    char* name;
    fmi2CallbackFunctions cb;
    int logging_on;
    char* resources; /* directory path */
    double r[ATO_N_VARS]; /* parameters, inputs and (current) outputs */
    char* str[ATO_N_VARS];
    int initialized;
    int64_t start_ticks;
    long executions;
    int have_core;
    core c;
    int vr_v1, n_pressure;
    int pressure_vr[MAX_PRESSURE_OUTPUTS], pressure_vehicle[MAX_PRESSURE_OUTPUTS];
} inst;

static void logm(inst* m, fmi2Status status, const char* category, const char* fmt, ...) {
    char buf[1024];
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(buf, sizeof buf, fmt, ap);
    va_end(ap);
    /* the complete message as the format, '%' doubled (see brake_delay.c) */
    char esc[2048];
    size_t k = 0;
    for (const char* p = buf; *p && k + 2 < sizeof esc; p++) {
        if (*p == '%') esc[k++] = '%';
        esc[k++] = *p;
    }
    esc[k] = 0;
    if (m->cb.logger && (status != fmi2OK || m->logging_on))
        m->cb.logger(m->cb.componentEnvironment, m->name, status, category, esc);
}

static int64_t to_ticks(double seconds) { return (int64_t)llrint(seconds * 1e9); }
static double to_seconds(int64_t ticks) { return (double)ticks / 1e9; }
/* Python's max(a, b) / min(a, b): the first argument unless the second is larger/smaller */
static double pymax(double a, double b) { return b > a ? b : a; }
static int64_t floordiv(int64_t a, int64_t b) {
    int64_t q = a / b;
    return (a % b != 0 && ((a < 0) != (b < 0))) ? q - 1 : q;
}
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
static int read_table(inst* m, const char* route, const char* kind, steps* out) {
    size_t n = strlen(m->resources) + strlen(route) + strlen(kind) + 32;
    char* path = malloc(n);
    snprintf(path, n, "%s/routes/%s.%s", m->resources, route, kind);
    FILE* f = fopen(path, "r");
    if (!f) {
        logm(m, fmi2Error, "logStatusError", "bad parameter: route '%s' not found (%s)", route,
             path);
        free(path);
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
        logm(m, fmi2Error, "logStatusError", "%s: no rows", path);
        free(path);
        return 0;
    }
    free(path);
    return 1;
}

static int load_route(inst* m, core* c, const char* route) {
    for (const char* p = route; *p; p++)
        if (*p == '/' || *p == '\\' || *p == '.') {
            logm(m, fmi2Error, "logStatusError",
                 "bad parameter: route = '%s': the native FMU reads bundled routes only "
                 "(resources/routes/); a route file path needs the Python FMU", route);
            return 0;
        }
    if (!read_table(m, route, "grade", &c->grade) ||
        !read_table(m, route, "speed_limit", &c->limit) ||
        !read_table(m, route, "additional", &c->additional))
        return 0;
    if (c->additional.n < 2) {
        logm(m, fmi2Error, "logStatusError", "route '%s': additional profile needs 2 knots",
             route);
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
static double delayed(const core* c, int64_t tick) {
    int64_t target = tick - c->delay_ticks;
    double value = c->th[0].value;
    for (int i = 0; i < c->n_th; i++) {
        if (c->th[i].tick > target) break;
        value = c->th[i].value;
    }
    return value;
}

static int cmp_i64(const void* a, const void* b) {
    int64_t x = *(const int64_t*)a, y = *(const int64_t*)b;
    return x < y ? -1 : x > y;
}

/* -- the train -------------------------------------------------------------------------------- */
static void free_core(inst* m) {
    if (!m->have_core) return;
    core* c = &m->c;
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
    memset(c, 0, sizeof *c);
    m->have_core = 0;
}

/* FreightParams.check_relations, and the one declared bound the variable table cannot hold
 * (max_traction_force is declared above 0, exclusive; the table's min is inclusive). Every
 * other declared range (min/max, the integer traction_model in [0, 1]) is enforced where the
 * value is set (set_number, from the generated ATO_VARS). Messages name the parameter. */
static int check_parameters(inst* m) {
    const double* r = m->r;
    if (r[ATO_VR_resistance_spread] != 0.0) {
        logm(m, fmi2Error, "logStatusError",
             "bad parameter: resistance_spread = %.17g: the native build has no resistance "
             "spread (0 only; use the Python FMU)", r[ATO_VR_resistance_spread]);
        return 0;
    }
    if (!(r[ATO_VR_max_traction_force] > 0)) {
        logm(m, fmi2Error, "logStatusError",
             "bad parameter: max_traction_force = %.17g: must be greater than 0",
             r[ATO_VR_max_traction_force]);
        return 0;
    }
    if (r[ATO_VR_coupler_slack] > 0) {
        double lighter = r[ATO_VR_loco_mass] < r[ATO_VR_wagon_mass] ? r[ATO_VR_loco_mass]
                                                                    : r[ATO_VR_wagon_mass];
        double h = r[ATO_VR_max_step];
        double stiffness = r[ATO_VR_coupler_stiffness] * (h * h) / (0.5 * lighter);
        if (stiffness > 0.5) {
            logm(m, fmi2Error, "logStatusError",
                 "bad parameter: coupler_stiffness = %.17g with slack needs max_step <= %.2g s "
                 "(contact too stiff for the sub-step)", r[ATO_VR_coupler_stiffness],
                 sqrt(0.5 / stiffness) * h);
            return 0;
        }
    }
    return 1;
}

static void compute_outputs(inst* m);

/* FreightTrain.from_parameters / __init__: the same operations per vehicle */
static int ensure_core(inst* m) {
    if (m->have_core) return 1;
    if (!check_parameters(m)) return 0;
    const double* r = m->r;
    core* c = &m->c;
    memset(c, 0, sizeof *c);
    m->have_core = 1; /* free_core releases whatever was allocated */
    if (!load_route(m, c, m->str[ATO_VR_route])) {
        free_core(m);
        return 0;
    }
    int n = 0;
    m->vr_v1 = -1;
    m->n_pressure = 0;
    for (int i = 0; i < ATO_N_VARS; i++) {
        int vehicle;
        if (sscanf(ATO_VARS[i].name, "v[%d]", &vehicle) == 1) {
            if (m->vr_v1 < 0) m->vr_v1 = i;
            n++;
        } else if (sscanf(ATO_VARS[i].name, "p_cyl[%d]", &vehicle) == 1 &&
                   m->n_pressure < MAX_PRESSURE_OUTPUTS) {
            m->pressure_vr[m->n_pressure] = i;
            m->pressure_vehicle[m->n_pressure++] = vehicle - 1;
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
    c->grid_ticks = to_ticks(r[ATO_VR_max_step]);
    c->delay_ticks = to_ticks(r[ATO_VR_traction_delay]);
    c->t_ticks = m->start_ticks;
    c->th = grow(NULL, &c->cap_th, 1, sizeof(tcmd));
    c->th[0].tick = BEFORE_START;
    c->th[0].value = 0.0;
    c->n_th = 1;
    c->bh = grow(NULL, &c->cap_bh, 1, sizeof(bcmd));
    c->bh[0].t = -1e18;
    c->bh[0].value = 0.0;
    c->n_bh = 1;
    compute_outputs(m);
    return 1;
}

/* FreightTrain.coupler_forces, coupler j (between vehicles j and j+1) */
static double coupler_force(const core* c, int j) {
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
static void compute_outputs(inst* m) {
    const core* c = &m->c;
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
    r[ATO_VR_draft_force_max] = n > 1 ? pymax(fmax, 0.0) : 0.0;
    r[ATO_VR_buff_force_max] = n > 1 ? pymax(-fmin, 0.0) : 0.0;
    r[ATO_VR_draft_force_peak] = c->peak_draft;
    r[ATO_VR_buff_force_peak] = c->peak_buff;
    r[ATO_VR_air_brake_force] = air;
    r[ATO_VR_grade] = step_at(&c->grade, c->x[0]);
    r[ATO_VR_speed_limit] = step_at(&c->limit, c->x[0]);
    r[ATO_VR_brake_pipe_reduction] = c->bh[c->n_bh - 1].value;
    for (int i = 0; i < n; i++) r[m->vr_v1 + i] = c->v[i];
    for (int k = 0; k < m->n_pressure; k++)
        r[m->pressure_vr[k]] = m->pressure_vehicle[k] < n ? c->pres[m->pressure_vehicle[k]]
                                                          : NAN;
}

/* FreightTrain.advance + _advance_compiled */
static int advance(inst* m, int64_t t, int64_t h, double demand, double reduction) {
    core* c = &m->c;
    int n = c->n;
    if (t != c->t_ticks) {
        logm(m, fmi2Error, "logStatusError", "doStep at t=%.17g s but plant is at t=%.17g s",
             to_seconds(t), to_seconds(c->t_ticks));
        return 0;
    }
    if (demand != c->th[c->n_th - 1].value) { /* dead_time.record */
        c->th = grow(c->th, &c->cap_th, c->n_th + 1, sizeof(tcmd));
        c->th[c->n_th].tick = t;
        c->th[c->n_th++].value = demand;
    }
    if (reduction != c->bh[c->n_bh - 1].value) {
        c->bh = grow(c->bh, &c->cap_bh, c->n_bh + 1, sizeof(bcmd));
        c->bh[c->n_bh].t = to_seconds(t);
        c->bh[c->n_bh++].value = reduction;
    }
    /* dead_time.substep_ends: grid multiples, instants a delayed demand acts, the end */
    int64_t end = t + h;
    int64_t first = (floordiv(t, c->grid_ticks) + 1) * c->grid_ticks;
    size_t n_grid = first < end ? (size_t)((end - 1 - first) / c->grid_ticks + 1) : 0;
    size_t cap = n_grid + (size_t)c->n_th + 1, n_cuts = 0;
    int64_t* cuts = malloc(cap * sizeof(int64_t));
    cuts[n_cuts++] = end;
    for (int64_t k = first; k < end; k += c->grid_ticks) cuts[n_cuts++] = k;
    for (int i = 0; i < c->n_th; i++) {
        int64_t act = c->th[i].tick + c->delay_ticks;
        if (t < act && act < end) cuts[n_cuts++] = act;
    }
    qsort(cuts, n_cuts, sizeof(int64_t), cmp_i64);
    size_t n_sub = 0;
    for (size_t i = 0; i < n_cuts; i++) /* a set: each cut once */
        if (i == 0 || cuts[i] != cuts[i - 1]) cuts[n_sub++] = cuts[i];
    double* hs = malloc(4 * n_sub * sizeof(double));
    double *t0s = hs + n_sub, *t1s = hs + 2 * n_sub, *demands = hs + 3 * n_sub;
    int64_t now = t;
    for (size_t s = 0; s < n_sub; s++) {
        t0s[s] = to_seconds(now);
        t1s[s] = to_seconds(cuts[s]);
        hs[s] = to_seconds(cuts[s] - now);
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
    compute_outputs(m);
    return 1;
}

/* -- FMI 2-shaped functions ------------------------------------------------------------------ */
static char* dup(const char* s) {
    char* d = malloc(strlen(s) + 1);
    strcpy(d, s);
    return d;
}

/* file:// URI -> path (percent-decoded); NULL if not a file URI */
static char* uri_to_path(const char* uri) {
    if (!uri) return NULL;
    const char* p = uri;
    if (strncmp(p, "file://", 7) == 0) {
        p += 7;
        if (strncmp(p, "localhost", 9) == 0) p += 9;
    } else if (strncmp(p, "file:", 5) == 0) {
        p += 5;
    } else {
        return NULL;
    }
#ifdef _WIN32
    if (p[0] == '/' && p[1] && p[2] == ':') p++; /* /C:/... */
#endif
    char* out = malloc(strlen(p) + 1);
    char* o = out;
    for (; *p; p++) {
        if (*p == '%' && p[1] && p[2]) {
            char hex[3] = {p[1], p[2], 0};
            *o++ = (char)strtol(hex, NULL, 16);
            p += 2;
        } else {
            *o++ = *p;
        }
    }
    while (o > out && (o[-1] == '/' || o[-1] == '\\')) o--;
    *o = 0;
    return out;
}

static void reset_values(inst* m) {
    for (int i = 0; i < ATO_N_VARS; i++) {
        m->r[i] = ATO_VARS[i].start;
        if (ATO_VARS[i].type == ATO_STRING) {
            free(m->str[i]);
            m->str[i] = dup(ATO_VARS[i].start_string);
        }
    }
}

static fmi2Component ft_instantiate(fmi2String name, fmi2Type type, fmi2String guid,
                                    fmi2String resources, const fmi2CallbackFunctions* cb,
                                    fmi2Boolean visible, fmi2Boolean logging_on) {
    (void)visible;
    inst tmp = {0};
    tmp.name = (char*)(name ? name : "?");
    if (cb) tmp.cb = *cb;
    if (type != fmi2CoSimulation) {
        logm(&tmp, fmi2Error, "logStatusError", "%s: only co-simulation is supported",
             ATO_MODEL_IDENTIFIER);
        return NULL;
    }
    if (!guid || strcmp(guid, ATO_GUID) != 0) {
        logm(&tmp, fmi2Error, "logStatusError",
             "fmi2Instantiate: GUID %s does not match this binary's %s", guid ? guid : "(null)",
             ATO_GUID);
        return NULL;
    }
    char* res = uri_to_path(resources);
    if (!res) {
        logm(&tmp, fmi2Error, "logStatusError",
             "fmi2Instantiate: resource location '%s' is not a file URI",
             resources ? resources : "(null)");
        return NULL;
    }
    inst* m = calloc(1, sizeof(inst));
    m->name = dup(tmp.name);
    m->cb = tmp.cb;
    m->logging_on = logging_on;
    m->resources = res;
    reset_values(m);
    return m;
}

static void ft_free(fmi2Component comp) {
    inst* m = comp;
    if (!m) return;
    free_core(m);
    for (int i = 0; i < ATO_N_VARS; i++) free(m->str[i]);
    free(m->resources);
    free(m->name);
    free(m);
}

static fmi2Status ft_set_debug_logging(fmi2Component comp, fmi2Boolean on, size_t n,
                                       const fmi2String cats[]) {
    (void)n; (void)cats;
    ((inst*)comp)->logging_on = on;
    return fmi2OK;
}

static fmi2Status ft_setup(fmi2Component comp, fmi2Boolean tol_defined, fmi2Real tol,
                           fmi2Real start, fmi2Boolean stop_defined, fmi2Real stop) {
    (void)tol_defined; (void)tol; (void)stop_defined; (void)stop;
    inst* m = comp;
    if (!isfinite(start)) {
        logm(m, fmi2Error, "logStatusError", "start time %g is not finite", start);
        return fmi2Error;
    }
    m->start_ticks = to_ticks(start);
    free_core(m);
    return fmi2OK;
}

static fmi2Status ft_enter_init(fmi2Component comp) {
    ((inst*)comp)->initialized = 0;
    return fmi2OK;
}

static fmi2Status ft_exit_init(fmi2Component comp) {
    inst* m = comp;
    if (!ensure_core(m)) return fmi2Error;
    m->initialized = 1;
    return fmi2OK;
}

static fmi2Status ft_terminate(fmi2Component comp) { (void)comp; return fmi2OK; }

static fmi2Status ft_reset(fmi2Component comp) {
    inst* m = comp;
    free_core(m);
    reset_values(m);
    m->initialized = 0;
    m->start_ticks = 0;
    m->executions = 0;
    return fmi2OK;
}

static int check_vr(inst* m, fmi2ValueReference vr, int type, const char* call) {
    if (vr >= ATO_N_VARS || ATO_VARS[vr].type != type) {
        logm(m, fmi2Error, "logStatusError", "%s: no variable of this type with value "
             "reference %u", call, (unsigned)vr);
        return 0;
    }
    return 1;
}

/* Real and Integer variables live in m->r; outputs are current after every step */
static fmi2Status get_numbers(inst* m, const fmi2ValueReference vr[], size_t n, int type,
                              const char* call, fmi2Real* reals, fmi2Integer* ints) {
    for (size_t i = 0; i < n; i++) {
        if (!check_vr(m, vr[i], type, call)) return fmi2Error;
        if (ATO_VARS[vr[i]].causality == ATO_OUTPUT && !ensure_core(m)) return fmi2Error;
        if (reals) reals[i] = m->r[vr[i]];
        else ints[i] = (fmi2Integer)m->r[vr[i]];
    }
    return fmi2OK;
}

static fmi2Status set_number(inst* m, fmi2ValueReference vr, double value, int type,
                             const char* call) {
    if (!check_vr(m, vr, type, call)) return fmi2Error;
    const ato_var* v = &ATO_VARS[vr];
    if (v->causality == ATO_OUTPUT) {
        logm(m, fmi2Error, "logStatusError", "%s: %s is an output", call, v->name);
        return fmi2Error;
    }
    if (v->causality == ATO_PARAMETER && m->initialized) {
        logm(m, fmi2Error, "logStatusError", "%s: parameter '%s' is fixed after initialisation",
             call, v->name);
        return fmi2Error;
    }
    if (!isfinite(value)) {
        logm(m, fmi2Error, "logStatusError", "%s: %s = %g: not a finite number", call, v->name,
             value);
        return fmi2Error;
    }
    if (v->causality == ATO_PARAMETER && ((v->has_min && value < v->min) ||
                                          (v->has_max && value > v->max))) {
        logm(m, fmi2Error, "logStatusError", "%s: %s = %.17g outside [%g, %g]", call, v->name,
             value, v->has_min ? v->min : -INFINITY, v->has_max ? v->max : INFINITY);
        return fmi2Error;
    }
    m->r[vr] = value;
    if (v->causality == ATO_PARAMETER) free_core(m);
    return fmi2OK;
}

static fmi2Status ft_get_real(fmi2Component comp, const fmi2ValueReference vr[], size_t n,
                              fmi2Real value[]) {
    return get_numbers(comp, vr, n, ATO_REAL, "fmi2GetReal", value, NULL);
}
static fmi2Status ft_get_integer(fmi2Component comp, const fmi2ValueReference vr[], size_t n,
                                 fmi2Integer value[]) {
    return get_numbers(comp, vr, n, ATO_INTEGER, "fmi2GetInteger", NULL, value);
}
static fmi2Status ft_set_real(fmi2Component comp, const fmi2ValueReference vr[], size_t n,
                              const fmi2Real value[]) {
    for (size_t i = 0; i < n; i++)
        if (set_number(comp, vr[i], value[i], ATO_REAL, "fmi2SetReal") != fmi2OK)
            return fmi2Error;
    return fmi2OK;
}
static fmi2Status ft_set_integer(fmi2Component comp, const fmi2ValueReference vr[], size_t n,
                                 const fmi2Integer value[]) {
    for (size_t i = 0; i < n; i++)
        if (set_number(comp, vr[i], (double)value[i], ATO_INTEGER, "fmi2SetInteger") != fmi2OK)
            return fmi2Error;
    return fmi2OK;
}

static fmi2Status ft_get_string(fmi2Component comp, const fmi2ValueReference vr[], size_t n,
                                fmi2String value[]) {
    inst* m = comp;
    for (size_t i = 0; i < n; i++) {
        if (!check_vr(m, vr[i], ATO_STRING, "fmi2GetString")) return fmi2Error;
        value[i] = m->str[vr[i]];
    }
    return fmi2OK;
}

static fmi2Status ft_set_string(fmi2Component comp, const fmi2ValueReference vr[], size_t n,
                                const fmi2String value[]) {
    inst* m = comp;
    for (size_t i = 0; i < n; i++) {
        if (!check_vr(m, vr[i], ATO_STRING, "fmi2SetString")) return fmi2Error;
        if (m->initialized) {
            logm(m, fmi2Error, "logStatusError",
                 "fmi2SetString: parameter '%s' is fixed after initialisation",
                 ATO_VARS[vr[i]].name);
            return fmi2Error;
        }
        free(m->str[vr[i]]);
        m->str[vr[i]] = dup(value[i] ? value[i] : "");
        free_core(m);
    }
    return fmi2OK;
}

static fmi2Status ft_get_boolean(fmi2Component c, const fmi2ValueReference vr[], size_t n,
                                 fmi2Boolean v[]) {
    (void)vr; (void)v;
    if (n == 0) return fmi2OK;
    logm(c, fmi2Error, "logStatusError", "fmi2GetBoolean: this FMU has no such variables");
    return fmi2Error;
}
static fmi2Status ft_set_boolean(fmi2Component c, const fmi2ValueReference vr[], size_t n,
                                 const fmi2Boolean v[]) {
    (void)vr; (void)v;
    if (n == 0) return fmi2OK;
    logm(c, fmi2Error, "logStatusError", "fmi2SetBoolean: this FMU has no such variables");
    return fmi2Error;
}

static fmi2Status ft_do_step(fmi2Component comp, fmi2Real t, fmi2Real h, fmi2Boolean no_set) {
    (void)no_set;
    inst* m = comp;
    if (!ensure_core(m)) return fmi2Error;
    if (!(h > 0.0) || !isfinite(h)) {
        logm(m, fmi2Error, "logStatusError", "doStep: step size %g must be positive and finite",
             h);
        return fmi2Error;
    }
    if (!isfinite(t)) {
        logm(m, fmi2Error, "logStatusError", "doStep: time %g is not finite", t);
        return fmi2Error;
    }
    if (!advance(m, to_ticks(t), to_ticks(h), m->r[ATO_VR_force_demand],
                 m->r[ATO_VR_pipe_reduction]))
        return fmi2Error;
    m->executions++;
    return fmi2OK;
}

/* -- FMU state: a byte image (magic, values, strings, core state) ---------------------------- */
typedef struct { unsigned char* p; size_t n, cap; } buf;
static void put(buf* b, const void* data, size_t n) {
    if (b->n + n > b->cap) {
        b->cap = (b->n + n) * 2;
        b->p = realloc(b->p, b->cap);
    }
    memcpy(b->p + b->n, data, n);
    b->n += n;
}
typedef struct { const unsigned char* p; size_t n, at; int ok; } rd;
static void take(rd* r, void* out, size_t n) {
    if (!r->ok || r->at + n > r->n) { r->ok = 0; memset(out, 0, n); return; }
    memcpy(out, r->p + r->at, n);
    r->at += n;
}

static buf image(inst* m) {
    buf b = {0};
    put(&b, STATE_MAGIC, sizeof STATE_MAGIC);
    put(&b, m->r, sizeof m->r);
    for (int i = 0; i < ATO_N_VARS; i++)
        if (ATO_VARS[i].type == ATO_STRING) {
            uint64_t len = strlen(m->str[i]);
            put(&b, &len, sizeof len);
            put(&b, m->str[i], len);
        }
    int32_t flags[2] = {m->initialized, m->have_core};
    put(&b, flags, sizeof flags);
    put(&b, &m->start_ticks, sizeof m->start_ticks);
    int64_t ex = m->executions;
    put(&b, &ex, sizeof ex);
    if (m->have_core) {
        core* c = &m->c;
        int32_t counts[3] = {c->n, c->n_th, c->n_bh};
        put(&b, counts, sizeof counts);
        put(&b, &c->t_ticks, sizeof c->t_ticks);
        put(&b, c->x, (size_t)c->n * sizeof(double));
        put(&b, c->v, (size_t)c->n * sizeof(double));
        put(&b, c->pres, (size_t)c->n * sizeof(double));
        double scalars[6] = {c->traction_force, c->energy, c->peak_draft, c->peak_buff,
                             c->accel, (double)c->held};
        put(&b, scalars, sizeof scalars);
        put(&b, c->th, (size_t)c->n_th * sizeof(tcmd));
        put(&b, c->bh, (size_t)c->n_bh * sizeof(bcmd));
    }
    return b;
}

static fmi2Status truncated(inst* m) {
    logm(m, fmi2Error, "logStatusError", "truncated FMU state");
    return fmi2Error;
}

static fmi2Status restore(inst* m, const unsigned char* data, size_t n) {
    rd r = {data, n, 0, 1};
    char magic[sizeof STATE_MAGIC];
    take(&r, magic, sizeof magic);
    if (!r.ok || memcmp(magic, STATE_MAGIC, sizeof magic) != 0) {
        logm(m, fmi2Error, "logStatusError", "state does not belong to FMU %s",
             ATO_MODEL_IDENTIFIER);
        return fmi2Error;
    }
    double values[ATO_N_VARS];
    take(&r, values, sizeof values);
    char* strs[ATO_N_VARS] = {0};
    for (int i = 0; i < ATO_N_VARS && r.ok; i++)
        if (ATO_VARS[i].type == ATO_STRING) {
            uint64_t len = 0;
            take(&r, &len, sizeof len);
            if (!r.ok || len > n) { r.ok = 0; break; }
            strs[i] = calloc(len + 1, 1);
            take(&r, strs[i], len);
        }
    int32_t flags[2];
    int64_t start, ex;
    take(&r, flags, sizeof flags);
    take(&r, &start, sizeof start);
    take(&r, &ex, sizeof ex);
    if (!r.ok) {
        for (int i = 0; i < ATO_N_VARS; i++) free(strs[i]);
        return truncated(m);
    }
    free_core(m);
    memcpy(m->r, values, sizeof values);
    for (int i = 0; i < ATO_N_VARS; i++)
        if (ATO_VARS[i].type == ATO_STRING) { free(m->str[i]); m->str[i] = strs[i]; }
    m->start_ticks = start;
    m->executions = (long)ex;
    m->initialized = 0;
    if (flags[1]) {
        if (!ensure_core(m)) return fmi2Error; /* the train from the restored parameters */
        core* c = &m->c;
        int32_t counts[3] = {0, 0, 0};
        take(&r, counts, sizeof counts);
        if (!r.ok || counts[0] != c->n || counts[1] < 1 || counts[2] < 1 ||
            (size_t)counts[1] > n || (size_t)counts[2] > n)
            return truncated(m);
        take(&r, &c->t_ticks, sizeof c->t_ticks);
        take(&r, c->x, (size_t)c->n * sizeof(double));
        take(&r, c->v, (size_t)c->n * sizeof(double));
        take(&r, c->pres, (size_t)c->n * sizeof(double));
        double scalars[6];
        take(&r, scalars, sizeof scalars);
        c->th = grow(c->th, &c->cap_th, counts[1], sizeof(tcmd));
        c->bh = grow(c->bh, &c->cap_bh, counts[2], sizeof(bcmd));
        c->n_th = counts[1];
        c->n_bh = counts[2];
        take(&r, c->th, (size_t)c->n_th * sizeof(tcmd));
        take(&r, c->bh, (size_t)c->n_bh * sizeof(bcmd));
        if (!r.ok) {
            free_core(m);
            return truncated(m);
        }
        c->traction_force = scalars[0];
        c->energy = scalars[1];
        c->peak_draft = scalars[2];
        c->peak_buff = scalars[3];
        c->accel = scalars[4];
        c->held = scalars[5] != 0.0;
        compute_outputs(m);
    }
    m->initialized = flags[0];
    return fmi2OK;
}

typedef struct { size_t n; unsigned char* p; } state_blob;

static fmi2Status ft_get_state(fmi2Component comp, fmi2FMUstate* state) {
    inst* m = comp;
    buf b = image(m);
    state_blob* s = *state ? (state_blob*)*state : calloc(1, sizeof(state_blob));
    free(s->p);
    s->p = b.p;
    s->n = b.n;
    *state = s;
    return fmi2OK;
}
static fmi2Status ft_set_state(fmi2Component comp, fmi2FMUstate state) {
    if (!state) return fmi2Error;
    state_blob* s = state;
    return restore(comp, s->p, s->n);
}
static fmi2Status ft_free_state(fmi2Component comp, fmi2FMUstate* state) {
    (void)comp;
    if (state && *state) {
        free(((state_blob*)*state)->p);
        free(*state);
        *state = NULL;
    }
    return fmi2OK;
}
static fmi2Status ft_state_size(fmi2Component comp, fmi2FMUstate state, size_t* size) {
    (void)comp;
    *size = ((state_blob*)state)->n;
    return fmi2OK;
}
static fmi2Status ft_serialize(fmi2Component comp, fmi2FMUstate state, fmi2Byte out[],
                               size_t size) {
    state_blob* s = state;
    if (size < s->n) {
        logm(comp, fmi2Error, "logStatusError", "serialize: buffer of %zu bytes < %zu", size,
             s->n);
        return fmi2Error;
    }
    memcpy(out, s->p, s->n);
    return fmi2OK;
}
static fmi2Status ft_deserialize(fmi2Component comp, const fmi2Byte in[], size_t size,
                                 fmi2FMUstate* state) {
    (void)comp;
    state_blob* s = *state ? (state_blob*)*state : calloc(1, sizeof(state_blob));
    free(s->p);
    s->p = malloc(size ? size : 1);
    memcpy(s->p, in, size);
    s->n = size;
    *state = s;
    return fmi2OK;
}

static const ato_backend BACKEND = {
    "native C model " ATO_MODEL_IDENTIFIER, -1, 1,
    ft_instantiate, ft_free, ft_set_debug_logging,
    ft_setup, ft_enter_init, ft_exit_init, ft_terminate, ft_reset,
    ft_get_real, ft_get_integer, ft_get_boolean, ft_get_string,
    ft_set_real, ft_set_integer, ft_set_boolean, ft_set_string,
    ft_do_step,
    ft_get_state, ft_set_state, ft_free_state, ft_state_size, ft_serialize, ft_deserialize,
};

const ato_backend* ato_backend_get(char* error, size_t error_size) {
    (void)error; (void)error_size;
    return &BACKEND;
}
