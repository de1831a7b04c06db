/*
 * ato_controller.c: native backend of a sampled controller FMU, the C twin of
 * cosim/fmu/slave.py's SampledControllerSlave (and CoreSlave) over one online law (ato_law.h).
 *
 * Timing contract (the same as the Python FMUs'; times in integer nanoseconds, so k T never
 * drifts):
 *  - an event is due when the controller's time has reached next_event_time and the event of
 *    this instant has not been committed; reading an output then computes the event from the
 *    current inputs without committing it (inputs set again at the same instant give the
 *    outputs of the new inputs); doStep commits the event computed from the inputs it is
 *    given;
 *  - the event after one at the grid instant k is at k + hold sample_time (hold from the law);
 *    outputs hold between events; next_event_time and executions announce them;
 *  - doStep must continue from the controller's time; a step longer than the time to the next
 *    event executes every event inside it with the inputs held at the step's start (said once
 *    with fmi2Warning); with strict_steps such a step is refused with fmi2Error naming the
 *    event;
 *  - the FMU state is complete: values, timing, shown outputs and the law's committed state.
 *
 * Variables come from the generated <id>_decl.h (the Python FMU's declarations).
 */
#include <math.h>
#include <stdarg.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "ato_backend.h"
#include "ato_law.h"
#include "ato_vars.h"
#include "ato_model.h" /* generated: includes <id>_decl.h */

#define STATE_MAGIC "ATO-" ATO_MODEL_IDENTIFIER "-controller-state-1"

typedef struct {
    char* name;
    fmi2CallbackFunctions cb;
    int logging_on;
    char* resources;
    double v[ATO_N_VARS];   /* parameters and inputs */
    char* str[ATO_N_VARS];  /* String parameters */
    double out[ATO_N_VARS]; /* outputs shown */
    int initialized;
    int64_t start_ticks, now, next;
    int64_t done; /* instant of the last committed event, if has_done */
    int has_done;
    long executions;
    law_core* core;
    size_t state_size;
    unsigned char* committed; /* scratch: the law's state before a tentative event */
    /* the event computed on a read and not committed */
    int tent_valid, tent_hold;
    int64_t tent_now;
    double tent_in[ATO_N_VARS];
    double tent_out[ATO_N_VARS];
    unsigned char* tent_after;
    /* (now, input serial) of the tentative event the outputs show */
    long serial;
    int shown_valid;
    int64_t shown_now;
    long shown_serial;
    int held_logged;
} inst;

static void logm(inst* m, fmi2Status status, const char* fmt, ...) {
    char buf[1200];
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(buf, sizeof buf, fmt, ap);
    va_end(ap);
    /* the complete message as the format, '%' doubled (see brake_delay.c) */
    char esc[2400];
    size_t k = 0;
    for (const char* p = buf; *p && k + 2 < sizeof esc; p++) {
        if (*p == '%') esc[k++] = '%';
        esc[k++] = *p;
    }
    esc[k] = 0;
    if (m->cb.logger && (status != fmi2OK || m->logging_on))
        m->cb.logger(m->cb.componentEnvironment, m->name, status,
                     status == fmi2Warning ? "logStatusWarning" : "logStatusError", esc);
}

static int64_t to_ticks(double seconds) { return (int64_t)llrint(seconds * 1e9); }
static double to_seconds(int64_t ticks) { return (double)ticks / 1e9; }

/* the shortest decimal that reads back as x, laid out as Python's repr: fixed notation for
 * decimal exponents -4 .. 15 (with ".0" for a whole number), else d.ddde+XX */
