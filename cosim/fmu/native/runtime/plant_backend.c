/*
 * plant_backend.c: the plants' stepping policy on the native runtime (runtime.c), over
 * one plant model (ATO_MODEL, see plant_backend.h): PlantSlave's stepping.
 *
 * The core is built from the parameters at the end of initialisation (or at the first output
 * read) and dropped when a parameter or the start time changes; every doStep advances it and
 * computes the outputs into the variables; the plant's part of the FMU state is its
 * calling-sequence data (initialised, core built, start time, executions), then the core's.
 */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "plant_backend.h"

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

/* a new start time: the core is built again from it */
static void setup(ato_inst* m) { free_core(m); }

/* outputs from the core, computed after every step */
static int get_output(ato_inst* m, unsigned vr, double* out) {
    if (!ensure_core(m)) return 0;
    *out = m->r[vr];
    return 1;
}

static fmi2Status do_step(ato_inst* m, double t, double h) {
    if (!isfinite(t)) {
        ATO_ERROR(m, "doStep: time %g is not finite", t);
        return fmi2Error;
    }
    if (!ATO_MODEL.step(m, m->core, ato_to_ticks(t), ato_to_ticks(h))) return fmi2Error;
    ATO_MODEL.outputs(m, m->core);
    m->executions++;
    return fmi2OK;
}

/* -- the plant's part of the FMU state: calling sequence, then the core --------------------- */
static void save(ato_inst* m, ato_buf* b) {
    int32_t flags[2] = {m->initialized, m->core != NULL};
    ato_put(b, flags, sizeof flags);
    ato_put(b, &m->start_ticks, sizeof m->start_ticks);
    int64_t ex = m->executions;
    ato_put(b, &ex, sizeof ex);
    if (m->core) ATO_MODEL.save(m->core, b);
}

static fmi2Status load(ato_inst* m, ato_rd* r, double* values, char** strs) {
    int32_t flags[2];
    int64_t start, ex;
    ato_take(r, flags, sizeof flags);
    ato_take(r, &start, sizeof start);
    ato_take(r, &ex, sizeof ex);
    if (!r->ok) {
        ato_drop_values(values, strs);
        ATO_ERROR(m, "truncated FMU state");
        return fmi2Error;
    }
    free_core(m);
    ato_adopt_values(m, values, strs);
    m->start_ticks = start;
    m->executions = (long)ex;
    m->initialized = 0;
    if (flags[1]) {
        if (!ensure_core(m)) return fmi2Error;
        if (!ATO_MODEL.load(m->core, r) || !r->ok) {
            free_core(m);
            ATO_ERROR(m, "truncated FMU state");
            return fmi2Error;
        }
        ATO_MODEL.outputs(m, m->core);
    }
    m->initialized = flags[0];
    return fmi2OK;
}

const ato_policy ATO_POLICY = {
    "native C model (plant_backend.c)", -1, &ATO_MODEL.id, sizeof(ato_inst), 1024, 0,
    ensure_core, free_core, NULL, setup, NULL, get_output, NULL, do_step, 0, save, load,
};
