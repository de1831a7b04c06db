/*
 * runtime.c: the native runtime under every native FMU (see runtime.h), the C twin of
 * cosim/fmu/slave.py's CoreSlave; a backend's ATO_POLICY says what differs.
 */
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "runtime.h"

#define P ATO_POLICY
#define NV (P.id->n_vars)
#define VARS (P.id->vars)

/* longest message any policy logs (its message_size is at most this) */
#define MESSAGE_MAX 1200

void ato_log(ato_inst* m, fmi2Status status, const char* fmt, ...) {
    char buf[MESSAGE_MAX];
    size_t size = P.message_size < sizeof buf ? P.message_size : sizeof buf;
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(buf, size, fmt, ap);
    va_end(ap);
    /* the complete message as the format, '%' doubled: right for printf-style loggers and for
     * loggers that show the format as it is (fmpy) */
    char esc[2 * MESSAGE_MAX];
    size_t k = 0;
    for (const char* p = buf; *p && k + 2 < 2 * size; p++) {
        if (*p == '%') esc[k++] = '%';
        esc[k++] = *p;
    }
    esc[k] = 0;
    if (m->cb.logger && (status != fmi2OK || m->logging_on))
        m->cb.logger(m->cb.componentEnvironment, m->name, status,
                     status == fmi2OK        ? "logAll"
                     : status == fmi2Warning ? "logStatusWarning"
                                             : "logStatusError",
                     esc);
}

int64_t ato_to_ticks(double seconds) { return (int64_t)llrint(seconds * 1e9); }
double ato_to_seconds(int64_t ticks) { return (double)ticks / 1e9; }
int64_t ato_floordiv(int64_t a, int64_t b) {
    int64_t q = a / b;
    return (a % b != 0 && ((a < 0) != (b < 0))) ? q - 1 : q;
}

/* the shortest decimal that reads back as x, laid out as Python's repr: fixed notation for
 * decimal exponents -4 .. 15 (with ".0" for a whole number), else d.ddde+XX */
ato_num ato_fmt(double x) {
    ato_num out;
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
    /* fixed notation, written in place: at most 23 characters (sign, "0.", three zeros and
     * 17 digits for exp10 = -4; sign, 16 digits, "." and one digit for exp10 = 15) */
    char* body = out.s;
    int at = 0;
    if (*sign) body[at++] = '-';
    if (exp10 < 0) {
        at += snprintf(body + at, sizeof out.s - at, "0.");
        for (int i = 0; i < -exp10 - 1; i++) body[at++] = '0';
        at += snprintf(body + at, sizeof out.s - at, "%s", mant);
    } else {
        for (int i = 0; i <= exp10; i++) body[at++] = i < k ? mant[i] : '0';
        body[at++] = '.';
        if (exp10 + 1 < k) at += snprintf(body + at, sizeof out.s - at, "%s", mant + exp10 + 1);
        else body[at++] = '0';
    }
    body[at] = 0;
    return out;
}

