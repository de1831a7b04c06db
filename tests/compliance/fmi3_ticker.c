/*
 * A small FMI 3.0 co-simulation FMU written from the standard alone (no code of this project),
 * the third-party stand-in of the FMI 3 compliance tests: a ticker with time events.
 *
 *   output Int32   ticks  number of time events so far (one at every k * PERIOD, k >= 0)
 *   input  Float64 u      ;  output Float64 y = u (direct feedthrough)
 *   independent    time
 *
 * hasEventMode: in Event Mode fmi3UpdateDiscreteStates handles a due tick and returns
 * nextEventTime = the next multiple of PERIOD; fmi3DoStep stops at a tick with earlyReturn when
 * allowed (mightReturnEarlyFromDoStep) and sets eventHandlingNeeded there. FMU state: get/set.
 *
 * Planted faults for the checks' own tests (compile with -D...):
 *   FAULT_PAST_EVENT   nextEventTime is one period in the past
 *   FAULT_STATE        fmi3SetFMUState restores nothing
 *
 * The functions this FMU does not provide are stubs in fmi3_ticker_stubs.c.
 */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "fmi3Functions.h"

#define PERIOD 0.3
enum { VR_TIME = 0, VR_TICKS = 1, VR_U = 2, VR_Y = 3 };
enum { INSTANTIATED, INIT, EVENT, STEP, TERMINATED };

typedef struct {
    double time, u;
    int ticks, mode, event_mode_used, early_allowed;
    long long next_tick; /* index k of the next tick not yet counted */
} Ticker;

static double tick_time(long long k) { return k * PERIOD; }

static void count_due(Ticker* m)
{
    while (tick_time(m->next_tick) <= m->time + 1e-12) {
        m->ticks++;
        m->next_tick++;
    }
}

fmi3Instance fmi3InstantiateCoSimulation(fmi3String name, fmi3String token, fmi3String res,
                                         fmi3Boolean visible, fmi3Boolean loggingOn,
                                         fmi3Boolean eventModeUsed,
                                         fmi3Boolean earlyReturnAllowed,
                                         const fmi3ValueReference req[], size_t nreq,
                                         fmi3InstanceEnvironment env,
                                         fmi3LogMessageCallback log,
                                         fmi3IntermediateUpdateCallback update)
{
    (void)name, (void)token, (void)res, (void)visible, (void)loggingOn, (void)req, (void)nreq;
    (void)env, (void)log, (void)update;
    Ticker* m = calloc(1, sizeof *m);
    m->event_mode_used = eventModeUsed;
    m->early_allowed = earlyReturnAllowed;
    return m;
}

void fmi3FreeInstance(fmi3Instance c) { free(c); }

fmi3Status fmi3EnterInitializationMode(fmi3Instance c, fmi3Boolean tolDef, fmi3Float64 tol,
                                       fmi3Float64 start, fmi3Boolean stopDef, fmi3Float64 stop)
{
    Ticker* m = c;
    (void)tolDef, (void)tol, (void)stopDef, (void)stop;
    if (m->mode != INSTANTIATED)
        return fmi3Error;
    m->time = start;
    m->ticks = 0;
    m->next_tick = (long long)ceil(start / PERIOD - 1e-9);
    m->mode = INIT;
    return fmi3OK;
}

fmi3Status fmi3ExitInitializationMode(fmi3Instance c)
{
    Ticker* m = c;
    if (m->mode != INIT)
        return fmi3Error;
    m->mode = m->event_mode_used ? EVENT : STEP;
    if (!m->event_mode_used)
        count_due(m);
    return fmi3OK;
}

fmi3Status fmi3EnterEventMode(fmi3Instance c)
{
    Ticker* m = c;
    if (m->mode != STEP || !m->event_mode_used)
        return fmi3Error;
    m->mode = EVENT;
    return fmi3OK;
}

fmi3Status fmi3EnterStepMode(fmi3Instance c)
{
    Ticker* m = c;
    if (m->mode != EVENT)
        return fmi3Error;
    m->mode = STEP;
    return fmi3OK;
}

