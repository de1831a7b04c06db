/* The event-driven algorithm's communication points in C (cosim/run/master/native_loop.py).
 *
 * The same points, calls and order as cosim.run.master.algorithms.EventDriven.run for FMI 2.0
 * co-simulation FMUs called through their C functions: at each point the values flow (the
 * plan of the FMUs due there: each stage's fmi2Get<type> calls, the connections' change
 * counts, then its copies and fmi2Set<type> calls), the output row is read when it is an
 * output point, the schedules of the FMUs due there are updated (periodic, or the announced
 * next_event_time), the next point is the earliest of the stop time, the next output point,
 * every scheduled FMU's next event and every limited FMU's time plus max_step, and every FMU
 * due there steps to it (fmi2DoStep in pieces of at most its max_step, inputs held).
 *
 * Times are integer nanoseconds; seconds are ticks / 1e9 and ticks llrint(seconds * 1e9),
 * as cosim.fmu.state.to_seconds / to_ticks. Anything else the Python loop does (a refused
 * step, a failed get or set, a bad announced event, a plan not built yet, a full recording,
 * a progress report every `budget` seconds of wall time) returns to Python with the loop's
 * state at the start of a point, or at the failed step, so that Python goes on from there.
 */
#define _POSIX_C_SOURCE 199309L
#include <math.h>
#include <stddef.h>
#include <stdint.h>
#include <time.h>

#define EXPORT __attribute__((visibility("default")))

typedef int (*get_real_fn)(void *, const unsigned int *, size_t, double *);
typedef int (*get_int_fn)(void *, const unsigned int *, size_t, int *);
typedef int (*set_real_fn)(void *, const unsigned int *, size_t, const double *);
typedef int (*set_int_fn)(void *, const unsigned int *, size_t, const int *);
typedef int (*do_step_fn)(void *, double, double, int);

enum { OP_GET = 0, OP_SET = 1, OP_COPY = 2, OP_TRACK = 3, OP_ROW = 4 };
enum { NOT_SCHEDULED = 0, SAMPLED = 1, ANNOUNCED = 2 };
enum {
    DONE = 0,        /* the stop time's point is done */
    YIELD = 1,       /* the budget is spent (or a history buffer is full): at a point's start */
    NEED_PLAN = 2,   /* no plan for the FMUs due at this point: at its start */
    NEED_ROWS = 3,   /* an output point and the recording is full: at its start */
    CALL_FAILED = 4, /* a get or set returned more than fmi2Warning: failed_op, status */
    BAD_EVENT = 5,   /* an announced next_event_time not after now: failed_unit, value */
    STEP_FAILED = 6  /* a doStep returned more than fmi2Warning: failed_unit, step_t/h, status */
};
#define FMI2_WARNING 1
#define CRUMB_DO_STEP 3.0 /* cosim.run.isolation.CALLS index of _do_step */
#define CRUMB_IDLE (-1.0)

typedef struct {
    int32_t kind;   /* OP_* */
    int32_t is_int; /* C int values (fmi2Integer, fmi2Boolean), else double */
    int32_t unit;   /* the FMU called (GET, SET, ROW); the connection (TRACK) */
    int32_t n;      /* values (GET, SET, ROW) */
    int64_t offset; /* ROW: the first column in the output row */
    void *fn;       /* the FMI function (GET, SET, ROW) */
    void *component;
    const unsigned int *vrs;
    void *buf; /* the values (GET, SET, an int ROW); the destination (COPY); the value (TRACK) */
    void *src; /* the source value (COPY) */
} Op;

typedef struct {
    uint64_t due; /* the FMUs due, one bit per unit */
    int64_t n_ops;
    Op *ops;
} Plan;

typedef struct {
    void *component;
    void *do_step;  /* fmi2DoStep */
    void *get_real; /* fmi2GetReal (an announced next_event_time) */
    int64_t time;   /* ticks */
    int64_t sample; /* ticks (SAMPLED) */
    int64_t max_step;
    int64_t next_event;
    int64_t do_steps;
    double wall; /* s inside this FMU's calls */
    int32_t scheduled;
    int32_t next_event_column; /* its column in the output row when read there, else -1 */
    uint32_t next_event_vr;
    int32_t crumb_index;
} Unit;

typedef struct {
    double last;
    int64_t has_last;
    int64_t changes;
    double *history; /* every new value, when kept (NULL: not kept) */
    int64_t n_history;
    int64_t capacity;
} Link;

