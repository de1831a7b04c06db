/* A small FMI 3.0 Scheduled Execution FMU for the tests: Tasks, four model partitions.
     fast  (vr 1, constant clock, interval 0.1 s, priority 1): n_fast += 1, y += u; at its
           alarm_after-th activation it sets the countdown clock alarm to alarm_delay
     slow  (vr 2, fixed clock: interval slow_interval, shift slow_shift, priority 0):
           n_slow += 1, ticks the output clock done
     alarm (vr 3, countdown clock, priority 2): n_alarm += 1, t_alarm = activation time
     kick  (vr 4, triggered clock, priority 3): n_kick += 1, t_kick = activation time
   Every activation is logged as "activate <clock> at <time>" (%.17g). With SLOW_CHANGING slow
   is a changing clock instead: its first interval slow_interval, doubled at each activation
   (fmi3GetIntervalDecimal gives it with fmi3IntervalChanged). */
#include <stdio.h>
#include <stdlib.h>
#include "fmi3Functions.h"

enum { FAST = 1, SLOW, ALARM, KICK, DONE, SLOW_INTERVAL = 10, SLOW_SHIFT, ALARM_AFTER,
       ALARM_DELAY, U = 20, N_FAST, N_SLOW, N_ALARM, N_KICK, Y, T_ALARM, T_KICK };

typedef struct {
    fmi3Float64 slow_interval, slow_shift, alarm_delay, u, y, t_alarm, t_kick, alarm_interval;
    fmi3Int32 alarm_after, n_fast, n_slow, n_alarm, n_kick;
    fmi3IntervalQualifier alarm_qualifier;
    fmi3Boolean done;
    fmi3LogMessageCallback log; fmi3ClockUpdateCallback update; fmi3InstanceEnvironment env;
} M;

static const char *NAMES[] = {"", "fast", "slow", "alarm", "kick"};

fmi3Instance fmi3InstantiateScheduledExecution(fmi3String name, fmi3String token,
    fmi3String res, fmi3Boolean visible, fmi3Boolean loggingOn, fmi3InstanceEnvironment env,
    fmi3LogMessageCallback log, fmi3ClockUpdateCallback update,
    fmi3LockPreemptionCallback lock, fmi3UnlockPreemptionCallback unlock) {
    (void)name; (void)token; (void)res; (void)visible; (void)loggingOn; (void)lock;
    (void)unlock;
    M *m = calloc(1, sizeof(M));
    m->slow_interval = 0.25; m->alarm_after = 5; m->alarm_delay = 0.05;
    m->alarm_qualifier = fmi3IntervalNotYetKnown;
    m->log = log; m->update = update; m->env = env;
    return m;
}
void fmi3FreeInstance(fmi3Instance i) { free(i); }
const char *fmi3GetVersion(void) { return fmi3Version; }
fmi3Status fmi3SetDebugLogging(fmi3Instance i, fmi3Boolean on, size_t n, const fmi3String c[]) {
    (void)i; (void)on; (void)n; (void)c; return fmi3OK; }
fmi3Status fmi3EnterInitializationMode(fmi3Instance i, fmi3Boolean td, fmi3Float64 tol,
    fmi3Float64 start, fmi3Boolean sd, fmi3Float64 stop) {
    (void)i; (void)td; (void)tol; (void)start; (void)sd; (void)stop; return fmi3OK; }
fmi3Status fmi3ExitInitializationMode(fmi3Instance i) { (void)i; return fmi3OK; }
fmi3Status fmi3Terminate(fmi3Instance i) { (void)i; return fmi3OK; }
fmi3Status fmi3Reset(fmi3Instance i) { (void)i; return fmi3Error; }

static fmi3Float64 *real(M *m, fmi3ValueReference vr) {
    switch (vr) {
    case SLOW_INTERVAL: return &m->slow_interval;
    case SLOW_SHIFT: return &m->slow_shift;
    case ALARM_DELAY: return &m->alarm_delay;
    case U: return &m->u;
    case Y: return &m->y;
    case T_ALARM: return &m->t_alarm;
    case T_KICK: return &m->t_kick;
    default: return NULL;
    }
}