typedef struct { char s[40]; } num;
static num fmt(double x) {
    num out;
    if (!isfinite(x)) {
        snprintf(out.s, sizeof out.s, "%s", isnan(x) ? "nan" : x > 0 ? "inf" : "-inf");
        return out;
    }
    char e[40];
    int digits = 1;
    for (; digits < 17; digits++) {
        snprintf(e, sizeof e, "%.*e", digits - 1, x);
        if (strtod(e, NULL) == x) break;
    }
    snprintf(e, sizeof e, "%.*e", digits - 1, x);
    char* ep = strchr(e, 'e');
    int exp10 = atoi(ep + 1);
    *ep = 0;
    char mant[24];
    int k = 0;
    for (const char* q = e; *q; q++)
        if (*q >= '0' && *q <= '9') mant[k++] = *q;
    mant[k] = 0;
    while (k > 1 && mant[k - 1] == '0') mant[--k] = 0; /* trailing zeros of the digits */
    const char* sign = signbit(x) ? "-" : "";
    if (exp10 < -4 || exp10 >= 16) {
        snprintf(out.s, sizeof out.s, "%s%c%s%s%se%c%02d", sign, mant[0], k > 1 ? "." : "",
                 mant + 1, "", exp10 < 0 ? '-' : '+', abs(exp10));
        return out;
    }
    char body[40];
    int at = 0;
    if (exp10 < 0) {
        at += snprintf(body + at, sizeof body - at, "0.");
        for (int i = 0; i < -exp10 - 1; i++) body[at++] = '0';
        at += snprintf(body + at, sizeof body - at, "%s", mant);
    } else {
        for (int i = 0; i <= exp10; i++) body[at++] = i < k ? mant[i] : '0';
        body[at++] = '.';
        if (exp10 + 1 < k) at += snprintf(body + at, sizeof body - at, "%s", mant + exp10 + 1);
        else body[at++] = '0';
    }
    body[at] = 0;
    snprintf(out.s, sizeof out.s, "%s%s", sign, body);
    return out;
}

const char* ato_repr(double x, char buf[40]) {
    num n = fmt(x);
    memcpy(buf, n.s, sizeof n.s);
    return buf;
}

static char* dup(const char* s) {
    char* d = malloc(strlen(s) + 1);
    strcpy(d, s);
    return d;
}

static ato_values values_of(inst* m) {
    ato_values p = {m->v, m->str, m->resources};
    return p;
}

/* -- core and timing ------------------------------------------------------------------------ */
static void free_core(inst* m) {
    if (!m->core) return;
    law_free(m->core);
    m->core = NULL;
    free(m->committed);
    free(m->tent_after);
    m->committed = m->tent_after = NULL;
    m->tent_valid = 0;
}

static int64_t sample_ticks(const inst* m) { return to_ticks(m->v[ATO_VR_sample_time]); }

static void show(inst* m, const double* outputs, int64_t next_event, long executions) {
    if (outputs)
        for (int i = 0; i < ATO_N_VARS; i++)
            if (ATO_VARS[i].causality == ATO_OUTPUT && i != ATO_VR_next_event_time &&
                i != ATO_VR_executions)
                m->out[i] = outputs[i];
    m->out[ATO_VR_next_event_time] = to_seconds(next_event);
    m->out[ATO_VR_executions] = (double)executions;
}

/* check_declared (cosim/fmu/declare.py) for the declared ranges of the generated table: the
 * first parameter outside its [min, max]; NULL when all keep them */
static int declared_ranges_hold(inst* m, char* err, size_t n) {
    for (int i = 0; i < ATO_N_VARS; i++) {
        const ato_var* v = &ATO_VARS[i];
        if (v->causality != ATO_PARAMETER || v->type == ATO_STRING || v->type == ATO_BOOLEAN)
            continue;
        double x = m->v[i];
        int low = v->has_min && !(x >= v->min), high = v->has_max && !(x <= v->max);
        if (low || high) {
            snprintf(err, n, "%s = %s: must be at %s %s", v->name, fmt(x).s,
                     low ? "least" : "most", fmt(low ? v->min : v->max).s);
            return 0;
        }
    }
    return 1;
}