typedef struct {
    int64_t n_units;
    Unit *units;
    int64_t n_plans;
    Plan *plans;
    int64_t n_record;
    Op *record;
    int64_t n_links;
    Link *links;
    int64_t t;
    uint64_t due;
    int64_t stop;
    int64_t next_output;
    int64_t output;
    double *store;
    int64_t width;
    int64_t rows;
    int64_t capacity;
    double *crumb; /* the isolation breadcrumb (NULL outside a child) */
    double budget; /* s of wall time before returning YIELD */
    int64_t report_at; /* ticks: YIELD once a point reaches it (a progress report) */
    /* where it stopped */
    int64_t failed_unit;
    int64_t failed_op; /* in plans[failed_plan].ops, or record ops when failed_plan == -1 */
    int64_t failed_plan;
    int64_t status;
    int64_t step_t;
    int64_t step_h;
    int64_t t_next;
    uint64_t due_next;
    double value;
} Loop;

/* The sizes the Python side's ctypes mirrors must have. */
EXPORT size_t native_loop_sizeof_op(void) { return sizeof(Op); }
EXPORT size_t native_loop_sizeof_plan(void) { return sizeof(Plan); }
EXPORT size_t native_loop_sizeof_unit(void) { return sizeof(Unit); }
EXPORT size_t native_loop_sizeof_link(void) { return sizeof(Link); }
EXPORT size_t native_loop_sizeof_loop(void) { return sizeof(Loop); }

static double now_s(void) {
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}

static double to_seconds(int64_t ticks) { return (double)ticks / 1e9; }

/* An FMI get or set: its status; the FMU's wall time accumulated as Batch.get / set do. */
static int call(Loop *lp, const Op *op, void *values) {
    Unit *u = &lp->units[op->unit];
    double t0 = now_s();
    int status;
    if (op->kind == OP_SET)
        status = op->is_int ? ((set_int_fn)op->fn)(op->component, op->vrs, (size_t)op->n,
                                                    (const int *)values)
                            : ((set_real_fn)op->fn)(op->component, op->vrs, (size_t)op->n,
                                                     (const double *)values);
    else
        status = op->is_int ? ((get_int_fn)op->fn)(op->component, op->vrs, (size_t)op->n,
                                                    (int *)values)
                            : ((get_real_fn)op->fn)(op->component, op->vrs, (size_t)op->n,
                                                     (double *)values);
    u->wall += now_s() - t0;
    return status;
}

/* Run ops[0..n): 0, or CALL_FAILED with failed_op / status set. */
static int run_ops(Loop *lp, const Op *ops, int64_t n, double *row) {
    for (int64_t i = 0; i < n; i++) {
        const Op *op = &ops[i];
        int status;
        switch (op->kind) {
        case OP_GET:
        case OP_SET:
            status = call(lp, op, op->buf);
            break;
        case OP_ROW:
            if (op->is_int) {
                status = call(lp, op, op->buf);
                const int *v = (const int *)op->buf;
                for (int32_t j = 0; j < op->n; j++) row[op->offset + j] = (double)v[j];
            } else {
                status = call(lp, op, row + op->offset);
            }
            break;
        case OP_COPY:
            if (op->is_int)
                *(int *)op->buf = *(const int *)op->src;
            else
                *(double *)op->buf = *(const double *)op->src;
            continue;
        default: { /* OP_TRACK: Stage.write's change count and history */
            Link *lk = &lp->links[op->unit];
            double v = op->is_int ? (double)*(const int *)op->buf : *(const double *)op->buf;
            int changed = lk->has_last && v != lk->last;
            if (changed) lk->changes++;
            if (lk->history && (!lk->has_last || changed))
                lk->history[lk->n_history++] = v;
            lk->last = v;
            lk->has_last = 1;
            continue;
        }
        }
        if (status > FMI2_WARNING) {
            lp->failed_op = i;
            lp->status = status;
            return CALL_FAILED;
        }
    }
    return 0;
}

static int output_point(const Loop *lp, int64_t t) {
    return t >= lp->next_output || t >= lp->stop;
}

static int64_t to_ticks(double seconds) {
    double x = seconds * 1e9;
    if (x >= 9.2e18) return INT64_MAX; /* never reached: later than any stop time */
    if (x <= -9.2e18) return INT64_MIN;
    return (int64_t)llrint(x); /* round half to even, as Python's round */
}

/* doStep of unit u from its time to `ticks`, in pieces of at most its max_step: 0, or
 * STEP_FAILED with the failed piece. */
