/*
 * ato_plant_backend.c: the generic native backend over one plant model (ATO_MODEL, see
 * ato_plant_backend.h).
 *
 * FMI 2-shaped functions (ato_backend.h) for the fmi2 front: variables by value reference
 * from the generated table, the declared ranges of parameters checked on set, parameters
 * fixed after initialisation, the core built from the parameters at the end of
 * initialisation (or at the first output read), outputs computed after every step, and the
 * FMU state as a byte image: magic, variables, strings, calling-sequence data, core state.
 */
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "ato_plant_backend.h"

#define NV (ATO_MODEL.n_vars)
#define VARS (ATO_MODEL.vars)

void ato_log(ato_inst* m, fmi2Status status, const char* fmt, ...) {
    char buf[1024];
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(buf, sizeof buf, fmt, ap);
    va_end(ap);
    /* the complete message as the format, '%' doubled: right for printf-style loggers and for
     * loggers that show the format as it is (fmpy) */
    char esc[2048];
    size_t k = 0;
    for (const char* p = buf; *p && k + 2 < sizeof esc; p++) {
        if (*p == '%') esc[k++] = '%';
        esc[k++] = *p;
    }
    esc[k] = 0;
    if (m->cb.logger && (status != fmi2OK || m->logging_on))
        m->cb.logger(m->cb.componentEnvironment, m->name, status,
                     status == fmi2OK ? "logAll" : "logStatusError", esc);
}

int64_t ato_to_ticks(double seconds) { return (int64_t)llrint(seconds * 1e9); }
double ato_to_seconds(int64_t ticks) { return (double)ticks / 1e9; }
int64_t ato_floordiv(int64_t a, int64_t b) {
    int64_t q = a / b;
    return (a % b != 0 && ((a < 0) != (b < 0))) ? q - 1 : q;
}

void ato_put(ato_buf* b, const void* data, size_t n) {
    if (b->n + n > b->cap) {
        b->cap = (b->n + n) * 2;
        b->p = realloc(b->p, b->cap);
    }
    memcpy(b->p + b->n, data, n);
    b->n += n;
}
void ato_take(ato_rd* r, void* out, size_t n) {
    if (!r->ok || r->at + n > r->n) { r->ok = 0; memset(out, 0, n); return; }
    memcpy(out, r->p + r->at, n);
    r->at += n;
}

static int cmp_i64(const void* a, const void* b) {
    int64_t x = *(const int64_t*)a, y = *(const int64_t*)b;
    return x < y ? -1 : x > y;
}

size_t ato_substep_ends_acting(int64_t t, int64_t h, const int64_t* grids, int n_grids,
                               const int64_t* acts, size_t n_acts, int64_t** out) {
    int64_t end = t + h;
    size_t cap = 1 + n_acts;
    for (int g = 0; g < n_grids; g++)
        if (grids[g] > 0) {
            int64_t first = (ato_floordiv(t, grids[g]) + 1) * grids[g];
            if (first < end) cap += (size_t)((end - 1 - first) / grids[g] + 1);
        }
    int64_t* cuts = malloc(cap * sizeof(int64_t));
    size_t n = 0;
    cuts[n++] = end;
    for (int g = 0; g < n_grids; g++)
        if (grids[g] > 0)
            for (int64_t k = (ato_floordiv(t, grids[g]) + 1) * grids[g]; k < end; k += grids[g])
                cuts[n++] = k;
    for (size_t i = 0; i < n_acts; i++)
        if (t < acts[i] && acts[i] < end) cuts[n++] = acts[i];
    qsort(cuts, n, sizeof(int64_t), cmp_i64);
    size_t u = 0; /* a set: each cut once */
    for (size_t i = 0; i < n; i++)
        if (u == 0 || cuts[i] != cuts[u - 1]) cuts[u++] = cuts[i];
    *out = cuts;
    return u;
}

