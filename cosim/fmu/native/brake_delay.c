/*
 * brake_delay.c: native backend of BrakeDelayTrain, the C twin of plants/brake_delay.py
 * (seed 000, eqs. 1-7): first-order brake lag plus exact dead time, single-mass train.
 *
 *   da_c/dt = -a_c / tau + (1 / tau) a_t(t - Td),   a_t = -c u
 *   dv/dt   = a_c - a_r(v, s),   ds/dt = v,   a_r = (a + (b + c v) v) / m + g_scale g i(s) / 1000
 *
 * The same floating-point operations in the same order as the Python core (sub-steps on the
 * absolute integer-nanosecond grid of max_step, split where the delayed command changes; exact
 * ZOH lag; RK4 for v and s; grade changes and the stopping instant located by the same Newton
 * iterations), so with the same libm exp the results are equal bit for bit.
 *
 * It is an FMI 2-shaped backend (cosim/fmu/front/ato_backend.h): the FMI 2 front
 * (fmi2_front.c) or the FMI 3 front (fmi3_front.c) links it statically; its event_time_vr is
 * the generated ATO_EVENT_TIME_VR (-1: a plant has no events). Variables come from the generated
 * BrakeDelayTrain_decl.h. The route parameter names a bundled route whose grade steps the
 * build exported to resources/routes/<name>.grade ("start permille" lines, %.17g).
 */
#include <math.h>
#include <stdarg.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "ato_backend.h"
#include "ato_vars.h"
#include "BrakeDelayTrain_decl.h"

#define TICKS_PER_SECOND 1000000000LL
#define BEFORE_START (-(1LL << 62))
#define GRAVITY 9.81
#define STATE_MAGIC "ATO-BrakeDelayTrain-state-1"

typedef struct { int64_t tick; double value; } cmd;

typedef struct {
    /* parameters, fixed while the core lives */
    double mass, da, db, dc, gain, tau, grade_scale;
    int64_t delay_ticks, grid_ticks;
    int n_grade;
    double* starts; /* starts[0] = -inf */
    double* grades; /* permille */
    /* state */
    int64_t t_ticks;
    double a_c, v, s;
    int n_hist, cap_hist;
    cmd* hist;
} core;

typedef struct {
    char* name;
    fmi2CallbackFunctions cb;
    int logging_on;
    char* resources; /* directory path */
    double r[ATO_N_VARS];
    char* str[ATO_N_VARS];
    int initialized;
    int64_t start_ticks;
    long executions;
    int have_core;
    core c;
} inst;

