/*
 * ato_plant_backend.h: the generic native backend of the plant models (ato_plant_backend.c)
 * and the interface of a model to it.
 *
 * ato_plant_backend.c is an FMI 2-shaped backend (ato_backend.h) for any native model whose
 * variables are the generated ATO_VARS table: instantiation (GUID, resource URI), Real /
 * Integer / Boolean / String variables with the declared ranges, parameters fixed after
 * initialisation, doStep checks, errors logged with logging off, and the FMU state as a byte
 * image (variables, strings, calling-sequence data, then the model's core). A model file
 * defines ATO_MODEL: its core's life cycle, step, outputs and state.
 *
 * Integer and Boolean variables are kept as doubles in inst->r (exact for int32 and 0/1).
 */
#ifndef ATO_PLANT_BACKEND_H
#define ATO_PLANT_BACKEND_H

#include <stddef.h>
#include <stdint.h>

#include "ato_backend.h"
#include "ato_math.h"
#include "ato_vars.h"

#define ATO_TICKS_PER_SECOND 1000000000LL

typedef struct { unsigned char* p; size_t n, cap; } ato_buf; /* state being written */
typedef struct { const unsigned char* p; size_t n, at; int ok; } ato_rd; /* being read */

typedef struct ato_inst {
    char* name;
    fmi2CallbackFunctions cb;
    int logging_on;
    char* resources; /* the FMU's resources directory (a path) */
    double* r;       /* value of every variable by value reference (outputs: last computed) */
    char** str;      /* String variables (NULL for the others) */
    int initialized;
    int64_t start_ticks;
    long executions;
    void* core;      /* the model's core; NULL until built from the parameters */
} ato_inst;

typedef struct ato_model {
    const char* identifier;
    const char* guid;
    const char* state_magic; /* first bytes of a serialized state of this model */
    int n_vars;
    const ato_var* vars;
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

void ato_log(ato_inst* m, fmi2Status status, const char* fmt, ...);
#define ATO_ERROR(m, ...) ato_log((m), fmi2Error, __VA_ARGS__)
int64_t ato_to_ticks(double seconds);
double ato_to_seconds(int64_t ticks);
int64_t ato_floordiv(int64_t a, int64_t b);

void ato_put(ato_buf* b, const void* data, size_t n);
void ato_take(ato_rd* r, void* out, size_t n);

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