size_t ato_substep_ends(int64_t t, int64_t h, const int64_t* grids, int n_grids,
                        int64_t** out) {
    return ato_substep_ends_acting(t, h, grids, n_grids, NULL, 0, out);
}

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

static void free_core(ato_inst* m) {
    if (m->core) ATO_MODEL.destroy(m->core);
    m->core = NULL;
}

static int ensure_core(ato_inst* m) {
    if (m->core) return 1;
    m->core = ATO_MODEL.create(m);
    if (!m->core) return 0;
    ATO_MODEL.outputs(m, m->core);
    return 1;
}

static fmi2Component am_instantiate(fmi2String name, fmi2Type type, fmi2String guid,
                                    fmi2String resources, const fmi2CallbackFunctions* cb,
                                    fmi2Boolean visible, fmi2Boolean logging_on) {
    (void)visible;
    ato_inst tmp = {0};
    tmp.name = (char*)(name ? name : "?");
    if (cb) tmp.cb = *cb;
    if (type != fmi2CoSimulation) {
        ATO_ERROR(&tmp, "%s: only co-simulation is supported", ATO_MODEL.identifier);
        return NULL;
    }
    if (!guid || strcmp(guid, ATO_MODEL.guid) != 0) {
        ATO_ERROR(&tmp, "fmi2Instantiate: GUID %s does not match this binary's %s",
                  guid ? guid : "(null)", ATO_MODEL.guid);
        return NULL;
    }
    char* res = uri_to_path(resources);
    if (!res) {
        ATO_ERROR(&tmp, "fmi2Instantiate: resource location '%s' is not a file URI",
                  resources ? resources : "(null)");
        return NULL;
    }
    ato_inst* m = calloc(1, sizeof(ato_inst));
    m->name = dup(tmp.name);
    m->cb = tmp.cb;
    m->logging_on = logging_on;
    m->resources = res;
    m->r = calloc((size_t)NV, sizeof(double));
    m->str = calloc((size_t)NV, sizeof(char*));
    for (int i = 0; i < NV; i++) {
        m->r[i] = VARS[i].start;
        if (VARS[i].type == ATO_STRING) m->str[i] = dup(VARS[i].start_string);
    }
    return m;
}

static void am_free(fmi2Component comp) {
    ato_inst* m = comp;
    if (!m) return;
    free_core(m);
    for (int i = 0; i < NV; i++) free(m->str[i]);
    free(m->str);
    free(m->r);
    free(m->resources);
    free(m->name);
    free(m);
}

static fmi2Status am_set_debug_logging(fmi2Component comp, fmi2Boolean on, size_t n,
                                       const fmi2String cats[]) {
    (void)n; (void)cats;
    ((ato_inst*)comp)->logging_on = on;
    return fmi2OK;
}

static fmi2Status am_setup(fmi2Component comp, fmi2Boolean tol_defined, fmi2Real tol,
                           fmi2Real start, fmi2Boolean stop_defined, fmi2Real stop) {
    (void)tol_defined; (void)tol; (void)stop_defined; (void)stop;
    ato_inst* m = comp;
    if (!isfinite(start)) {
        ATO_ERROR(m, "start time %g is not finite", start);
        return fmi2Error;
    }
    m->start_ticks = ato_to_ticks(start);
    free_core(m);
    return fmi2OK;
}

static fmi2Status am_enter_init(fmi2Component comp) {
    ((ato_inst*)comp)->initialized = 0;
    return fmi2OK;
}

static fmi2Status am_exit_init(fmi2Component comp) {
    ato_inst* m = comp;
    if (!ensure_core(m)) return fmi2Error;
    m->initialized = 1;
    return fmi2OK;
}

static fmi2Status am_terminate(fmi2Component comp) { (void)comp; return fmi2OK; }

static fmi2Status am_reset(fmi2Component comp) {
    ato_inst* m = comp;
    free_core(m);
    for (int i = 0; i < NV; i++) {
        m->r[i] = VARS[i].start;
        if (VARS[i].type == ATO_STRING) {
            free(m->str[i]);
            m->str[i] = dup(VARS[i].start_string);
        }
    }
    m->initialized = 0;
    m->start_ticks = 0;
    m->executions = 0;
    return fmi2OK;
}

