/* Small FMI 3.0 co-simulation FMUs for the tests (one model per MODEL_* define):
   TimeEvents (announces nextEventTime, or returns early; its output clock "ticked", vr 17, is
   active in the Event Mode of each of its events until fmi3UpdateDiscreteStates handles it),
   Feedthrough (y_T = u_T for every
   type, 64-bit integers exactly, an array), Terminator (terminateSimulation at stop_at),
   Countdown (a countdown input clock: its first interval "first" told in Initialization Mode
   only, as FMI 3.0 sec. 2.2.8.2 has the importer ask it there; after each tick it ticks again
   at interval 0 until it has ticked "repeat" + 1 times at that instant, then its interval
   doubles, or becomes "period" when it was 0), Clocked (a
   periodic input clock "tick" whose interval and shift the FMU gives on request, its interval
   multiplied by growth at every tick; with CLOCK_CHANGING it is a changing Clock: its first
   interval told in Initialization Mode, the next one in each Event Mode where it ticked; with
   CLOCK_TRIGGERED it is a triggered Clock: fmi3SetClock outside Event Mode is refused, FMI 3.0
   sec. 2.2.8.4, and at each tick y takes its clocked input u and the FMU logs
   "tick at t = <its time, %.17g>"), Pulses (events, announced as nextEventTime, at the
   times k period, k = 0 .. 30, whose bit k is set in its parameter "pattern"; its output clock
   "ticked", vr 17, is active in the Event Mode of each of them as TimeEvents'). TimeEvents
   compares times within its parameter tolerance (0: exactly). */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <math.h>
#include "fmi3Functions.h"

#define EPS 1e-9
#define NT 14 /* Feedthrough: Float64 Float32 Int8 UInt8 Int16 UInt16 Int32 UInt32 Int64 UInt64
                 Boolean String Binary Enumeration: u_T has vr 2i+1, y_T vr 2i+2 */

typedef struct {
    fmi3Float64 time, period, u, q, next, stop_at, interval, first, tol, last_event, shift,
        growth, interval_counter, shift_counter, resolution, /* these three: Fraction */
        repeat, report, /* Countdown: ticks at interval 0 after each tick, interval told */
        pattern; /* Pulses: bit k set: an event at k period */
    fmi3Int32 n, burst;
    fmi3Boolean announce, eventMode, earlyReturn, tick, pending, init, inEvent;
    double num[NT]; /* numeric and Boolean feedthrough values (as double, exact up to 2^53) */
    fmi3Int64 i64; fmi3UInt64 u64; /* the Int64 and UInt64 feedthrough values, exact */
    char *str;
    fmi3Byte bin[64]; size_t binSize;
    fmi3Float64 arr[3];
    fmi3LogMessageCallback log; fmi3InstanceEnvironment env;
} M;

#if defined(MODEL_PULSES)
static double next_pulse(M *m, int k);
#endif
static void say(M *m, const char *msg) { if (m->log) m->log(m->env, fmi3OK, "log", msg); }

fmi3Instance fmi3InstantiateCoSimulation(fmi3String name, fmi3String token, fmi3String res,
    fmi3Boolean visible, fmi3Boolean loggingOn, fmi3Boolean eventModeUsed,
    fmi3Boolean earlyReturnAllowed, const fmi3ValueReference req[], size_t nReq,
    fmi3InstanceEnvironment env, fmi3LogMessageCallback log,
    fmi3IntermediateUpdateCallback upd) {
    (void)name; (void)token; (void)res; (void)visible; (void)loggingOn; (void)req; (void)nReq;
    (void)upd;
    M *m = calloc(1, sizeof(M));
    m->period = 0.1; m->announce = fmi3True; m->stop_at = 0.75; m->first = 0.1;
    m->tol = EPS; m->interval = 0.3; m->shift = 0.1; m->growth = 1.0;
    m->interval_counter = 3; m->shift_counter = 1; m->resolution = 10;
#if defined(MODEL_PULSES)
    m->period = 1.0; m->pattern = 771; /* the declared start values */
#endif
#if defined(COUNTDOWN_REPEAT)
    m->repeat = COUNTDOWN_REPEAT; /* the declared start value of repeat */
#endif
    for (int k = 0; k < NT; k++) /* the Feedthrough's declared start values */
        m->num[k] = k < 2 ? 1.5 : k == 10 ? 0.0 : 1.0;
    m->i64 = 1; m->u64 = 1; /* the exact Int64 and UInt64 start values */
    m->eventMode = eventModeUsed; m->earlyReturn = earlyReturnAllowed;
    m->str = strdup("in"); m->log = log; m->env = env;
    return m;
}
void fmi3FreeInstance(fmi3Instance i) { M *m = i; if (m) { free(m->str); free(m); } }
const char *fmi3GetVersion(void) { return fmi3Version; }
fmi3Status fmi3SetDebugLogging(fmi3Instance i, fmi3Boolean on, size_t n, const fmi3String c[]) {
    (void)i; (void)on; (void)n; (void)c; return fmi3OK; }