static int ensure_core(inst* m) {
    if (m->core) return 1;
    char err[1024] = "";
    if (!declared_ranges_hold(m, err, sizeof err)) {
        logm(m, fmi2Error, "%s: bad parameter: %s", m->name, err);
        return 0;
    }
    ato_values p = values_of(m);
    m->core = law_make(&p, to_seconds(m->start_ticks), err, sizeof err);
    if (!m->core) {
        logm(m, fmi2Error, "%s: bad parameter: %s", m->name, err);
        return 0;
    }
    m->state_size = law_state_size(m->core);
    m->committed = malloc(m->state_size ? m->state_size : 1);
    m->tent_after = malloc(m->state_size ? m->state_size : 1);
    m->tent_valid = 0;
    law_outputs(m->core, m->out);
    show(m, NULL, m->next, m->executions);
    return 1;
}

static int event_due(const inst* m) {
    return m->now >= m->next && !(m->has_done && m->done == m->now);
}

/* the scheduled event being run at now (the sampling grid is kept if late) */
static int64_t grid_event(const inst* m) {
    int64_t event = m->next, period = sample_ticks(m);
    while (event + period <= m->now) event += period;
    return event;
}

static int inputs_equal(const inst* m) {
    for (int i = 0; i < ATO_N_VARS; i++)
        if (ATO_VARS[i].causality == ATO_INPUT && !(m->v[i] == m->tent_in[i])) return 0;
    return 1;
}

/* the due event computed from the current inputs, not committed (the law's state is put back) */
static int compute_tentative(inst* m) {
    if (m->tent_valid && m->tent_now == m->now && inputs_equal(m)) return 1;
    char err[1024] = "";
    ato_values p = values_of(m);
    law_get_state(m->core, m->committed);
    int hold = law_compute(m->core, to_seconds(m->now), &p, m->tent_out, err, sizeof err);
    if (hold <= 0) {
        law_set_state(m->core, m->committed);
        m->tent_valid = 0;
        logm(m, fmi2Error, "%s: %s", m->name, err);
        return 0;
    }
    law_get_state(m->core, m->tent_after);
    law_set_state(m->core, m->committed);
    memcpy(m->tent_in, m->v, sizeof m->v);
    m->tent_now = m->now;
    m->tent_hold = hold;
    m->tent_valid = 1;
    return 1;
}

static int refresh_outputs(inst* m) {
    if (!(m->initialized && event_due(m))) return 1;
    if (m->tent_valid && m->shown_valid && m->shown_now == m->now &&
        m->shown_serial == m->serial)
        return 1;
    if (!compute_tentative(m)) return 0;
    show(m, m->tent_out, grid_event(m) + m->tent_hold * sample_ticks(m), m->executions + 1);
    m->shown_valid = 1;
    m->shown_now = m->now;
    m->shown_serial = m->serial;
    return 1;
}

/* -- FMI 2-shaped functions ------------------------------------------------------------------ */
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

static void set_starts(inst* m) {
    for (int i = 0; i < ATO_N_VARS; i++) {
        m->v[i] = ATO_VARS[i].start;
        m->out[i] = ATO_VARS[i].start;
        if (ATO_VARS[i].type == ATO_STRING) {
            free(m->str[i]);
            m->str[i] = dup(ATO_VARS[i].start_string);
        }
    }
}

static fmi2Component c_instantiate(fmi2String name, fmi2Type type, fmi2String guid,
                                   fmi2String resources, const fmi2CallbackFunctions* cb,
                                   fmi2Boolean visible, fmi2Boolean logging_on) {
    (void)visible;
    inst tmp;
    memset(&tmp, 0, sizeof tmp);
    tmp.name = (char*)(name ? name : "?");
    if (cb) tmp.cb = *cb;
    if (type != fmi2CoSimulation) {
        logm(&tmp, fmi2Error, "%s: only co-simulation is supported", ATO_MODEL_IDENTIFIER);
        return NULL;
    }
    if (!guid || strcmp(guid, ATO_GUID) != 0) {
        logm(&tmp, fmi2Error, "fmi2Instantiate: GUID %s does not match this binary's %s",
             guid ? guid : "(null)", ATO_GUID);
        return NULL;
    }
    char* res = uri_to_path(resources);
    if (!res) {
        logm(&tmp, fmi2Error, "fmi2Instantiate: resource location '%s' is not a file URI",
             resources ? resources : "(null)");
        return NULL;
    }
    inst* m = calloc(1, sizeof(inst));
    m->name = dup(tmp.name);
    m->cb = tmp.cb;
    m->logging_on = logging_on;
    m->resources = res;
    set_starts(m);
    return m;
}