static const char* TYPE_CALL[][2] = {{"fmi2GetReal", "fmi2SetReal"},
                                     {"fmi2GetInteger", "fmi2SetInteger"},
                                     {"fmi2GetBoolean", "fmi2SetBoolean"},
                                     {"fmi2GetString", "fmi2SetString"}};

static int check_vr(ato_inst* m, fmi2ValueReference vr, int type, int set) {
    if (vr >= (fmi2ValueReference)NV || VARS[vr].type != type) {
        ATO_ERROR(m, "%s: no variable of this type with value reference %u",
                  TYPE_CALL[type][set], (unsigned)vr);
        return 0;
    }
    return 1;
}

/* a numeric value read (Real, Integer, Boolean): outputs from the core */
static int get_number(ato_inst* m, fmi2ValueReference vr, int type, double* out) {
    if (!check_vr(m, vr, type, 0)) return 0;
    if (VARS[vr].causality == ATO_OUTPUT && !ensure_core(m)) return 0;
    *out = m->r[vr];
    return 1;
}

/* a numeric value written: parameters in range and only before initialisation */
static int set_number(ato_inst* m, fmi2ValueReference vr, int type, double value) {
    if (!check_vr(m, vr, type, 1)) return 0;
    const ato_var* v = &VARS[vr];
    const char* call = TYPE_CALL[type][1];
    if (v->causality == ATO_OUTPUT) {
        ATO_ERROR(m, "%s: %s is an output", call, v->name);
        return 0;
    }
    if (v->causality == ATO_PARAMETER && m->initialized) {
        ATO_ERROR(m, "%s: parameter '%s' is fixed after initialisation", call, v->name);
        return 0;
    }
    if (!isfinite(value)) {
        ATO_ERROR(m, "%s: %s = %g: not a finite number", call, v->name, value);
        return 0;
    }
    if (v->causality == ATO_PARAMETER && ((v->has_min && value < v->min) ||
                                          (v->has_max && value > v->max))) {
        ATO_ERROR(m, "%s: %s = %.17g outside [%g, %g]", call, v->name, value,
                  v->has_min ? v->min : -INFINITY, v->has_max ? v->max : INFINITY);
        return 0;
    }
    m->r[vr] = value;
    if (v->causality == ATO_PARAMETER) free_core(m);
    return 1;
}

static fmi2Status am_get_real(fmi2Component c, const fmi2ValueReference vr[], size_t n,
                              fmi2Real v[]) {
    for (size_t i = 0; i < n; i++)
        if (!get_number(c, vr[i], ATO_REAL, &v[i])) return fmi2Error;
    return fmi2OK;
}
static fmi2Status am_get_integer(fmi2Component c, const fmi2ValueReference vr[], size_t n,
                                 fmi2Integer v[]) {
    for (size_t i = 0; i < n; i++) {
        double x;
        if (!get_number(c, vr[i], ATO_INTEGER, &x)) return fmi2Error;
        v[i] = (fmi2Integer)x;
    }
    return fmi2OK;
}
static fmi2Status am_get_boolean(fmi2Component c, const fmi2ValueReference vr[], size_t n,
                                 fmi2Boolean v[]) {
    for (size_t i = 0; i < n; i++) {
        double x;
        if (!get_number(c, vr[i], ATO_BOOLEAN, &x)) return fmi2Error;
        v[i] = x != 0.0 ? fmi2True : fmi2False;
    }
    return fmi2OK;
}
static fmi2Status am_set_real(fmi2Component c, const fmi2ValueReference vr[], size_t n,
                              const fmi2Real v[]) {
    for (size_t i = 0; i < n; i++)
        if (!set_number(c, vr[i], ATO_REAL, v[i])) return fmi2Error;
    return fmi2OK;
}
static fmi2Status am_set_integer(fmi2Component c, const fmi2ValueReference vr[], size_t n,
                                 const fmi2Integer v[]) {
    for (size_t i = 0; i < n; i++)
        if (!set_number(c, vr[i], ATO_INTEGER, (double)v[i])) return fmi2Error;
    return fmi2OK;
}
static fmi2Status am_set_boolean(fmi2Component c, const fmi2ValueReference vr[], size_t n,
                                 const fmi2Boolean v[]) {
    for (size_t i = 0; i < n; i++)
        if (!set_number(c, vr[i], ATO_BOOLEAN, v[i] ? 1.0 : 0.0)) return fmi2Error;
    return fmi2OK;
}

