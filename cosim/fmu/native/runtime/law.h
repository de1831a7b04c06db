/*
 * law.h: the interface between the sampled-controller backend (controller_backend.c) and the
 * online law of one controller (stop_pid.c, speed_pid.c, explicit_mpc.c), linked statically,
 * one law per FMU.
 *
 * controller_backend.c is the C twin of cosim/fmu/slave.py's SampledControllerSlave: the FMI 2
 * calls, the variables of the generated <id>_decl.h, the timing contract (sample period,
 * next_event_time, events computed on read from the current inputs without committing them,
 * every event inside a long doStep executed with the inputs held at the step's start, the
 * strict_steps refusal), outputs held between events, and the complete FMU state. The law is
 * the core (controllers/...): its parameters, state and compute().
 *
 * Values: every variable's value is a double in v[vr] (Integer and Boolean ones exactly, as
 * 0/1 for a Boolean); String values are in s[vr]. Value references are the ATO_VR_* of the
 * generated header.
 */
#ifndef ATO_LAW_H
#define ATO_LAW_H

#include <stddef.h>

typedef struct law_core law_core; /* defined by the law */

typedef struct ato_values {
    const double* v;        /* by value reference */
    char* const* s;         /* String values by value reference (NULL for other types) */
    const char* resources;  /* the FMU's resources folder (a path) */
} ato_values;

/* The core from the parameter values (the core's from_parameters with its check()); NULL
 * after writing a message that names the parameter into err. */
law_core* law_make(const ato_values* p, double t0, char* err, size_t err_size);
void law_free(law_core* c);

/* Size in bytes of the core's state (plain data), and copies in and out. */
size_t law_state_size(const law_core* c);
void law_get_state(const law_core* c, void* out);
void law_set_state(law_core* c, const void* in);

/* One event at time t (s) from the inputs (and parameters) in p: writes every output of the
 * law into out[vr] and returns the number of samples until the next event (>= 1), or 0 after
 * writing a message into err. */
int law_compute(law_core* c, double t, const ato_values* p, double* out, char* err,
                size_t err_size);

/* x as the shortest decimal that reads back exactly (Python's repr of a float), in buf;
 * returns buf (for messages that name a value as the Python core's do) */
const char* ato_repr(double x, char buf[40]);

/* The outputs shown before the first event (the core's outputs()), into out[vr]. */
void law_outputs(const law_core* c, double* out);

#endif