static void c_free(fmi2Component comp) {
    inst* m = comp;
    if (!m) return;
    free_core(m);
    for (int i = 0; i < ATO_N_VARS; i++) free(m->str[i]);
    free(m->resources);
    free(m->name);
    free(m);
}

static fmi2Status c_set_debug_logging(fmi2Component comp, fmi2Boolean on, size_t n,
                                      const fmi2String cats[]) {
    (void)n; (void)cats;
    ((inst*)comp)->logging_on = on;
    return fmi2OK;
}

static fmi2Status c_setup(fmi2Component comp, fmi2Boolean tol_defined, fmi2Real tol,
                          fmi2Real start, fmi2Boolean stop_defined, fmi2Real stop) {
    (void)tol_defined; (void)tol; (void)stop_defined; (void)stop;
    inst* m = comp;
    if (!isfinite(start)) {
        logm(m, fmi2Error, "start time %g is not finite", start);
        return fmi2Error;
    }
    m->start_ticks = m->now = m->next = to_ticks(start);
    m->has_done = 0;
    m->tent_valid = 0;
    return fmi2OK;
}

static fmi2Status c_enter_init(fmi2Component comp) {
    ((inst*)comp)->initialized = 0;
    return fmi2OK;
}

static fmi2Status c_exit_init(fmi2Component comp) {
    inst* m = comp;
    if (!ensure_core(m)) return fmi2Error;
    m->initialized = 1;
    return fmi2OK;
}

static fmi2Status c_terminate(fmi2Component comp) { (void)comp; return fmi2OK; }

static fmi2Status c_reset(fmi2Component comp) {
    inst* m = comp;
    free_core(m);
    set_starts(m);
    m->initialized = 0;
    m->start_ticks = m->now = m->next = 0;
    m->has_done = 0;
    m->executions = 0;
    m->shown_valid = 0;
    m->held_logged = 0;
    return fmi2OK;
}

static int check_vr(inst* m, fmi2ValueReference vr, int type, const char* call) {
    if (vr >= ATO_N_VARS || ATO_VARS[vr].type != type) {
        logm(m, fmi2Error, "%s: no variable of this type with value reference %u", call,
             (unsigned)vr);
        return 0;
    }
    return 1;
}

/* value of a Real, Integer or Boolean variable (outputs made current first) */
static int get_value(inst* m, fmi2ValueReference vr, int type, const char* call, double* out) {
    if (!check_vr(m, vr, type, call)) return 0;
    if (ATO_VARS[vr].causality == ATO_OUTPUT) {
        if (!ensure_core(m) || !refresh_outputs(m)) return 0;
        *out = m->out[vr];
    } else {
        *out = m->v[vr];
    }
    return 1;
}

/* CoreSlave's setter: parameters fixed after initialisation, finite Reals, parameter ranges */
static int set_value(inst* m, fmi2ValueReference vr, int type, const char* call, double value) {
    if (!check_vr(m, vr, type, call)) return 0;
    const ato_var* v = &ATO_VARS[vr];
    if (v->causality == ATO_OUTPUT) {
        logm(m, fmi2Error, "%s: %s is an output", call, v->name);
        return 0;
    }
    if (v->causality == ATO_PARAMETER && m->initialized) {
        logm(m, fmi2Error, "%s: parameter '%s' is fixed after initialisation", call, v->name);
        return 0;
    }
    if (type == ATO_REAL && !isfinite(value)) {
        logm(m, fmi2Error, "%s: %s = %g: not a finite number", call, v->name, value);
        return 0;
    }
    if (v->causality == ATO_PARAMETER && ((v->has_min && value < v->min) ||
                                          (v->has_max && value > v->max))) {
        logm(m, fmi2Error, "%s: %s = %s outside [%s, %s]", call, v->name, fmt(value).s,
             fmt(v->has_min ? v->min : -INFINITY).s, fmt(v->has_max ? v->max : INFINITY).s);
        return 0;
    }
    m->v[vr] = value;
    if (v->causality == ATO_PARAMETER) free_core(m);
    else m->serial++;
    return 1;
}