static fmi2Status am_get_string(fmi2Component comp, const fmi2ValueReference vr[], size_t n,
                                fmi2String value[]) {
    ato_inst* m = comp;
    for (size_t i = 0; i < n; i++) {
        if (!check_vr(m, vr[i], ATO_STRING, 0)) return fmi2Error;
        value[i] = m->str[vr[i]];
    }
    return fmi2OK;
}

static fmi2Status am_set_string(fmi2Component comp, const fmi2ValueReference vr[], size_t n,
                                const fmi2String value[]) {
    ato_inst* m = comp;
    for (size_t i = 0; i < n; i++) {
        if (!check_vr(m, vr[i], ATO_STRING, 1)) return fmi2Error;
        if (m->initialized) {
            ATO_ERROR(m, "fmi2SetString: parameter '%s' is fixed after initialisation",
                      VARS[vr[i]].name);
            return fmi2Error;
        }
        free(m->str[vr[i]]);
        m->str[vr[i]] = dup(value[i] ? value[i] : "");
        free_core(m);
    }
    return fmi2OK;
}

static fmi2Status am_do_step(fmi2Component comp, fmi2Real t, fmi2Real h, fmi2Boolean no_set) {
    (void)no_set;
    ato_inst* m = comp;
    if (!ensure_core(m)) return fmi2Error;
    if (!(h > 0.0) || !isfinite(h)) {
        ATO_ERROR(m, "doStep: step size %g must be positive and finite", h);
        return fmi2Error;
    }
    if (!isfinite(t)) {
        ATO_ERROR(m, "doStep: time %g is not finite", t);
        return fmi2Error;
    }
    if (!ATO_MODEL.step(m, m->core, ato_to_ticks(t), ato_to_ticks(h))) return fmi2Error;
    ATO_MODEL.outputs(m, m->core);
    m->executions++;
    return fmi2OK;
}

/* -- FMU state: a byte image (magic, values, strings, calling sequence, core) --------------- */
static ato_buf image(ato_inst* m) {
    ato_buf b = {0};
    const char* magic = ATO_MODEL.state_magic;
    ato_put(&b, magic, strlen(magic) + 1);
    ato_put(&b, m->r, (size_t)NV * sizeof(double));
    for (int i = 0; i < NV; i++)
        if (VARS[i].type == ATO_STRING) {
            uint64_t len = strlen(m->str[i]);
            ato_put(&b, &len, sizeof len);
            ato_put(&b, m->str[i], len);
        }
    int32_t flags[2] = {m->initialized, m->core != NULL};
    ato_put(&b, flags, sizeof flags);
    ato_put(&b, &m->start_ticks, sizeof m->start_ticks);
    int64_t ex = m->executions;
    ato_put(&b, &ex, sizeof ex);
    if (m->core) ATO_MODEL.save(m->core, &b);
    return b;
}