fmi3Status fmi3EnterInitializationMode(fmi3Instance i, fmi3Boolean td, fmi3Float64 tol,
    fmi3Float64 start, fmi3Boolean sd, fmi3Float64 stop) {
    M *m = i; (void)td; (void)tol; (void)sd; (void)stop; m->time = start; m->init = fmi3True;
    return fmi3OK; }
fmi3Status fmi3ExitInitializationMode(fmi3Instance i) {
    M *m = i; m->next = m->time + m->period; m->pending = fmi3True; m->init = fmi3False;
    m->inEvent = m->eventMode; /* FMI 3.0 sec. 2.3.3: then in Event Mode when it is used */
#if !defined(MODEL_CLOCKED)
    m->interval = m->first;
#endif
#if defined(MODEL_COUNTDOWN)
    m->pending = fmi3False; /* the first interval was told in Initialization Mode */
#endif
#if defined(MODEL_PULSES)
    m->next = next_pulse(m, -1);
#endif
    return fmi3OK; }
fmi3Status fmi3EnterEventMode(fmi3Instance i) { M *m = i; m->inEvent = fmi3True; return fmi3OK; }
fmi3Status fmi3EnterStepMode(fmi3Instance i) { M *m = i; m->inEvent = fmi3False; return fmi3OK; }
fmi3Status fmi3Terminate(fmi3Instance i) { say(i, "terminated"); return fmi3OK; }
fmi3Status fmi3Reset(fmi3Instance i) { (void)i; return fmi3OK; }

#if defined(MODEL_PULSES)
/* Pulses: the time of the first pulse after pulse k (k = -1: the first), or infinity */
static double next_pulse(M *m, int k) {
    long bits = (long)m->pattern;
    for (int j = k + 1; j <= 30; j++)
        if (bits >> j & 1) return j * m->period;
    return INFINITY;
}
#endif

static inline void time_event(M *m) {
    m->n++; m->q = m->u; m->last_event = m->time; m->next += m->period; }

fmi3Status fmi3UpdateDiscreteStates(fmi3Instance i, fmi3Boolean *need, fmi3Boolean *term,
    fmi3Boolean *nom, fmi3Boolean *vals, fmi3Boolean *defined, fmi3Float64 *next) {
    M *m = i; (void)m;
    *need = fmi3False; *term = fmi3False; *nom = fmi3False; *vals = fmi3False;
    *defined = fmi3False; *next = 0.0;
#if defined(MODEL_TIMEEVENTS)
    if (m->time >= m->next - m->tol) time_event(m);
    *defined = m->announce; *next = m->next;
#elif defined(MODEL_PULSES)
    if (m->time >= m->next - m->tol) {
        m->n++; m->q = m->u; m->last_event = m->time;
        m->next = next_pulse(m, (int)floor(m->time / m->period + 0.5));
    }
    *defined = isfinite(m->next); *next = *defined ? m->next : 0.0;
#elif defined(MODEL_CLOCKED)
    if (m->tick) { m->n++; m->q = m->time; m->tick = fmi3False;
                   if (m->growth != 1.0) { m->interval *= m->growth; m->pending = fmi3True; }
#if defined(CLOCK_CHANGING)
                   m->pending = fmi3True; /* a changing Clock's next interval, told at once */
#elif defined(CLOCK_TRIGGERED)
                   m->last_event = m->u; /* y, the clocked input at the tick */
                   char text[64];
                   snprintf(text, sizeof text, "tick at t = %.17g", m->time);
                   say(m, text);
#endif
    }
#elif defined(MODEL_COUNTDOWN)
    if (m->tick) {
        m->n++; m->q = m->u; m->tick = fmi3False; m->pending = fmi3True;
        if (m->burst < m->repeat) { m->burst++; m->report = 0.0; }
        else { m->burst = 0; m->interval = m->interval > 0 ? 2 * m->interval : m->period;
               m->report = m->interval; }
    }
#endif
    return fmi3OK;
}