static fmi2Status c_get_real(fmi2Component comp, const fmi2ValueReference vr[], size_t n,
                             fmi2Real value[]) {
    for (size_t i = 0; i < n; i++)
        if (!get_value(comp, vr[i], ATO_REAL, "fmi2GetReal", &value[i])) return fmi2Error;
    return fmi2OK;
}
static fmi2Status c_get_integer(fmi2Component comp, const fmi2ValueReference vr[], size_t n,
                                fmi2Integer value[]) {
    for (size_t i = 0; i < n; i++) {
        double x;
        if (!get_value(comp, vr[i], ATO_INTEGER, "fmi2GetInteger", &x)) return fmi2Error;
        value[i] = (fmi2Integer)x;
    }
    return fmi2OK;
}
static fmi2Status c_get_boolean(fmi2Component comp, const fmi2ValueReference vr[], size_t n,
                                fmi2Boolean value[]) {
    for (size_t i = 0; i < n; i++) {
        double x;
        if (!get_value(comp, vr[i], ATO_BOOLEAN, "fmi2GetBoolean", &x)) return fmi2Error;
        value[i] = x != 0.0 ? fmi2True : fmi2False;
    }
    return fmi2OK;
}
static fmi2Status c_set_real(fmi2Component comp, const fmi2ValueReference vr[], size_t n,
                             const fmi2Real value[]) {
    for (size_t i = 0; i < n; i++)
        if (!set_value(comp, vr[i], ATO_REAL, "fmi2SetReal", value[i])) return fmi2Error;
    return fmi2OK;
}
static fmi2Status c_set_integer(fmi2Component comp, const fmi2ValueReference vr[], size_t n,
                                const fmi2Integer value[]) {
    for (size_t i = 0; i < n; i++)
        if (!set_value(comp, vr[i], ATO_INTEGER, "fmi2SetInteger", (double)value[i]))
            return fmi2Error;
    return fmi2OK;
}
static fmi2Status c_set_boolean(fmi2Component comp, const fmi2ValueReference vr[], size_t n,
                                const fmi2Boolean value[]) {
    for (size_t i = 0; i < n; i++)
        if (!set_value(comp, vr[i], ATO_BOOLEAN, "fmi2SetBoolean", value[i] ? 1.0 : 0.0))
            return fmi2Error;
    return fmi2OK;
}

static fmi2Status c_get_string(fmi2Component comp, const fmi2ValueReference vr[], size_t n,
                               fmi2String value[]) {
    inst* m = comp;
    for (size_t i = 0; i < n; i++) {
        if (!check_vr(m, vr[i], ATO_STRING, "fmi2GetString")) return fmi2Error;
        value[i] = m->str[vr[i]];
    }
    return fmi2OK;
}

static fmi2Status c_set_string(fmi2Component comp, const fmi2ValueReference vr[], size_t n,
                               const fmi2String value[]) {
    inst* m = comp;
    for (size_t i = 0; i < n; i++) {
        if (!check_vr(m, vr[i], ATO_STRING, "fmi2SetString")) return fmi2Error;
        if (m->initialized) {
            logm(m, fmi2Error, "fmi2SetString: parameter '%s' is fixed after initialisation",
                 ATO_VARS[vr[i]].name);
            return fmi2Error;
        }
        free(m->str[vr[i]]);
        m->str[vr[i]] = dup(value[i] ? value[i] : "");
        free_core(m);
    }
    return fmi2OK;
}