const char* ato_repr(double x, char buf[40]) {
    ato_num n = ato_fmt(x);
    memcpy(buf, n.s, sizeof n.s);
    return buf;
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

/* every variable at its declared start (the policy's part too) */
static void set_starts(ato_inst* m) {
    for (int i = 0; i < NV; i++) {
        m->r[i] = VARS[i].start;
        if (VARS[i].type == ATO_STRING) {
            free(m->str[i]);
            m->str[i] = dup(VARS[i].start_string);
        }
    }
    if (P.starts) P.starts(m);
}

static fmi2Component rt_instantiate(fmi2String name, fmi2Type type, fmi2String guid,
                                    fmi2String resources, const fmi2CallbackFunctions* cb,
                                    fmi2Boolean visible, fmi2Boolean logging_on) {
    (void)visible;
    ato_inst tmp;
    memset(&tmp, 0, sizeof tmp);
    tmp.name = (char*)(name ? name : "?");
    if (cb) tmp.cb = *cb;
    if (type != fmi2CoSimulation) {
        ATO_ERROR(&tmp, "%s: only co-simulation is supported", P.id->identifier);
        return NULL;
    }
    if (!guid || strcmp(guid, P.id->guid) != 0) {
        ATO_ERROR(&tmp, "fmi2Instantiate: GUID %s does not match this binary's %s",
                  guid ? guid : "(null)", P.id->guid);
        return NULL;
    }
    char* res = uri_to_path(resources);
    if (!res) {
        ATO_ERROR(&tmp, "fmi2Instantiate: resource location '%s' is not a file URI",
                  resources ? resources : "(null)");
        return NULL;
    }
    ato_inst* m = calloc(1, P.inst_size);
    m->name = dup(tmp.name);
    m->cb = tmp.cb;
    m->logging_on = logging_on;
    m->resources = res;
    m->r = calloc((size_t)NV, sizeof(double));
    m->str = calloc((size_t)NV, sizeof(char*));
    set_starts(m);
    return m;
}

static void rt_free(fmi2Component comp) {
    ato_inst* m = comp;
    if (!m) return;
    P.free_core(m);
    for (int i = 0; i < NV; i++) free(m->str[i]);
    free(m->str);
    free(m->r);
    free(m->resources);
    free(m->name);
    free(m);
}

static fmi2Status rt_set_debug_logging(fmi2Component comp, fmi2Boolean on, size_t n,
                                       const fmi2String cats[]) {
    (void)n; (void)cats;
    ((ato_inst*)comp)->logging_on = on;
    return fmi2OK;
}

static fmi2Status rt_setup(fmi2Component comp, fmi2Boolean tol_defined, fmi2Real tol,
                           fmi2Real start, fmi2Boolean stop_defined, fmi2Real stop) {
    (void)tol_defined; (void)tol; (void)stop_defined; (void)stop;
    ato_inst* m = comp;
    if (!isfinite(start)) {
        ATO_ERROR(m, "start time %g is not finite", start);
        return fmi2Error;
    }
    m->start_ticks = ato_to_ticks(start);
    if (P.setup) P.setup(m);
    return fmi2OK;
}

static fmi2Status rt_enter_init(fmi2Component comp) {
    ((ato_inst*)comp)->initialized = 0;
    return fmi2OK;
}

static fmi2Status rt_exit_init(fmi2Component comp) {
    ato_inst* m = comp;
    if (!P.ensure_core(m)) return fmi2Error;
    m->initialized = 1;
    return fmi2OK;
}

static fmi2Status rt_terminate(fmi2Component comp) { (void)comp; return fmi2OK; }

static fmi2Status rt_reset(fmi2Component comp) {
    ato_inst* m = comp;
    P.free_core(m);
    set_starts(m);
    m->initialized = 0;
    m->start_ticks = 0;
    m->executions = 0;
    if (P.reset) P.reset(m);
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

/* a numeric value read (Real, Integer, Boolean): outputs as the policy shows them */
static int get_number(ato_inst* m, fmi2ValueReference vr, int type, double* out) {
    if (!check_vr(m, vr, type, 0)) return 0;
    if (VARS[vr].causality == ATO_OUTPUT) return P.get_output(m, (unsigned)vr, out);
    *out = m->r[vr];
    return 1;
}

/* CoreSlave's setter: no outputs, parameters fixed after initialisation, finite numbers,
 * parameters inside their declared ranges */
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
    if (!isfinite(value)) { /* only a Real can be other than finite */
        ATO_ERROR(m, "%s: %s = %g: not a finite number", call, v->name, value);
        return 0;
    }
    if (v->causality == ATO_PARAMETER && ((v->has_min && value < v->min) ||
                                          (v->has_max && value > v->max))) {
        double lo = v->has_min ? v->min : -INFINITY, hi = v->has_max ? v->max : INFINITY;
        if (P.repr_messages)
            ATO_ERROR(m, "%s: %s = %s outside [%s, %s]", call, v->name, ato_fmt(value).s,
                      ato_fmt(lo).s, ato_fmt(hi).s);
        else
            ATO_ERROR(m, "%s: %s = %.17g outside [%g, %g]", call, v->name, value, lo, hi);
        return 0;
    }
    m->r[vr] = value;
    if (v->causality == ATO_PARAMETER) P.free_core(m);
    else if (P.input_set) P.input_set(m);
    return 1;
}

static fmi2Status rt_get_real(fmi2Component c, const fmi2ValueReference vr[], size_t n,
                              fmi2Real v[]) {
    for (size_t i = 0; i < n; i++)
        if (!get_number(c, vr[i], ATO_REAL, &v[i])) return fmi2Error;
    return fmi2OK;
}
static fmi2Status rt_get_integer(fmi2Component c, const fmi2ValueReference vr[], size_t n,
                                 fmi2Integer v[]) {
    for (size_t i = 0; i < n; i++) {
        double x;
        if (!get_number(c, vr[i], ATO_INTEGER, &x)) return fmi2Error;
        v[i] = (fmi2Integer)x;
    }
    return fmi2OK;
}
static fmi2Status rt_get_boolean(fmi2Component c, const fmi2ValueReference vr[], size_t n,
                                 fmi2Boolean v[]) {
    for (size_t i = 0; i < n; i++) {
        double x;
        if (!get_number(c, vr[i], ATO_BOOLEAN, &x)) return fmi2Error;
        v[i] = x != 0.0 ? fmi2True : fmi2False;
    }
    return fmi2OK;
}
static fmi2Status rt_set_real(fmi2Component c, const fmi2ValueReference vr[], size_t n,
                              const fmi2Real v[]) {
    for (size_t i = 0; i < n; i++)
        if (!set_number(c, vr[i], ATO_REAL, v[i])) return fmi2Error;
    return fmi2OK;
}
static fmi2Status rt_set_integer(fmi2Component c, const fmi2ValueReference vr[], size_t n,
                                 const fmi2Integer v[]) {
    for (size_t i = 0; i < n; i++)
        if (!set_number(c, vr[i], ATO_INTEGER, (double)v[i])) return fmi2Error;
    return fmi2OK;
}
static fmi2Status rt_set_boolean(fmi2Component c, const fmi2ValueReference vr[], size_t n,
                                 const fmi2Boolean v[]) {
    for (size_t i = 0; i < n; i++)
        if (!set_number(c, vr[i], ATO_BOOLEAN, v[i] ? 1.0 : 0.0)) return fmi2Error;
    return fmi2OK;
}

static fmi2Status rt_get_string(fmi2Component comp, const fmi2ValueReference vr[], size_t n,
                                fmi2String value[]) {
    ato_inst* m = comp;
    for (size_t i = 0; i < n; i++) {
        if (!check_vr(m, vr[i], ATO_STRING, 0)) return fmi2Error;
        value[i] = m->str[vr[i]];
    }
    return fmi2OK;
}

static fmi2Status rt_set_string(fmi2Component comp, const fmi2ValueReference vr[], size_t n,
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
        P.free_core(m);
    }
    return fmi2OK;
}

