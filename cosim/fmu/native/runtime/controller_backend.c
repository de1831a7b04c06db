/*
 * controller_backend.c: the sampled controllers' event policy on the native runtime
 * (runtime.c, the twin of CoreSlave: variables, their checks, logging, the FMU-state image),
 * the C twin of cosim/fmu/slave.py's SampledControllerSlave over one online law (law.h).
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
 *  - the FMU state is complete: values (the runtime's), timing, shown outputs and the law's
 *    committed state.
 *
 * Variables come from the generated <id>_decl.h (the Python FMU's declarations).
 */
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "runtime.h"
#include "law.h"
#include "ato_model.h" /* generated: includes <id>_decl.h */

#define STATE_MAGIC "ATO-" ATO_MODEL_IDENTIFIER "-controller-state-1"

typedef struct {
    ato_inst rt;            /* the runtime's: values (parameters and inputs), strings, timing */
    double out[ATO_N_VARS]; /* outputs shown */
    int64_t now, next;
    int64_t done; /* instant of the last committed event, if has_done */
    int has_done;
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

#define V(m) ((m)->rt.r)
#define CORE(m) ((law_core*)(m)->rt.core)
#define fmt ato_fmt

static ato_values values_of(inst* m) {
    ato_values p = {V(m), m->rt.str, m->rt.resources};
    return p;
}

/* -- core and timing ------------------------------------------------------------------------ */
static void free_core(ato_inst* rt) {
    inst* m = (inst*)rt;
    if (!m->rt.core) return;
    law_free(CORE(m));
    m->rt.core = NULL;
    free(m->committed);
    free(m->tent_after);
    m->committed = m->tent_after = NULL;
    m->tent_valid = 0;
}

static int64_t sample_ticks(const inst* m) { return ato_to_ticks(V(m)[ATO_VR_sample_time]); }

static void show(inst* m, const double* outputs, int64_t next_event, long executions) {
    if (outputs)
        for (int i = 0; i < ATO_N_VARS; i++)
            if (ATO_VARS[i].causality == ATO_OUTPUT && i != ATO_VR_next_event_time &&
                i != ATO_VR_executions)
                m->out[i] = outputs[i];
    m->out[ATO_VR_next_event_time] = ato_to_seconds(next_event);
    m->out[ATO_VR_executions] = (double)executions;
}

/* check_declared (cosim/fmu/declare.py) for the declared ranges of the generated table: the
 * first parameter outside its [min, max]; NULL when all keep them */
static int declared_ranges_hold(inst* m, char* err, size_t n) {
    for (int i = 0; i < ATO_N_VARS; i++) {
        const ato_var* v = &ATO_VARS[i];
        if (v->causality != ATO_PARAMETER || v->type == ATO_STRING || v->type == ATO_BOOLEAN)
            continue;
        double x = V(m)[i];
        int low = v->has_min && !(x >= v->min), high = v->has_max && !(x <= v->max);
        if (low || high) {
            snprintf(err, n, "%s = %s: must be at %s %s", v->name, fmt(x).s,
                     low ? "least" : "most", fmt(low ? v->min : v->max).s);
            return 0;
        }
    }
    return 1;
}

static int ensure_core(ato_inst* rt) {
    inst* m = (inst*)rt;
    if (m->rt.core) return 1;
    char err[1024] = "";
    if (!declared_ranges_hold(m, err, sizeof err)) {
        ATO_ERROR(rt, "%s: bad parameter: %s", rt->name, err);
        return 0;
    }
    ato_values p = values_of(m);
    rt->core = law_make(&p, ato_to_seconds(rt->start_ticks), err, sizeof err);
    if (!rt->core) {
        ATO_ERROR(rt, "%s: bad parameter: %s", rt->name, err);
        return 0;
    }
    m->state_size = law_state_size(CORE(m));
    m->committed = malloc(m->state_size ? m->state_size : 1);
    m->tent_after = malloc(m->state_size ? m->state_size : 1);
    m->tent_valid = 0;
    law_outputs(CORE(m), m->out);
    show(m, NULL, m->next, rt->executions);
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
        if (ATO_VARS[i].causality == ATO_INPUT && !(V(m)[i] == m->tent_in[i])) return 0;
    return 1;
}

/* the due event computed from the current inputs, not committed (the law's state is put back) */
static int compute_tentative(inst* m) {
    if (m->tent_valid && m->tent_now == m->now && inputs_equal(m)) return 1;
    char err[1024] = "";
    ato_values p = values_of(m);
    law_get_state(CORE(m), m->committed);
    int hold = law_compute(CORE(m), ato_to_seconds(m->now), &p, m->tent_out, err, sizeof err);
    if (hold <= 0) {
        law_set_state(CORE(m), m->committed);
        m->tent_valid = 0;
        ATO_ERROR(&m->rt, "%s: %s", m->rt.name, err);
        return 0;
    }
    law_get_state(CORE(m), m->tent_after);
    law_set_state(CORE(m), m->committed);
    memcpy(m->tent_in, V(m), sizeof m->tent_in);
    m->tent_now = m->now;
    m->tent_hold = hold;
    m->tent_valid = 1;
    return 1;
}

static int refresh_outputs(inst* m) {
    if (!(m->rt.initialized && event_due(m))) return 1;
    if (m->tent_valid && m->shown_valid && m->shown_now == m->now &&
        m->shown_serial == m->serial)
        return 1;
    if (!compute_tentative(m)) return 0;
    show(m, m->tent_out, grid_event(m) + m->tent_hold * sample_ticks(m), m->rt.executions + 1);
    m->shown_valid = 1;
    m->shown_now = m->now;
    m->shown_serial = m->serial;
    return 1;
}

/* -- the runtime's hooks --------------------------------------------------------------------- */
static void starts(ato_inst* rt) {
    inst* m = (inst*)rt;
    for (int i = 0; i < ATO_N_VARS; i++) m->out[i] = ATO_VARS[i].start;
}

static void setup(ato_inst* rt) {
    inst* m = (inst*)rt;
    m->now = m->next = rt->start_ticks;
    m->has_done = 0;
    m->tent_valid = 0;
}

static void reset(ato_inst* rt) {
    inst* m = (inst*)rt;
    m->now = m->next = 0;
    m->has_done = 0;
    m->shown_valid = 0;
    m->held_logged = 0;
}

/* outputs as shown: the due event computed from the current inputs first */
static int get_output(ato_inst* rt, unsigned vr, double* out) {
    inst* m = (inst*)rt;
    if (!ensure_core(rt) || !refresh_outputs(m)) return 0;
    *out = m->out[vr];
    return 1;
}

static void input_set(ato_inst* rt) { ((inst*)rt)->serial++; }

static fmi2Status do_step(ato_inst* rt, double t, double h) {
    inst* m = (inst*)rt;
    if (!isfinite(t) || ato_to_ticks(t) != m->now) {
        ATO_ERROR(rt, "doStep at t=%s s, but this controller is at t=%s s (a step must "
                  "continue from the end of the previous one)", fmt(t).s,
                  fmt(ato_to_seconds(m->now)).s);
        return fmi2Error;
    }
    int64_t end = ato_to_ticks(t + h);
    for (;;) { /* each event in [now, end): those after the first with the inputs held */
        int due = event_due(m);
        int64_t following;
        if (due) {
            if (!compute_tentative(m)) return fmi2Error;
            following = grid_event(m) + m->tent_hold * sample_ticks(m);
        } else {
            following = m->next;
        }
        if (following < end && V(m)[ATO_VR_strict_steps] != 0.0) {
            ATO_ERROR(rt, "%s: doStep from t=%s s to t=%s s passes over this "
                      "controller's event at t=%s s (sample_time %s s) and strict_steps is "
                      "true: use communication steps that end on its sample instants (at most "
                      "sample_time long)", rt->name, fmt(t).s, fmt(ato_to_seconds(end)).s,
                      fmt(ato_to_seconds(following)).s, fmt(V(m)[ATO_VR_sample_time]).s);
            return fmi2Error;
        }
        if (due) { /* commit the event computed from the inputs of this doStep */
            m->next = following;
            m->done = m->now;
            m->has_done = 1;
            rt->executions++;
            show(m, m->tent_out, following, rt->executions);
            law_set_state(CORE(m), m->tent_after);
            m->tent_valid = 0;
        }
        if (following >= end) break;
        if (!m->held_logged) {
            m->held_logged = 1;
            ato_log(rt, fmi2Warning, "%s: doStep from t=%s s to t=%s s passes over this "
                    "controller's event at t=%s s (sample_time %s s): its events inside a "
                    "step are executed with the inputs held at the step's start (said once; "
                    "strict_steps = true refuses such steps)", rt->name, fmt(t).s,
                    fmt(ato_to_seconds(end)).s, fmt(ato_to_seconds(following)).s,
                    fmt(V(m)[ATO_VR_sample_time]).s);
        }
        m->now = following;
    }
    m->now = end;
    return fmi2OK;
}

/* -- the controller's part of the FMU state: shown outputs, timing, the law's state ---------- */
static void save(ato_inst* rt, ato_buf* b) {
    inst* m = (inst*)rt;
    ato_put(b, m->out, sizeof m->out);
    int32_t flags[2] = {rt->initialized, m->has_done};
    ato_put(b, flags, sizeof flags);
    int64_t ticks[4] = {rt->start_ticks, m->now, m->next, m->done};
    ato_put(b, ticks, sizeof ticks);
    int64_t ex = rt->executions;
    ato_put(b, &ex, sizeof ex);
    uint64_t size = m->state_size;
    ato_put(b, &size, sizeof size);
    law_get_state(CORE(m), m->committed); /* the committed state: the core holds no other */
    ato_put(b, m->committed, m->state_size);
}

static int same_parameters(const inst* m, const double* v, char* const* str) {
    for (int i = 0; i < ATO_N_VARS; i++) {
        if (ATO_VARS[i].causality != ATO_PARAMETER) continue;
        if (ATO_VARS[i].type == ATO_STRING ? strcmp(m->rt.str[i], str[i]) != 0
                                           : !(V(m)[i] == v[i]))
            return 0;
    }
    return 1;
}

static fmi2Status load(ato_inst* rt, ato_rd* r, double* values, char** strs) {
    inst* m = (inst*)rt;
    double outs[ATO_N_VARS];
    ato_take(r, outs, sizeof outs);
    int32_t flags[2];
    int64_t ticks[4], ex;
    uint64_t size = 0;
    ato_take(r, flags, sizeof flags);
    ato_take(r, ticks, sizeof ticks);
    ato_take(r, &ex, sizeof ex);
    ato_take(r, &size, sizeof size);
    const unsigned char* core_bytes = r->ok && r->at + size <= r->n ? r->p + r->at : NULL;
    if (!core_bytes) {
        ato_drop_values(values, strs);
        ATO_ERROR(rt, "truncated FMU state");
        return fmi2Error;
    }
    int keep = rt->core && same_parameters(m, values, strs);
    ato_adopt_values(rt, values, strs);
    rt->start_ticks = ticks[0];
    m->now = ticks[1];
    m->next = ticks[2];
    m->done = ticks[3];
    m->has_done = flags[1];
    rt->executions = (long)ex;
    if (!keep) {
        free_core(rt);
        rt->initialized = 0;
        if (!ensure_core(rt)) return fmi2Error;
    }
    if (size != m->state_size) {
        ATO_ERROR(rt, "FMU state: %llu bytes of controller state, this core has %zu",
                  (unsigned long long)size, m->state_size);
        return fmi2Error;
    }
    law_set_state(CORE(m), core_bytes);
    memcpy(m->out, outs, sizeof outs);
    m->tent_valid = 0;
    m->shown_valid = 0;
    rt->initialized = flags[0];
    return fmi2OK;
}

static const ato_identity IDENTITY = {ATO_MODEL_IDENTIFIER, ATO_GUID, STATE_MAGIC, ATO_N_VARS,
                                      ATO_VARS};

const ato_policy ATO_POLICY = {
    "native C controller " ATO_MODEL_IDENTIFIER, ATO_VR_next_event_time, &IDENTITY,
    sizeof(inst), 1200, 1,
    ensure_core, free_core, starts, setup, reset, get_output, input_set, do_step, 1, save, load,
};