static fmi2Status c_do_step(fmi2Component comp, fmi2Real t, fmi2Real h, fmi2Boolean no_set) {
    (void)no_set;
    inst* m = comp;
    if (!ensure_core(m)) return fmi2Error;
    if (!(h > 0.0) || !isfinite(h)) {
        logm(m, fmi2Error, "doStep: step size %g must be positive and finite", h);
        return fmi2Error;
    }
    if (!isfinite(t) || to_ticks(t) != m->now) {
        logm(m, fmi2Error, "doStep at t=%s s, but this controller is at t=%s s (a step must "
             "continue from the end of the previous one)", fmt(t).s, fmt(to_seconds(m->now)).s);
        return fmi2Error;
    }
    int64_t end = to_ticks(t + h);
    for (;;) { /* each event in [now, end): those after the first with the inputs held */
        int due = event_due(m);
        int64_t following;
        if (due) {
            if (!compute_tentative(m)) return fmi2Error;
            following = grid_event(m) + m->tent_hold * sample_ticks(m);
        } else {
            following = m->next;
        }
        if (following < end && m->v[ATO_VR_strict_steps] != 0.0) {
            logm(m, fmi2Error, "%s: doStep from t=%s s to t=%s s passes over this "
                 "controller's event at t=%s s (sample_time %s s) and strict_steps is true: "
                 "use communication steps that end on its sample instants (at most "
                 "sample_time long)", m->name, fmt(t).s, fmt(to_seconds(end)).s,
                 fmt(to_seconds(following)).s, fmt(m->v[ATO_VR_sample_time]).s);
            return fmi2Error;
        }
        if (due) { /* commit the event computed from the inputs of this doStep */
            m->next = following;
            m->done = m->now;
            m->has_done = 1;
            m->executions++;
            show(m, m->tent_out, following, m->executions);
            law_set_state(m->core, m->tent_after);
            m->tent_valid = 0;
        }
        if (following >= end) break;
        if (!m->held_logged) {
            m->held_logged = 1;
            logm(m, fmi2Warning, "%s: doStep from t=%s s to t=%s s passes over this "
                 "controller's event at t=%s s (sample_time %s s): its events inside a step "
                 "are executed with the inputs held at the step's start (said once; "
                 "strict_steps = true refuses such steps)", m->name, fmt(t).s,
                 fmt(to_seconds(end)).s, fmt(to_seconds(following)).s,
                 fmt(m->v[ATO_VR_sample_time]).s);
        }
        m->now = following;
    }
    m->now = end;
    return fmi2OK;
}

/* -- FMU state: a byte image ---------------------------------------------------------------- */
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

static int image(inst* m, buf* b) {
    if (!ensure_core(m)) return 0;
    put(b, STATE_MAGIC, sizeof STATE_MAGIC);
    put(b, m->v, sizeof m->v);
    for (int i = 0; i < ATO_N_VARS; i++)
        if (ATO_VARS[i].type == ATO_STRING) {
            uint64_t len = strlen(m->str[i]);
            put(b, &len, sizeof len);
            put(b, m->str[i], len);
        }
    put(b, m->out, sizeof m->out);
    int32_t flags[2] = {m->initialized, m->has_done};
    put(b, flags, sizeof flags);
    int64_t ticks[4] = {m->start_ticks, m->now, m->next, m->done};
    put(b, ticks, sizeof ticks);
    int64_t ex = m->executions;
    put(b, &ex, sizeof ex);
    uint64_t size = m->state_size;
    put(b, &size, sizeof size);
    law_get_state(m->core, m->committed); /* the committed state: the core holds no other */
    put(b, m->committed, m->state_size);
    return 1;
}

static int same_parameters(const inst* m, const double* v, char* const* str) {
    for (int i = 0; i < ATO_N_VARS; i++) {
        if (ATO_VARS[i].causality != ATO_PARAMETER) continue;
        if (ATO_VARS[i].type == ATO_STRING ? strcmp(m->str[i], str[i]) != 0 : !(m->v[i] == v[i]))
            return 0;
    }
    return 1;
}