static fmi2Status rt_do_step(fmi2Component comp, fmi2Real t, fmi2Real h, fmi2Boolean no_set) {
    (void)no_set;
    ato_inst* m = comp;
    if (!P.ensure_core(m)) return fmi2Error;
    if (!(h > 0.0) || !isfinite(h)) {
        ATO_ERROR(m, "doStep: step size %g must be positive and finite", h);
        return fmi2Error;
    }
    return P.do_step(m, t, h);
}

/* -- FMU state: a byte image (magic, values, strings, the policy's part) -------------------- */
static int image(ato_inst* m, ato_buf* b) {
    if (P.image_needs_core && !P.ensure_core(m)) return 0;
    const char* magic = P.id->state_magic;
    ato_put(b, magic, strlen(magic) + 1);
    ato_put(b, m->r, (size_t)NV * sizeof(double));
    for (int i = 0; i < NV; i++)
        if (VARS[i].type == ATO_STRING) {
            uint64_t len = strlen(m->str[i]);
            ato_put(b, &len, sizeof len);
            ato_put(b, m->str[i], len);
        }
    P.save(m, b);
    return 1;
}

void ato_drop_values(double* values, char** strs) {
    for (int i = 0; i < NV; i++) free(strs[i]);
    free(strs);
    free(values);
}