fmi3Status fmi3DoStep(fmi3Instance i, fmi3Float64 t, fmi3Float64 h, fmi3Boolean noSet,
    fmi3Boolean *event, fmi3Boolean *term, fmi3Boolean *early, fmi3Float64 *last) {
    M *m = i; (void)noSet;
    double end = t + h;
    *event = fmi3False; *term = fmi3False; *early = fmi3False; *last = end;
#if defined(MODEL_TIMEEVENTS) || defined(MODEL_PULSES)
    if (m->eventMode) {
        if (end > m->next + m->tol) {  /* passes over the event */
            if (!m->earlyReturn) { say(m, "doStep passes over an event"); return fmi3Error; }
            *early = fmi3True; *event = fmi3True; *last = m->next; m->time = m->next;
            return fmi3OK;
        }
        if (fabs(end - m->next) <= m->tol && !m->announce) *event = fmi3True;
    } else {
#if defined(MODEL_PULSES)
        while (m->next <= end + m->tol) {
            m->n++; m->next = next_pulse(m, (int)floor(m->next / m->period + 0.5)); }
#else
        while (m->next <= end + m->tol) time_event(m);
#endif
    }
#elif defined(MODEL_TERMINATOR)
    if (end >= m->stop_at - EPS) { *term = fmi3True; *last = end; }
#endif
    m->time = end;
    return fmi3OK;
}

