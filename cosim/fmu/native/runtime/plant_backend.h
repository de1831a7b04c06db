/*
 * plant_backend.h: the generic native backend of the plant models (plant_backend.c)
 * and the interface of a model to it.
 *
 * plant_backend.c is the plants' stepping policy on the runtime (runtime.h, which
 * holds the variables, their checks, logging and the FMU-state image): the core built from
 * the parameters at the end of initialisation (or at the first output read), a doStep
 * advancing it and computing the outputs, and the plant's part of the FMU state
 * (calling-sequence data, then the model's core). A model file defines ATO_MODEL: its core's
 * life cycle, step, outputs and state.
 */
#ifndef ATO_PLANT_BACKEND_H
#define ATO_PLANT_BACKEND_H

#include <stddef.h>
#include <stdint.h>

#include "minmax.h"
#include "runtime.h"

#define ATO_TICKS_PER_SECOND 1000000000LL

typedef struct ato_model {
    ato_identity id; /* identifier, GUID, state magic, variable table */
    /* the core from the parameters in m->r / m->str (start time m->start_ticks); NULL after
     * logging why */
    void* (*create)(ato_inst* m);
    void (*destroy)(void* core);
    /* advance from tick t by h ticks with the inputs in m->r; 0 after logging an error */
    int (*step)(ato_inst* m, void* core, int64_t t, int64_t h);
    /* write every output's value into m->r */
    void (*outputs)(ato_inst* m, void* core);
    /* the core's state (everything create does not rebuild from the parameters) */
    void (*save)(const void* core, ato_buf* b);
    int (*load)(void* core, ato_rd* r);
} ato_model;

extern const ato_model ATO_MODEL; /* defined by the model file */

/* the sub-step ends of plants.dead_time.substep_ends(t, h, grids) (no history): every
 * absolute multiple of each grid > 0 inside (t, t + h) and t + h, sorted, each once; returns
 * their number, *cuts malloc'ed */
size_t ato_substep_ends(int64_t t, int64_t h, const int64_t* grids, int n_grids,
                        int64_t** cuts);
/* the same with the instants among acts[0 .. n_acts - 1] inside (t, t + h) cut too (where a
 * delayed command acts: plants.dead_time.substep_ends with a history) */
size_t ato_substep_ends_acting(int64_t t, int64_t h, const int64_t* grids, int n_grids,
                               const int64_t* acts, size_t n_acts, int64_t** cuts);

#endif