void ato_adopt_values(ato_inst* m, double* values, char** strs) {
    memcpy(m->r, values, (size_t)NV * sizeof(double));
    free(values);
    for (int i = 0; i < NV; i++)
        if (VARS[i].type == ATO_STRING) { free(m->str[i]); m->str[i] = strs[i]; }
    free(strs);
}

static fmi2Status restore(ato_inst* m, const unsigned char* data, size_t n) {
    ato_rd r = {data, n, 0, 1};
    const char* magic = P.id->state_magic;
    size_t k = strlen(magic) + 1;
    if (n < k || memcmp(data, magic, k) != 0) {
        ATO_ERROR(m, "state does not belong to FMU %s", P.id->identifier);
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
    return P.load(m, &r, values, strs);
}

typedef struct { size_t n; unsigned char* p; } state_blob;

static fmi2Status rt_get_state(fmi2Component comp, fmi2FMUstate* state) {
    ato_buf b = {0};
    if (!image(comp, &b)) { free(b.p); return fmi2Error; }
    state_blob* s = *state ? (state_blob*)*state : calloc(1, sizeof(state_blob));
    free(s->p);
    s->p = b.p;
    s->n = b.n;
    *state = s;
    return fmi2OK;
}
static fmi2Status rt_set_state(fmi2Component comp, fmi2FMUstate state) {
    if (!state) return fmi2Error;
    state_blob* s = state;
    return restore(comp, s->p, s->n);
}
static fmi2Status rt_free_state(fmi2Component comp, fmi2FMUstate* state) {
    (void)comp;
    if (state && *state) {
        free(((state_blob*)*state)->p);
        free(*state);
        *state = NULL;
    }
    return fmi2OK;
}
static fmi2Status rt_state_size(fmi2Component comp, fmi2FMUstate state, size_t* size) {
    (void)comp;
    *size = ((state_blob*)state)->n;
    return fmi2OK;
}
static fmi2Status rt_serialize(fmi2Component comp, fmi2FMUstate state, fmi2Byte out[],
                               size_t size) {
    state_blob* s = state;
    if (size < s->n) {
        ATO_ERROR((ato_inst*)comp, "serialize: buffer of %zu bytes < %zu", size, s->n);
        return fmi2Error;
    }
    memcpy(out, s->p, s->n);
    return fmi2OK;
}
static fmi2Status rt_deserialize(fmi2Component comp, const fmi2Byte in[], size_t size,
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

const ato_backend* ato_backend_get(char* error, size_t error_size) {
    (void)error; (void)error_size;
    static ato_backend backend = {
        NULL, -1, 1,
        rt_instantiate, rt_free, rt_set_debug_logging,
        rt_setup, rt_enter_init, rt_exit_init, rt_terminate, rt_reset,
        rt_get_real, rt_get_integer, rt_get_boolean, rt_get_string,
        rt_set_real, rt_set_integer, rt_set_boolean, rt_set_string,
        rt_do_step,
        rt_get_state, rt_set_state, rt_free_state, rt_state_size, rt_serialize,
        rt_deserialize,
    };
    backend.name = P.backend_name;
    backend.event_time_vr = P.event_time_vr;
    return &backend;
}
