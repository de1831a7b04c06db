/*
 * runtime.h: the native runtime, the C twin of cosim/fmu/slave.py's CoreSlave, written
 * once for every native FMU (runtime.c), and the policy a backend puts on top of it.
 *
 * The runtime owns what every native FMU does the same way: instantiation (GUID, resource
 * URI), the variable table of the generated <id>_decl.h (Real / Integer / Boolean / String by
 * value reference), the declared checks on set (type, causality, finite, the parameters'
 * declared ranges), parameters fixed after initialisation, messages logged (errors also with
 * logging off, '%' kept literal), the FMU state as a byte image (magic, values, strings, then
 * the policy's part) with its copies, sizes and serialisation, and the FMI 2-shaped table
 * (ato_backend.h) the fronts call.
 *
 * A backend defines ATO_POLICY: how its core is built and freed, what an output read shows,
 * what a doStep does and the rest of its FMU-state image. controller_backend.c is the sampled
 * controllers' event policy (SampledControllerSlave's timing over one law, law.h);
 * plant_backend.c is the plants' stepping policy (PlantSlave over one model,
 * plant_backend.h).
 *
 * Integer and Boolean variables are kept as doubles in inst->r (exact for int32 and 0/1).
 */
#ifndef ATO_RUNTIME_H
#define ATO_RUNTIME_H

#include <stddef.h>
#include <stdint.h>

#include "ato_backend.h"
#include "vars.h"

typedef struct { unsigned char* p; size_t n, cap; } ato_buf; /* state being written */
typedef struct { const unsigned char* p; size_t n, at; int ok; } ato_rd; /* being read */

typedef struct ato_inst {
    char* name;
    fmi2CallbackFunctions cb;
    int logging_on;
    char* resources; /* the FMU's resources directory (a path) */
    double* r;       /* value of every variable by value reference (a plant's outputs: last
                      * computed; a controller shows its outputs apart) */
    char** str;      /* String variables (NULL for the others) */
    int initialized;
    int64_t start_ticks;
    long executions;
    void* core;      /* the model's core; NULL until built from the parameters */
} ato_inst;

/* which FMU a binary is: its identifier, GUID, state magic and variable table */
typedef struct ato_identity {
    const char* identifier;
    const char* guid;
    const char* state_magic; /* first bytes of a serialized state of this FMU */
    int n_vars;
    const ato_var* vars;
} ato_identity;

typedef struct ato_policy {
    const char* backend_name; /* ato_backend.name */
    long event_time_vr;       /* ato_backend.event_time_vr (-1: no events) */
    const ato_identity* id;
    size_t inst_size;         /* the policy's instance, an ato_inst first */
    size_t message_size;      /* a logged message's longest text + 1 */
    int repr_messages;        /* 1: a value out of its range named as Python's repr names it */
    /* the core from the parameters (1), or 0 after logging why; and its end */
    int (*ensure_core)(ato_inst* m);
    void (*free_core)(ato_inst* m);
    /* the policy's part of the start values and of a start time (both may be NULL) */
    void (*starts)(ato_inst* m);
    void (*setup)(ato_inst* m);
    /* the policy's fields back to their values at instantiation (after the runtime's) */
    void (*reset)(ato_inst* m);
    /* an output's value (made current first), 0 after logging an error */
    int (*get_output)(ato_inst* m, unsigned vr, double* out);
    void (*input_set)(ato_inst* m); /* an input was written (may be NULL) */
    /* a doStep whose size the runtime has checked (the core is built) */
    fmi2Status (*do_step)(ato_inst* m, double t, double h);
    int image_needs_core; /* the image builds the core first (failing if it cannot) */
    /* the policy's part of the FMU state, after the magic, the values and the strings */
    void (*save)(ato_inst* m, ato_buf* b);
    /* the rest of a state read from r: values and strs (malloc'ed, NULL for non-Strings) are
     * the state's, handed over (ato_adopt_values or ato_drop_values) */
    fmi2Status (*load)(ato_inst* m, ato_rd* r, double* values, char** strs);
} ato_policy;

extern const ato_policy ATO_POLICY; /* defined by the backend (controller or plant) */

void ato_log(ato_inst* m, fmi2Status status, const char* fmt, ...);
#define ATO_ERROR(m, ...) ato_log((m), fmi2Error, __VA_ARGS__)
int64_t ato_to_ticks(double seconds);
double ato_to_seconds(int64_t ticks);
int64_t ato_floordiv(int64_t a, int64_t b);

/* x as the shortest decimal that reads back exactly (Python's repr of a float): as a value
 * (ato_fmt(x).s in a message) or in buf */
typedef struct { char s[40]; } ato_num;
ato_num ato_fmt(double x);
const char* ato_repr(double x, char buf[40]);

void ato_put(ato_buf* b, const void* data, size_t n);
void ato_take(ato_rd* r, void* out, size_t n);

/* a state's values and strings made the instance's (the arrays freed), or dropped */
void ato_adopt_values(ato_inst* m, double* values, char** strs);
void ato_drop_values(double* values, char** strs);

#endif