/* ---- variables ---- */
#define GETSET(T, CT) \
fmi3Status fmi3Get##T(fmi3Instance i, const fmi3ValueReference vr[], size_t n, CT v[], size_t nv) { \
    M *m = i; size_t k = 0; (void)nv; \
    for (size_t j = 0; j < n; j++) { \
        if (!get_num(m, vr[j], &v[k], sizeof(CT), #T)) return fmi3Error; \
        k += vr[j] == 101 || vr[j] == 102 ? 3 : 1; } \
    return fmi3OK; } \
fmi3Status fmi3Set##T(fmi3Instance i, const fmi3ValueReference vr[], size_t n, const CT v[], size_t nv) { \
    M *m = i; size_t k = 0; (void)nv; \
    for (size_t j = 0; j < n; j++) { \
        if (!set_num(m, vr[j], &v[k], #T)) return fmi3Error; \
        k += vr[j] == 101 || vr[j] == 102 ? 3 : 1; } \
    return fmi3OK; }

static double *slot(M *m, fmi3ValueReference vr) {
#if defined(MODEL_FEEDTHROUGH)
    if (vr >= 1 && vr <= 2 * NT) return &m->num[(vr - 1) / 2];
    if (vr == 101 || vr == 102) return m->arr;
#else
    switch (vr) {
    case 0: return &m->period;
    case 1: return &m->u;
    case 2: return &m->q;
    case 5: return &m->stop_at;
    case 6: return &m->time;
    case 7: return &m->first;
    case 8: return &m->tol;
    case 9: return &m->last_event;
    case 11: return &m->interval;
    case 12: return &m->shift;
    case 13: return &m->growth;
    case 14: return &m->interval_counter;
    case 15: return &m->shift_counter;
    case 16: return &m->resolution;
    case 18: return &m->repeat;
    case 19: return &m->pattern;
    }
#endif
    return NULL;
}

static int is(const char *a, const char *b) { return strcmp(a, b) == 0; }

static int get_num(M *m, fmi3ValueReference vr, void *out, size_t size, const char *type) {
#if defined(MODEL_FEEDTHROUGH)
    if ((vr == 17 || vr == 18) && is(type, "Int64")) { *(fmi3Int64 *)out = m->i64; return 1; }
    if ((vr == 19 || vr == 20) && is(type, "UInt64")) { *(fmi3UInt64 *)out = m->u64; return 1; }
#else
    if (vr == 3 && is(type, "Int32")) { *(fmi3Int32 *)out = m->n; return 1; }
    if (vr == 4 && is(type, "Boolean")) { *(fmi3Boolean *)out = m->announce; return 1; }
#endif
    double *s = slot(m, vr);
    if (!s) return 0;
    int count = (vr == 101 || vr == 102) ? 3 : 1;
    for (int c = 0; c < count; c++) {
        double x = s[c];
        char *o = (char *)out + c * size;
        if (is(type, "Float64")) *(fmi3Float64 *)o = x;
        else if (is(type, "Float32")) *(fmi3Float32 *)o = (fmi3Float32)x;
        else if (is(type, "Int8")) *(fmi3Int8 *)o = (fmi3Int8)x;
        else if (is(type, "UInt8")) *(fmi3UInt8 *)o = (fmi3UInt8)x;
        else if (is(type, "Int16")) *(fmi3Int16 *)o = (fmi3Int16)x;
        else if (is(type, "UInt16")) *(fmi3UInt16 *)o = (fmi3UInt16)x;
        else if (is(type, "Int32")) *(fmi3Int32 *)o = (fmi3Int32)x;
        else if (is(type, "UInt32")) *(fmi3UInt32 *)o = (fmi3UInt32)x;
        else if (is(type, "Int64")) *(fmi3Int64 *)o = (fmi3Int64)x;
        else if (is(type, "UInt64")) *(fmi3UInt64 *)o = (fmi3UInt64)x;
        else if (is(type, "Boolean")) *(fmi3Boolean *)o = x != 0;
        else return 0;
    }
    return 1;
}

static int set_num(M *m, fmi3ValueReference vr, const void *in, const char *type) {
#if defined(MODEL_FEEDTHROUGH)
    if (vr == 17 && is(type, "Int64")) m->i64 = *(const fmi3Int64 *)in;
    if (vr == 19 && is(type, "UInt64")) m->u64 = *(const fmi3UInt64 *)in;
#else
    if (vr == 4 && is(type, "Boolean")) { m->announce = *(const fmi3Boolean *)in; return 1; }
#endif
    double *s = slot(m, vr);
    if (!s) return 0;
    int count = (vr == 101 || vr == 102) ? 3 : 1;
    size_t size = is(type, "Float64") || is(type, "Int64") || is(type, "UInt64") ? 8
        : is(type, "Float32") || is(type, "Int32") || is(type, "UInt32") ? 4
        : is(type, "Int16") || is(type, "UInt16") ? 2 : 1;
    for (int c = 0; c < count; c++) {
        const char *p = (const char *)in + c * size;
        double x;
        if (is(type, "Float64")) x = *(const fmi3Float64 *)p;
        else if (is(type, "Float32")) x = *(const fmi3Float32 *)p;
        else if (is(type, "Int8")) x = *(const fmi3Int8 *)p;
        else if (is(type, "UInt8")) x = *(const fmi3UInt8 *)p;
        else if (is(type, "Int16")) x = *(const fmi3Int16 *)p;
        else if (is(type, "UInt16")) x = *(const fmi3UInt16 *)p;
        else if (is(type, "Int32")) x = *(const fmi3Int32 *)p;
        else if (is(type, "UInt32")) x = *(const fmi3UInt32 *)p;
        else if (is(type, "Int64")) x = (double)*(const fmi3Int64 *)p;
        else if (is(type, "UInt64")) x = (double)*(const fmi3UInt64 *)p;
        else if (is(type, "Boolean")) x = *(const fmi3Boolean *)p;
        else return 0;
        s[c] = x;
#if defined(MODEL_FEEDTHROUGH)
        if (vr % 2 == 1) slot(m, vr + 1)[c] = x;  /* y_T = u_T */
        if (vr == 101) m->arr[c] = x;
#endif
    }
    return 1;
}

GETSET(Float64, fmi3Float64) GETSET(Float32, fmi3Float32) GETSET(Int8, fmi3Int8)
GETSET(UInt8, fmi3UInt8) GETSET(Int16, fmi3Int16) GETSET(UInt16, fmi3UInt16)
GETSET(Int32, fmi3Int32) GETSET(UInt32, fmi3UInt32) GETSET(Int64, fmi3Int64)
GETSET(UInt64, fmi3UInt64) GETSET(Boolean, fmi3Boolean)

fmi3Status fmi3GetString(fmi3Instance i, const fmi3ValueReference vr[], size_t n,
                         fmi3String v[], size_t nv) {
    M *m = i; (void)nv;
    for (size_t j = 0; j < n; j++) { if (vr[j] != 23 && vr[j] != 24) return fmi3Error;
                                     v[j] = m->str; }
    return fmi3OK; }
fmi3Status fmi3SetString(fmi3Instance i, const fmi3ValueReference vr[], size_t n,
                         const fmi3String v[], size_t nv) {
    M *m = i; (void)nv;
    for (size_t j = 0; j < n; j++) { if (vr[j] != 23) return fmi3Error;
                                     free(m->str); m->str = strdup(v[j]); }
    return fmi3OK; }
fmi3Status fmi3GetBinary(fmi3Instance i, const fmi3ValueReference vr[], size_t n,
                         size_t sizes[], fmi3Binary v[], size_t nv) {
    M *m = i; (void)nv;
    for (size_t j = 0; j < n; j++) { if (vr[j] != 25 && vr[j] != 26) return fmi3Error;
                                     v[j] = m->bin; sizes[j] = m->binSize; }
    return fmi3OK; }
fmi3Status fmi3SetBinary(fmi3Instance i, const fmi3ValueReference vr[], size_t n,
                         const size_t sizes[], const fmi3Binary v[], size_t nv) {
    M *m = i; (void)nv;
    for (size_t j = 0; j < n; j++) {
        if (vr[j] != 25 || sizes[j] > sizeof m->bin) return fmi3Error;
        memcpy(m->bin, v[j], sizes[j]); m->binSize = sizes[j]; }
    return fmi3OK; }

/* ---- clocks (Countdown: the clock "tick", value reference 10) ---- */
fmi3Status fmi3SetClock(fmi3Instance i, const fmi3ValueReference vr[], size_t n,
                        const fmi3Clock v[]) {
    M *m = i;
#if defined(CLOCK_TRIGGERED)
    if (!m->inEvent) { say(m, "fmi3SetClock outside Event Mode refused"); return fmi3Error; }
#endif
    for (size_t j = 0; j < n; j++) { if (vr[j] != 10) return fmi3Error; if (v[j]) m->tick = 1; }
    return fmi3OK; }
fmi3Status fmi3GetClock(fmi3Instance i, const fmi3ValueReference vr[], size_t n, fmi3Clock v[]) {
    M *m = i;
    for (size_t j = 0; j < n; j++)
        v[j] = vr[j] == 17 && m->time >= m->next - m->tol ? fmi3ClockActive : fmi3ClockInactive;
    return fmi3OK; }
fmi3Status fmi3GetIntervalDecimal(fmi3Instance i, const fmi3ValueReference vr[], size_t n,
                                  fmi3Float64 iv[], fmi3IntervalQualifier q[]) {
    M *m = i;
    for (size_t j = 0; j < n; j++) {
        if (vr[j] != 10) return fmi3Error;
        iv[j] = m->interval;
        q[j] = m->pending ? fmi3IntervalChanged : fmi3IntervalUnchanged;
#if defined(MODEL_COUNTDOWN)
        iv[j] = m->init ? m->first : m->report;
        if (m->init) q[j] = fmi3IntervalChanged;
#elif defined(CLOCK_CHANGING)
        if (m->init) q[j] = fmi3IntervalChanged; /* the first interval */
#endif
    }
    if (!m->init) m->pending = fmi3False;
    return fmi3OK; }
fmi3Status fmi3GetIntervalFraction(fmi3Instance i, const fmi3ValueReference vr[], size_t n,
                                   fmi3UInt64 counters[], fmi3UInt64 resolutions[],
                                   fmi3IntervalQualifier q[]) {
    M *m = i;
    for (size_t j = 0; j < n; j++) {
        if (vr[j] != 10) return fmi3Error;
        counters[j] = (fmi3UInt64)m->interval_counter;
        resolutions[j] = (fmi3UInt64)m->resolution;
        q[j] = m->pending ? fmi3IntervalChanged : fmi3IntervalUnchanged;
    }
    m->pending = fmi3False;
    return fmi3OK; }
fmi3Status fmi3GetShiftFraction(fmi3Instance i, const fmi3ValueReference vr[], size_t n,
                                fmi3UInt64 counters[], fmi3UInt64 resolutions[]) {
    M *m = i;
    for (size_t j = 0; j < n; j++) {
        if (vr[j] != 10) return fmi3Error;
        counters[j] = (fmi3UInt64)m->shift_counter;
        resolutions[j] = (fmi3UInt64)m->resolution;
    }
    return fmi3OK; }
fmi3Status fmi3GetShiftDecimal(fmi3Instance i, const fmi3ValueReference vr[], size_t n,
                               fmi3Float64 shifts[]) {
    M *m = i;
    for (size_t j = 0; j < n; j++) { if (vr[j] != 10) return fmi3Error; shifts[j] = m->shift; }
    return fmi3OK; }