static void logm(inst* m, fmi2Status status, const char* category, const char* fmt, ...) {
    char buf[1024];
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(buf, sizeof buf, fmt, ap);
    va_end(ap);
    /* the complete message as the format, '%' doubled: right for printf-style loggers and
     * for loggers that show the format as it is (fmpy) */
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
static double pymin(double a, double b) { return b < a ? b : a; }
static int64_t floordiv(int64_t a, int64_t b) {
    int64_t q = a / b;
    return (a % b != 0 && ((a < 0) != (b < 0))) ? q - 1 : q;
}

/* -- route ------------------------------------------------------------------------------ */
static int load_route(inst* m, core* c, const char* route) {
    for (const char* p = route; *p; p++)
        if (*p == '/' || *p == '\\' || *p == '.') {
            logm(m, fmi2Error, "logStatusError",
                 "bad parameter: route = '%s': the native FMU reads bundled routes only "
                 "(resources/routes/*.grade); a route file path needs the Python FMU", route);
            return 0;
        }
    size_t n = strlen(m->resources) + strlen(route) + 32;
    char* path = malloc(n);
    snprintf(path, n, "%s/routes/%s.grade", m->resources, route);
    FILE* f = fopen(path, "r");
    if (!f) {
        logm(m, fmi2Error, "logStatusError", "bad parameter: route '%s' not found (%s)", route,
             path);
        free(path);
        return 0;
    }
    int cap = 16, k = 0;
    c->starts = malloc(cap * sizeof(double));
    c->grades = malloc(cap * sizeof(double));
    char line[256];
    while (fgets(line, sizeof line, f)) {
        double a, b;
        if (line[0] == '#' || sscanf(line, "%lf %lf", &a, &b) != 2) continue;
        if (k == cap) {
            cap *= 2;
            c->starts = realloc(c->starts, cap * sizeof(double));
            c->grades = realloc(c->grades, cap * sizeof(double));
        }
        c->starts[k] = a;
        c->grades[k] = b;
        k++;
    }
    fclose(f);
    if (k == 0) {
        logm(m, fmi2Error, "logStatusError", "%s: no grade steps", path);
        free(path);
        return 0;
    }
    free(path);
    c->n_grade = k;
    return 1;
}

/* bisect_right(starts, s) */
static int bisect_right(const double* xs, int n, double s) {
    int lo = 0, hi = n;
    while (lo < hi) {
        int mid = (lo + hi) / 2;
        if (s < xs[mid]) hi = mid; else lo = mid + 1;
    }
    return lo;
}

static double grade_at(const core* c, double s) {
    return c->grades[bisect_right(c->starts, c->n_grade, s) - 1];
}
static double grade_accel(const core* c, double s) {
    return c->grade_scale * (GRAVITY * grade_at(c, s) / 1000.0);
}
static double next_grade_change(const core* c) {
    int i = bisect_right(c->starts, c->n_grade, c->s);
    return i < c->n_grade ? c->starts[i] : INFINITY;
}

/* -- dead time ---------------------------------------------------------------------------- */
static void record(core* c, int64_t tick, double value) {
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
static double delayed(const core* c, int64_t tick) {
    int64_t target = tick - c->delay_ticks;
    double value = c->hist[0].value;
    for (int i = 0; i < c->n_hist; i++) {
        if (c->hist[i].tick > target) break;
        value = c->hist[i].value;
    }
    return value;
}
static void prune(core* c, int64_t tick) {
    int64_t target = tick - c->delay_ticks;
    int drop = 0;
    while (c->n_hist - drop > 1 && c->hist[drop + 1].tick <= target) drop++;
    if (drop) {
        memmove(c->hist, c->hist + drop, (c->n_hist - drop) * sizeof(cmd));
        c->n_hist -= drop;
    }
}

/* -- physics ---------------------------------------------------------------------------- */
static double davis(const core* c, double v) { return c->da + (c->db + c->dc * v) * v; }
static double accel(const core* c, double a_c, double v, double g) {
    double a = a_c - davis(c, pymax(v, 0.0)) / c->mass - g;
    if (v <= 0.0 && a <= 0.0) return 0.0;
    return a;
}
static double lag(const core* c, double a_c0, double a_t, double dt) {
    return a_t + (a_c0 - a_t) * exp(-dt / c->tau);
}
static void rk4(const core* c, double a_t, double g, double h, double* v_out, double* s_out) {
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
static void substep(core* c, double h, double a_t) {
    double remaining = h;
    while (remaining > 0.0) {
        double g = grade_accel(c, c->s);
        double boundary = next_grade_change(c);
        double dt = remaining, v1, s1, unused;
        rk4(c, a_t, g, dt, &v1, &s1);
        if (s1 > boundary && c->v >= 0.0) {
            dt = remaining * (boundary - c->s) / (s1 - c->s);
            for (int i = 0; i < 4; i++) {
                rk4(c, a_t, g, dt, &v1, &s1);
                dt = pymin(pymax(dt - (s1 - boundary) / pymax(v1, 1e-9), 0.0), remaining);
            }
            rk4(c, a_t, g, dt, &v1, &unused);
            s1 = boundary;
        }
        if (v1 < 0.0) {
            dt = dt * c->v / (c->v - v1);
            for (int i = 0; i < 4; i++) {
                rk4(c, a_t, g, dt, &v1, &s1);
                double a1 = accel(c, lag(c, c->a_c, a_t, dt), pymax(v1, 1e-12), g);
                if (a1 >= 0.0) break;
                dt = pymin(pymax(dt - v1 / a1, 0.0), remaining);
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

static int cmp_i64(const void* a, const void* b) {
    int64_t x = *(const int64_t*)a, y = *(const int64_t*)b;
    return x < y ? -1 : x > y;
}

static int advance(inst* m, int64_t t, int64_t h, double u) {
    core* c = &m->c;
    if (t != c->t_ticks) {
        logm(m, fmi2Error, "logStatusError", "doStep at t=%.17g s but plant is at t=%.17g s",
             to_seconds(t), to_seconds(c->t_ticks));
        return 0;
    }
    record(c, t, u);
    int64_t end = t + h;
    int64_t first = (floordiv(t, c->grid_ticks) + 1) * c->grid_ticks;
    size_t n_grid = first < end ? (size_t)((end - 1 - first) / c->grid_ticks + 1) : 0;
    size_t cap = n_grid + (size_t)c->n_hist + 1, n = 0;
    int64_t* cuts = malloc(cap * sizeof(int64_t));
    cuts[n++] = end;
    for (int64_t k = first; k < end; k += c->grid_ticks) cuts[n++] = k;
    for (int i = 0; i < c->n_hist; i++) {
        int64_t act = c->hist[i].tick + c->delay_ticks;
        if (t < act && act < end) cuts[n++] = act;
    }
    qsort(cuts, n, sizeof(int64_t), cmp_i64);
    int64_t now = t;
    for (size_t i = 0; i < n; i++) {
        if (i > 0 && cuts[i] == cuts[i - 1]) continue; /* a set: each cut once */
        double a_t = -c->gain * delayed(c, now);
        substep(c, to_seconds(cuts[i] - now), a_t);
        now = cuts[i];
    }
    free(cuts);
    c->t_ticks = now;
    prune(c, now);
    return 1;
}

static void free_core(inst* m) {
    if (!m->have_core) return;
    free(m->c.starts);
    free(m->c.grades);
    free(m->c.hist);
    m->have_core = 0;
}

/* BrakeDelayTrain.__init__ with BrakeDelayParams.check: messages name the parameter */
static int ensure_core(inst* m) {
    if (m->have_core) return 1;
    const double* r = m->r;
    const char* positive[] = {"mass", "brake_time_constant", "max_step", "brake_gain"};
    const int vrs[] = {ATO_VR_mass, ATO_VR_brake_time_constant, ATO_VR_max_step,
                       ATO_VR_brake_gain};
    for (int i = 0; i < 4; i++)
        if (!(r[vrs[i]] > 0)) {
            logm(m, fmi2Error, "logStatusError", "bad parameter: %s = %.17g must be > 0",
                 positive[i], r[vrs[i]]);
            return 0;
        }
    if (!(r[ATO_VR_brake_delay] >= 0)) {
        logm(m, fmi2Error, "logStatusError", "bad parameter: brake_delay = %.17g must be >= 0",
             r[ATO_VR_brake_delay]);
        return 0;
    }
    if (r[ATO_VR_disturbance_amplitude] != 0.0) {
        logm(m, fmi2Error, "logStatusError", "bad parameter: disturbance_amplitude = %.17g: "
             "the native build has no disturbance (0 only; use the Python FMU)",
             r[ATO_VR_disturbance_amplitude]);
        return 0;
    }
    if (r[ATO_VR_v0] < 0) {
        logm(m, fmi2Error, "logStatusError", "bad parameter: v0 = %.17g must be >= 0",
             r[ATO_VR_v0]);
        return 0;
    }
    core* c = &m->c;
    memset(c, 0, sizeof *c);
    if (!load_route(m, c, m->str[ATO_VR_route])) {
        free(c->starts);
        free(c->grades);
        return 0;
    }
    c->mass = r[ATO_VR_mass];
    c->da = r[ATO_VR_davis_a];
    c->db = r[ATO_VR_davis_b];
    c->dc = r[ATO_VR_davis_c];
    c->gain = r[ATO_VR_brake_gain];
    c->tau = r[ATO_VR_brake_time_constant];
    c->grade_scale = r[ATO_VR_grade_scale];
    c->delay_ticks = to_ticks(r[ATO_VR_brake_delay]);
    c->grid_ticks = to_ticks(r[ATO_VR_max_step]);
    c->t_ticks = m->start_ticks;
    c->v = r[ATO_VR_v0];
    c->s = r[ATO_VR_s0];
    c->a_c = -c->gain * r[ATO_VR_initial_command];
    c->cap_hist = 8;
    c->n_hist = 1;
    c->hist = malloc(c->cap_hist * sizeof(cmd));
    c->hist[0].tick = BEFORE_START;
    c->hist[0].value = r[ATO_VR_initial_command];
    m->have_core = 1;
    return 1;
}

static double output(const inst* m, int vr) {
    const core* c = &m->c;
    switch (vr) {
    case ATO_VR_v: return c->v;
    case ATO_VR_s: return c->s;
    case ATO_VR_a: return accel(c, c->a_c, c->v, grade_accel(c, c->s));
    case ATO_VR_a_c: return c->a_c;
    case ATO_VR_applied_command: return delayed(c, c->t_ticks);
    case ATO_VR_grade: return c->grade_scale * grade_at(c, c->s);
    default: return NAN;
    }
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

static fmi2Component bd_instantiate(fmi2String name, fmi2Type type, fmi2String guid,
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
    for (int i = 0; i < ATO_N_VARS; i++) {
        m->r[i] = ATO_VARS[i].start;
        m->str[i] = ATO_VARS[i].type == ATO_STRING ? dup(ATO_VARS[i].start_string) : NULL;
    }
    return m;
}

static void bd_free(fmi2Component comp) {
    inst* m = comp;
    if (!m) return;
    free_core(m);
    for (int i = 0; i < ATO_N_VARS; i++) free(m->str[i]);
    free(m->resources);
    free(m->name);
    free(m);
}

static fmi2Status bd_set_debug_logging(fmi2Component comp, fmi2Boolean on, size_t n,
                                       const fmi2String cats[]) {
    (void)n; (void)cats;
    ((inst*)comp)->logging_on = on;
    return fmi2OK;
}

static fmi2Status bd_setup(fmi2Component comp, fmi2Boolean tol_defined, fmi2Real tol,
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

static fmi2Status bd_enter_init(fmi2Component comp) {
    ((inst*)comp)->initialized = 0;
    return fmi2OK;
}

static fmi2Status bd_exit_init(fmi2Component comp) {
    inst* m = comp;
    if (!ensure_core(m)) return fmi2Error;
    m->initialized = 1;
    return fmi2OK;
}

static fmi2Status bd_terminate(fmi2Component comp) { (void)comp; return fmi2OK; }

static fmi2Status bd_reset(fmi2Component comp) {
    inst* m = comp;
    free_core(m);
    for (int i = 0; i < ATO_N_VARS; i++) {
        m->r[i] = ATO_VARS[i].start;
        if (ATO_VARS[i].type == ATO_STRING) {
            free(m->str[i]);
            m->str[i] = dup(ATO_VARS[i].start_string);
        }
    }
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

static fmi2Status bd_get_real(fmi2Component comp, const fmi2ValueReference vr[], size_t n,
                              fmi2Real value[]) {
    inst* m = comp;
    for (size_t i = 0; i < n; i++) {
        if (!check_vr(m, vr[i], ATO_REAL, "fmi2GetReal")) return fmi2Error;
        if (ATO_VARS[vr[i]].causality == ATO_OUTPUT) {
            if (!ensure_core(m)) return fmi2Error;
            value[i] = output(m, (int)vr[i]);
        } else {
            value[i] = m->r[vr[i]];
        }
    }
    return fmi2OK;
}

static fmi2Status bd_set_real(fmi2Component comp, const fmi2ValueReference vr[], size_t n,
                              const fmi2Real value[]) {
    inst* m = comp;
    for (size_t i = 0; i < n; i++) {
        if (!check_vr(m, vr[i], ATO_REAL, "fmi2SetReal")) return fmi2Error;
        const ato_var* v = &ATO_VARS[vr[i]];
        if (v->causality == ATO_OUTPUT) {
            logm(m, fmi2Error, "logStatusError", "fmi2SetReal: %s is an output", v->name);
            return fmi2Error;
        }
        if (v->causality == ATO_PARAMETER && m->initialized) {
            logm(m, fmi2Error, "logStatusError",
                 "fmi2SetReal: parameter '%s' is fixed after initialisation", v->name);
            return fmi2Error;
        }
        if (!isfinite(value[i])) {
            logm(m, fmi2Error, "logStatusError", "fmi2SetReal: %s = %g: not a finite number",
                 v->name, value[i]);
            return fmi2Error;
        }
        if (v->causality == ATO_PARAMETER && ((v->has_min && value[i] < v->min) ||
                                              (v->has_max && value[i] > v->max))) {
            logm(m, fmi2Error, "logStatusError", "fmi2SetReal: %s = %.17g outside [%g, %g]",
                 v->name, value[i], v->has_min ? v->min : -INFINITY,
                 v->has_max ? v->max : INFINITY);
            return fmi2Error;
        }
        m->r[vr[i]] = value[i];
        if (v->causality == ATO_PARAMETER) free_core(m);
    }
    return fmi2OK;
}

static fmi2Status bd_get_string(fmi2Component comp, const fmi2ValueReference vr[], size_t n,
                                fmi2String value[]) {
    inst* m = comp;
    for (size_t i = 0; i < n; i++) {
        if (!check_vr(m, vr[i], ATO_STRING, "fmi2GetString")) return fmi2Error;
        value[i] = m->str[vr[i]];
    }
    return fmi2OK;
}

static fmi2Status bd_set_string(fmi2Component comp, const fmi2ValueReference vr[], size_t n,
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

static fmi2Status no_vars(inst* m, const char* call, size_t n) {
    if (n == 0) return fmi2OK;
    logm(m, fmi2Error, "logStatusError", "%s: this FMU has no such variables", call);
    return fmi2Error;
}
/* Integer variables (parameters only: disturbance_seed) are kept as doubles in m->r */
static fmi2Status bd_get_integer(fmi2Component comp, const fmi2ValueReference vr[], size_t n,
                                 fmi2Integer value[]) {
    inst* m = comp;
    for (size_t i = 0; i < n; i++) {
        if (!check_vr(m, vr[i], ATO_INTEGER, "fmi2GetInteger")) return fmi2Error;
        value[i] = (fmi2Integer)m->r[vr[i]];
    }
    return fmi2OK;
}
static fmi2Status bd_set_integer(fmi2Component comp, const fmi2ValueReference vr[], size_t n,
                                 const fmi2Integer value[]) {
    inst* m = comp;
    for (size_t i = 0; i < n; i++) {
        if (!check_vr(m, vr[i], ATO_INTEGER, "fmi2SetInteger")) return fmi2Error;
        if (m->initialized) {
            logm(m, fmi2Error, "logStatusError",
                 "fmi2SetInteger: parameter '%s' is fixed after initialisation",
                 ATO_VARS[vr[i]].name);
            return fmi2Error;
        }
        m->r[vr[i]] = (double)value[i];
        free_core(m);
    }
    return fmi2OK;
}
static fmi2Status bd_get_boolean(fmi2Component c, const fmi2ValueReference vr[], size_t n,
                                 fmi2Boolean v[]) {
    (void)vr; (void)v;
    return no_vars(c, "fmi2GetBoolean", n);
}
static fmi2Status bd_set_boolean(fmi2Component c, const fmi2ValueReference vr[], size_t n,
                                 const fmi2Boolean v[]) {
    (void)vr; (void)v;
    return no_vars(c, "fmi2SetBoolean", n);
}

static fmi2Status bd_do_step(fmi2Component comp, fmi2Real t, fmi2Real h, fmi2Boolean no_set) {
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
    if (!advance(m, to_ticks(t), to_ticks(h), m->r[ATO_VR_brake_command])) return fmi2Error;
    m->executions++;
    return fmi2OK;
}

/* -- FMU state: a byte image (magic, values, strings, core) --------------------------------- */
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
        put(&b, &c->t_ticks, sizeof c->t_ticks);
        put(&b, &c->a_c, sizeof c->a_c);
        put(&b, &c->v, sizeof c->v);
        put(&b, &c->s, sizeof c->s);
        int32_t nh = c->n_hist;
        put(&b, &nh, sizeof nh);
        put(&b, c->hist, (size_t)nh * sizeof(cmd));
    }
    return b;
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
        logm(m, fmi2Error, "logStatusError", "truncated FMU state");
        return fmi2Error;
    }
    free_core(m);
    memcpy(m->r, values, sizeof values);
    for (int i = 0; i < ATO_N_VARS; i++)
        if (ATO_VARS[i].type == ATO_STRING) { free(m->str[i]); m->str[i] = strs[i]; }
    m->start_ticks = start;
    m->executions = (long)ex;
    m->initialized = 0;
    if (flags[1]) {
        if (!ensure_core(m)) return fmi2Error;
        core* c = &m->c;
        int32_t nh = 0;
        take(&r, &c->t_ticks, sizeof c->t_ticks);
        take(&r, &c->a_c, sizeof c->a_c);
        take(&r, &c->v, sizeof c->v);
        take(&r, &c->s, sizeof c->s);
        take(&r, &nh, sizeof nh);
        if (!r.ok || nh < 1 || (size_t)nh * sizeof(cmd) > n) {
            logm(m, fmi2Error, "logStatusError", "truncated FMU state");
            return fmi2Error;
        }
        c->cap_hist = nh;
        c->hist = realloc(c->hist, (size_t)nh * sizeof(cmd));
        c->n_hist = nh;
        take(&r, c->hist, (size_t)nh * sizeof(cmd));
        if (!r.ok) {
            logm(m, fmi2Error, "logStatusError", "truncated FMU state");
            return fmi2Error;
        }
    }
    m->initialized = flags[0];
    return fmi2OK;
}

typedef struct { size_t n; unsigned char* p; } state_blob;

static fmi2Status bd_get_state(fmi2Component comp, fmi2FMUstate* state) {
    inst* m = comp;
    buf b = image(m);
    state_blob* s = *state ? (state_blob*)*state : calloc(1, sizeof(state_blob));
    free(s->p);
    s->p = b.p;
    s->n = b.n;
    *state = s;
    return fmi2OK;
}
static fmi2Status bd_set_state(fmi2Component comp, fmi2FMUstate state) {
    if (!state) return fmi2Error;
    state_blob* s = state;
    return restore(comp, s->p, s->n);
}
static fmi2Status bd_free_state(fmi2Component comp, fmi2FMUstate* state) {
    (void)comp;
    if (state && *state) {
        free(((state_blob*)*state)->p);
        free(*state);
        *state = NULL;
    }
    return fmi2OK;
}
static fmi2Status bd_state_size(fmi2Component comp, fmi2FMUstate state, size_t* size) {
    (void)comp;
    *size = ((state_blob*)state)->n;
    return fmi2OK;
}
static fmi2Status bd_serialize(fmi2Component comp, fmi2FMUstate state, fmi2Byte out[],
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
static fmi2Status bd_deserialize(fmi2Component comp, const fmi2Byte in[], size_t size,
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
    "native C model " ATO_MODEL_IDENTIFIER, ATO_EVENT_TIME_VR, 1,
    bd_instantiate, bd_free, bd_set_debug_logging,
    bd_setup, bd_enter_init, bd_exit_init, bd_terminate, bd_reset,
    bd_get_real, bd_get_integer, bd_get_boolean, bd_get_string,
    bd_set_real, bd_set_integer, bd_set_boolean, bd_set_string,
    bd_do_step,
    bd_get_state, bd_set_state, bd_free_state, bd_state_size, bd_serialize, bd_deserialize,
};

const ato_backend* ato_backend_get(char* error, size_t error_size) {
    (void)error; (void)error_size;
    return &BACKEND;
}