static fmi2Status restore(inst* m, const unsigned char* data, size_t n) {
    rd r = {data, n, 0, 1};
    char magic[sizeof STATE_MAGIC];
    take(&r, magic, sizeof magic);
    if (!r.ok || memcmp(magic, STATE_MAGIC, sizeof magic) != 0) {
        logm(m, fmi2Error, "state does not belong to FMU %s", ATO_MODEL_IDENTIFIER);
        return fmi2Error;
    }
    double values[ATO_N_VARS], outs[ATO_N_VARS];
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
    take(&r, outs, sizeof outs);
    int32_t flags[2];
    int64_t ticks[4], ex;
    uint64_t size = 0;
    take(&r, flags, sizeof flags);
    take(&r, ticks, sizeof ticks);
    take(&r, &ex, sizeof ex);
    take(&r, &size, sizeof size);
    const unsigned char* core_bytes = r.ok && r.at + size <= n ? data + r.at : NULL;
    if (!core_bytes) {
        for (int i = 0; i < ATO_N_VARS; i++) free(strs[i]);
        logm(m, fmi2Error, "truncated FMU state");
        return fmi2Error;
    }
    int keep = m->core && same_parameters(m, values, strs);
    memcpy(m->v, values, sizeof values);
    for (int i = 0; i < ATO_N_VARS; i++)
        if (ATO_VARS[i].type == ATO_STRING) { free(m->str[i]); m->str[i] = strs[i]; }
    m->start_ticks = ticks[0];
    m->now = ticks[1];
    m->next = ticks[2];
    m->done = ticks[3];
    m->has_done = flags[1];
    m->executions = (long)ex;
    if (!keep) {
        free_core(m);
        m->initialized = 0;
        if (!ensure_core(m)) return fmi2Error;
    }
    if (size != m->state_size) {
        logm(m, fmi2Error, "FMU state: %llu bytes of controller state, this core has %zu",
             (unsigned long long)size, m->state_size);
        return fmi2Error;
    }
    law_set_state(m->core, core_bytes);
    memcpy(m->out, outs, sizeof outs);
    m->tent_valid = 0;
    m->shown_valid = 0;
    m->initialized = flags[0];
    return fmi2OK;
}

typedef struct { size_t n; unsigned char* p; } state_blob;

static fmi2Status c_get_state(fmi2Component comp, fmi2FMUstate* state) {
    buf b = {0};
    if (!image(comp, &b)) { free(b.p); return fmi2Error; }
    state_blob* s = *state ? (state_blob*)*state : calloc(1, sizeof(state_blob));
    free(s->p);
    s->p = b.p;
    s->n = b.n;
    *state = s;
    return fmi2OK;
}
static fmi2Status c_set_state(fmi2Component comp, fmi2FMUstate state) {
    if (!state) return fmi2Error;
    state_blob* s = state;
    return restore(comp, s->p, s->n);
}
static fmi2Status c_free_state(fmi2Component comp, fmi2FMUstate* state) {
    (void)comp;
    if (state && *state) {
        free(((state_blob*)*state)->p);
        free(*state);
        *state = NULL;
    }
    return fmi2OK;
}
static fmi2Status c_state_size(fmi2Component comp, fmi2FMUstate state, size_t* size) {
    (void)comp;
    *size = ((state_blob*)state)->n;
    return fmi2OK;
}
static fmi2Status c_serialize(fmi2Component comp, fmi2FMUstate state, fmi2Byte out[],
                              size_t size) {
    state_blob* s = state;
    if (size < s->n) {
        logm(comp, fmi2Error, "serialize: buffer of %zu bytes < %zu", size, s->n);
        return fmi2Error;
    }
    memcpy(out, s->p, s->n);
    return fmi2OK;
}
static fmi2Status c_deserialize(fmi2Component comp, const fmi2Byte in[], size_t size,
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
    "native C controller " ATO_MODEL_IDENTIFIER, ATO_VR_next_event_time, 1,
    c_instantiate, c_free, c_set_debug_logging,
    c_setup, c_enter_init, c_exit_init, c_terminate, c_reset,
    c_get_real, c_get_integer, c_get_boolean, c_get_string,
    c_set_real, c_set_integer, c_set_boolean, c_set_string,
    c_do_step,
    c_get_state, c_set_state, c_free_state, c_state_size, c_serialize, c_deserialize,
};

const ato_backend* ato_backend_get(char* error, size_t error_size) {
    (void)error; (void)error_size;
    return &BACKEND;
}