static int step_to(Loop *lp, int64_t k, int64_t ticks) {
    Unit *u = &lp->units[k];
    while (u->time < ticks) {
        int64_t h = ticks - u->time;
        if (u->max_step && u->max_step < h) h = u->max_step;
        if (lp->crumb) {
            lp->crumb[0] = (double)u->crumb_index;
            lp->crumb[1] = CRUMB_DO_STEP;
            lp->crumb[2] = (double)u->time * 1e-9;
        }
        double t0 = now_s();
        int status = ((do_step_fn)u->do_step)(u->component, to_seconds(u->time),
                                               to_seconds(h), 1);
        u->wall += now_s() - t0;
        if (lp->crumb) lp->crumb[1] = CRUMB_IDLE;
        u->do_steps++;
        if (status > FMI2_WARNING) {
            lp->failed_unit = k;
            lp->step_t = u->time;
            lp->step_h = h;
            lp->status = status;
            return STEP_FAILED;
        }
        u->time += h;
    }
    return 0;
}

static int history_full(const Loop *lp) {
    for (int64_t i = 0; i < lp->n_links; i++) {
        const Link *lk = &lp->links[i];
        if (lk->history && lk->n_history >= lk->capacity) return 1;
    }
    return 0;
}

/* Communication points from lp->t (its values not yet moved) with lp->due due there, until
 * the stop time's point is done or something needs Python (the return code). */
EXPORT int native_loop_run(Loop *lp) {
    double started = now_s();
    for (;;) {
        int64_t t = lp->t;
        if (history_full(lp)) return YIELD;
        int recording = output_point(lp, t);
        if (recording && lp->rows >= lp->capacity) return NEED_ROWS;
        const Plan *plan = NULL;
        for (int64_t i = 0; i < lp->n_plans; i++)
            if (lp->plans[i].due == lp->due) {
                plan = &lp->plans[i];
                lp->failed_plan = i;
                break;
            }
        if (!plan) return NEED_PLAN;
        if (run_ops(lp, plan->ops, plan->n_ops, NULL)) return CALL_FAILED;
        double *row = NULL;
        if (recording) { /* first: a bad announced event below still keeps this point */
            row = lp->store + lp->rows * lp->width;
            row[0] = to_seconds(t);
            lp->failed_plan = -1;
            if (run_ops(lp, lp->record, lp->n_record, row)) return CALL_FAILED;
            lp->rows++;
            while (lp->next_output <= t) lp->next_output += lp->output;
            if (lp->next_output > lp->stop) lp->next_output = lp->stop;
        }
        for (int64_t k = 0; k < lp->n_units; k++) {
            Unit *u = &lp->units[k];
            if (u->scheduled == NOT_SCHEDULED || !(lp->due >> k & 1)) continue;
            if (u->scheduled == SAMPLED) {
                u->next_event = t + u->sample;
                continue;
            }
            double value;
            lp->status = 0;
            if (recording && u->next_event_column >= 0) {
                value = row[u->next_event_column];
            } else {
                double t0 = now_s();
                int status = ((get_real_fn)u->get_real)(u->component, &u->next_event_vr, 1,
                                                        &value);
                u->wall += now_s() - t0;
                if (status > FMI2_WARNING) { /* Python reads it again and fails */
                    value = NAN;
                    lp->status = status;
                }
            }
            int64_t next = isfinite(value) ? to_ticks(value) : t;
            if (next <= t) {
                lp->failed_unit = k;
                lp->value = value;
                return BAD_EVENT;
            }
            u->next_event = next;
        }
        if (t >= lp->stop) return DONE;
        int64_t t_next = lp->next_output < lp->stop ? lp->next_output : lp->stop;
        for (int64_t k = 0; k < lp->n_units; k++) {
            const Unit *u = &lp->units[k];
            if (u->scheduled != NOT_SCHEDULED) {
                if (u->next_event < t_next) t_next = u->next_event;
            } else if (u->max_step && u->time + u->max_step < t_next) {
                t_next = u->time + u->max_step;
            }
        }
        uint64_t due = 0;
        for (int64_t k = 0; k < lp->n_units; k++) {
            const Unit *u = &lp->units[k];
            if (u->scheduled == NOT_SCHEDULED || u->next_event == t_next) due |= 1ull << k;
        }
        lp->t_next = t_next;
        lp->due_next = due;
        for (int64_t k = 0; k < lp->n_units; k++)
            if (due >> k & 1 && step_to(lp, k, t_next)) return STEP_FAILED;
        lp->t = t_next;
        lp->due = due;
        if (t_next >= lp->report_at || now_s() - started >= lp->budget) return YIELD;
    }
}