static fmi2Status restore(ato_inst* m, const unsigned char* data, size_t n) {
    ato_rd r = {data, n, 0, 1};
    const char* magic = ATO_MODEL.state_magic;
    size_t k = strlen(magic) + 1;
    if (n < k || memcmp(data, magic, k) != 0) {
        ATO_ERROR(m, "state does not belong to FMU %s", ATO_MODEL.identifier);
        return fmi2Error;
    }
    r.at = k;
    double* values = malloc((size_t)NV * sizeof(double));
    ato_take(&r, values, (size_t)NV * sizeof(double));
    char** strs = calloc((size_t)NV, sizeof(char*));
    for (int i = 0; i < NV && r.ok; i++)
        if (VARS[i].type == ATO_STRING) {
            uint64_t len = 0;
            ato_take(&r, &len, sizeof len);
            if (!r.ok || len > n) { r.ok = 0; break; }
            strs[i] = calloc(len + 1, 1);
            ato_take(&r, strs[i], len);
        }
    int32_t flags[2];
    int64_t start, ex;
    ato_take(&r, flags, sizeof flags);
    ato_take(&r, &start, sizeof start);
    ato_take(&r, &ex, sizeof ex);
    if (!r.ok) {
        for (int i = 0; i < NV; i++) free(strs[i]);
        free(strs);
        free(values);
        ATO_ERROR(m, "truncated FMU state");
        return fmi2Error;
    }
    free_core(m);
    memcpy(m->r, values, (size_t)NV * sizeof(double));
    free(values);
    for (int i = 0; i < NV; i++)
        if (VARS[i].type == ATO_STRING) { free(m->str[i]); m->str[i] = strs[i]; }
    free(strs);
    m->start_ticks = start;
    m->executions = (long)ex;
    m->initialized = 0;
    if (flags[1]) {
        if (!ensure_core(m)) return fmi2Error;
        if (!ATO_MODEL.load(m->core, &r) || !r.ok) {
            free_core(m);
            ATO_ERROR(m, "truncated FMU state");
            return fmi2Error;
        }
        ATO_MODEL.outputs(m, m->core);
    }
    m->initialized = flags[0];
    return fmi2OK;
}

typedef struct { size_t n; unsigned char* p; } state_blob;

static fmi2Status am_get_state(fmi2Component comp, fmi2FMUstate* state) {
    ato_buf b = image(comp);
    state_blob* s = *state ? (state_blob*)*state : calloc(1, sizeof(state_blob));
    free(s->p);
    s->p = b.p;
    s->n = b.n;
    *state = s;
    return fmi2OK;
}
static fmi2Status am_set_state(fmi2Component comp, fmi2FMUstate state) {
    if (!state) return fmi2Error;
    state_blob* s = state;
    return restore(comp, s->p, s->n);
}
static fmi2Status am_free_state(fmi2Component comp, fmi2FMUstate* state) {
    (void)comp;
    if (state && *state) {
        free(((state_blob*)*state)->p);
        free(*state);
        *state = NULL;
    }
    return fmi2OK;
}
static fmi2Status am_state_size(fmi2Component comp, fmi2FMUstate state, size_t* size) {
    (void)comp;
    *size = ((state_blob*)state)->n;
    return fmi2OK;
}
static fmi2Status am_serialize(fmi2Component comp, fmi2FMUstate state, fmi2Byte out[],
                               size_t size) {
    state_blob* s = state;
    if (size < s->n) {
        ATO_ERROR(comp, "serialize: buffer of %zu bytes < %zu", size, s->n);
        return fmi2Error;
    }
    memcpy(out, s->p, s->n);
    return fmi2OK;
}
static fmi2Status am_deserialize(fmi2Component comp, const fmi2Byte in[], size_t size,
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
    "native C model (ato_plant_backend.c)", -1, 1,
    am_instantiate, am_free, am_set_debug_logging,
    am_setup, am_enter_init, am_exit_init, am_terminate, am_reset,
    am_get_real, am_get_integer, am_get_boolean, am_get_string,
    am_set_real, am_set_integer, am_set_boolean, am_set_string,
    am_do_step,
    am_get_state, am_set_state, am_free_state, am_state_size, am_serialize, am_deserialize,
};

const ato_backend* ato_backend_get(char* error, size_t error_size) {
    (void)error; (void)error_size;
    return &BACKEND;
}