static fmi3Int32 *integer(M *m, fmi3ValueReference vr) {
    switch (vr) {
    case ALARM_AFTER: return &m->alarm_after;
    case N_FAST: return &m->n_fast;
    case N_SLOW: return &m->n_slow;
    case N_ALARM: return &m->n_alarm;
    case N_KICK: return &m->n_kick;
    default: return NULL;
    }
}

#define GET(NAME, T, FIND) \
fmi3Status NAME(fmi3Instance i, const fmi3ValueReference vr[], size_t n, T v[], size_t nv) { \
    (void)nv; \
    for (size_t k = 0; k < n; k++) { \
        T *p = FIND(i, vr[k]); \
        if (!p) return fmi3Error; \
        v[k] = *p; \
    } \
    return fmi3OK; }
GET(fmi3GetFloat64, fmi3Float64, real)
GET(fmi3GetInt32, fmi3Int32, integer)
#define SET(NAME, T, FIND) \
fmi3Status NAME(fmi3Instance i, const fmi3ValueReference vr[], size_t n, const T v[], \
                size_t nv) { \
    (void)nv; \
    for (size_t k = 0; k < n; k++) { \
        T *p = FIND(i, vr[k]); \
        if (!p) return fmi3Error; \
        *p = v[k]; \
    } \
    return fmi3OK; }
SET(fmi3SetFloat64, fmi3Float64, real)
SET(fmi3SetInt32, fmi3Int32, integer)

fmi3Status fmi3GetClock(fmi3Instance i, const fmi3ValueReference vr[], size_t n,
                        fmi3Clock v[]) {
    M *m = i;
    for (size_t k = 0; k < n; k++) {
        if (vr[k] != DONE) return fmi3Error;
        v[k] = m->done; m->done = fmi3False; /* a tick is reported once */
    }
    return fmi3OK;
}

fmi3Status fmi3GetIntervalDecimal(fmi3Instance i, const fmi3ValueReference vr[], size_t n,
                                  fmi3Float64 v[], fmi3IntervalQualifier q[]) {
    M *m = i;
    for (size_t k = 0; k < n; k++) {
        if (vr[k] == SLOW) { v[k] = m->slow_interval; q[k] = fmi3IntervalChanged; }
        else if (vr[k] == ALARM) {
            q[k] = m->alarm_qualifier; v[k] = m->alarm_interval;
            if (m->alarm_qualifier == fmi3IntervalChanged)
                m->alarm_qualifier = fmi3IntervalUnchanged;
        } else return fmi3Error;
    }
    return fmi3OK;
}

fmi3Status fmi3GetShiftDecimal(fmi3Instance i, const fmi3ValueReference vr[], size_t n,
                               fmi3Float64 v[]) {
    M *m = i;
    for (size_t k = 0; k < n; k++) {
        if (vr[k] != SLOW) return fmi3Error;
        v[k] = m->slow_shift;
    }
    return fmi3OK;
}

fmi3Status fmi3ActivateModelPartition(fmi3Instance i, fmi3ValueReference clock,
                                      fmi3Float64 time) {
    M *m = i;
    if (clock < FAST || clock > KICK) return fmi3Error;
    char msg[64];
    snprintf(msg, sizeof msg, "activate %s at %.17g", NAMES[clock], time);
    m->log(m->env, fmi3OK, "log", msg);
    switch (clock) {
    case FAST:
        m->n_fast++; m->y += m->u;
        if (m->n_fast == m->alarm_after) {
            m->alarm_interval = m->alarm_delay; m->alarm_qualifier = fmi3IntervalChanged;
            m->update(m->env);
        }
        break;
    case SLOW:
        m->n_slow++; m->done = fmi3True; m->update(m->env);
#if defined(SLOW_CHANGING)
        m->slow_interval *= 2;
#endif
        break;
    case ALARM: m->n_alarm++; m->t_alarm = time; break;
    default: m->n_kick++; m->t_kick = time; break;
    }
    return fmi3OK;
}