fmi3Status fmi3UpdateDiscreteStates(fmi3Instance c, fmi3Boolean* need, fmi3Boolean* term,
                                    fmi3Boolean* nominals, fmi3Boolean* values,
                                    fmi3Boolean* defined, fmi3Float64* next)
{
    Ticker* m = c;
    if (m->mode != EVENT)
        return fmi3Error;
    count_due(m);
    *need = *term = *nominals = *values = fmi3False;
    *defined = fmi3True;
    *next = tick_time(m->next_tick);
#ifdef FAULT_PAST_EVENT
    *next -= 2 * PERIOD;
#endif
    return fmi3OK;
}

fmi3Status fmi3DoStep(fmi3Instance c, fmi3Float64 t, fmi3Float64 h, fmi3Boolean noSet,
                      fmi3Boolean* event, fmi3Boolean* term, fmi3Boolean* early,
                      fmi3Float64* last)
{
    Ticker* m = c;
    double end = t + h, tick;
    (void)noSet;
    if (m->mode != STEP || !(h > 0))
        return fmi3Error;
    *event = *term = *early = fmi3False;
    tick = tick_time(m->next_tick);
    if (m->event_mode_used && m->early_allowed && tick > t + 1e-12 && tick < end - 1e-12) {
        end = tick;
        *early = fmi3True;
    }
    m->time = end;
    if (m->event_mode_used)
        *event = fabs(tick - end) <= 1e-12 || tick < end;
    else
        count_due(m);
    *last = end;
    return fmi3OK;
}

fmi3Status fmi3Terminate(fmi3Instance c)
{
    Ticker* m = c;
    if (m->mode != STEP && m->mode != EVENT)
        return fmi3Error;
    m->mode = TERMINATED;
    return fmi3OK;
}

fmi3Status fmi3Reset(fmi3Instance c)
{
    Ticker* m = c;
    int used = m->event_mode_used, early = m->early_allowed;
    memset(m, 0, sizeof *m);
    m->event_mode_used = used;
    m->early_allowed = early;
    return fmi3OK;
}

fmi3Status fmi3GetFloat64(fmi3Instance c, const fmi3ValueReference vr[], size_t n,
                          fmi3Float64 v[], size_t nv)
{
    Ticker* m = c;
    (void)nv;
    if (m->mode == INSTANTIATED)
        return fmi3Error;
    for (size_t i = 0; i < n; ++i) {
        if (vr[i] == VR_TIME)
            v[i] = m->time;
        else if (vr[i] == VR_U || vr[i] == VR_Y)
            v[i] = m->u;
        else
            return fmi3Error;
    }
    return fmi3OK;
}

fmi3Status fmi3SetFloat64(fmi3Instance c, const fmi3ValueReference vr[], size_t n,
                          const fmi3Float64 v[], size_t nv)
{
    Ticker* m = c;
    (void)nv;
    for (size_t i = 0; i < n; ++i) {
        if (vr[i] != VR_U)
            return fmi3Error;
        m->u = v[i];
    }
    return fmi3OK;
}

fmi3Status fmi3GetInt32(fmi3Instance c, const fmi3ValueReference vr[], size_t n,
                        fmi3Int32 v[], size_t nv)
{
    Ticker* m = c;
    (void)nv;
    for (size_t i = 0; i < n; ++i) {
        if (vr[i] != VR_TICKS)
            return fmi3Error;
        v[i] = m->ticks;
    }
    return fmi3OK;
}

fmi3Status fmi3GetFMUState(fmi3Instance c, fmi3FMUState* s)
{
    Ticker* copy = *s ? *s : malloc(sizeof *copy);
    memcpy(copy, c, sizeof *copy);
    *s = copy;
    return fmi3OK;
}

fmi3Status fmi3SetFMUState(fmi3Instance c, fmi3FMUState s)
{
#ifndef FAULT_STATE
    memcpy(c, s, sizeof(Ticker));
#else
    (void)c, (void)s;
#endif
    return fmi3OK;
}

fmi3Status fmi3FreeFMUState(fmi3Instance c, fmi3FMUState* s)
{
    (void)c;
    free(*s);
    *s = NULL;
    return fmi3OK;
}

const char* fmi3GetVersion(void) { return fmi3Version; }
