/*
 * datadriven.h: the part of the seed-001 data-driven controllers shared by their laws
 * (ffdl_mfac.c, ffdl_ismc.c, ffdl_ismpc.c, emu_gpc.c), the C twin of
 * controllers/datadriven/emu_control.py DataDrivenEmuControl: the inputs' scaling (y_i =
 * c_y v_i, u_i = c_u F_i / m), the input box from the plant's envelope and the comfort limit,
 * the reference y_r(t) and y_r(t+1) at the predicted head position, the holding brake at the
 * final stop, and the outputs.
 *
 * A law's state is one array of doubles (law_state_size = its count times 8) beginning with
 * the drive's DD_DRIVE_STATE values: force[1..n], v_ref, a_ref, speed_error, holding (0/1);
 * each law file documents the rest (the order of the Python core's state_fields).
 */
#ifndef ATO_DATADRIVEN_H
#define ATO_DATADRIVEN_H

#include <stddef.h>

#include "law.h"
#include "profile.h"
#include "ato_model.h"
#include "ato_datadriven_const.h"

#define DD_N ATO_OPTION_units
#define DD_DRIVE_STATE (DD_N + 4)

typedef struct dd_drive {
    double mass, accel_max, hold_accel, stop_speed, output_scale, input_scale, sample_time;
    int next_position; /* reference_at_next_position */
    ato_profile profile;
} dd_drive;

/* one sample's quantities (DataDrivenEmuControl.compute before the law) */
typedef struct dd_sample {
    double v[DD_N], y[DD_N], lo[DD_N], hi[DD_N], hold[DD_N];
    double v_ref, a_ref, y_r, y_r_next, m;
    int holding;
} dd_sample;

/* the drive's parameters and reference profile; 0 after a message in err */
int dd_drive_make(dd_drive* d, const ato_values* p, char* err, size_t n);
void dd_drive_free(dd_drive* d);
/* the inputs of the event at t (s): scaled outputs, input box, references, holding */
void dd_sample_inputs(const dd_drive* d, double t, const double* in, dd_sample* s);
/* the forces m u and the drive's outputs into the drive state st (DD_DRIVE_STATE values) */
void dd_commit(const dd_sample* s, const double* u, double* st);
/* the outputs of the drive state st (the core's outputs()) into out[vr] */
void dd_outputs(const double* st, double* out);
/* sum of x[0..n-1] as numpy's add.reduce for n < 8: ((0.0 + x0) + x1) + ... */
double dd_sum(const double* x, int n);

/* law_state_size, law_get_state and law_set_state of a data-driven law whose whole state is
 * the c->count doubles at c->st (the drive's part first, read by dd_outputs) */
#define DD_LAW_STATE_IMAGE                                                                  \
    size_t law_state_size(const law_core* c) { return c->count * sizeof(double); }         \
    void law_get_state(const law_core* c, void* out) {                                      \
        memcpy(out, c->st, law_state_size(c));                                              \
    }                                                                                       \
    void law_set_state(law_core* c, const void* in) { memcpy(c->st, in, law_state_size(c)); }
/* the same and law_outputs, for a law whose outputs are the drive's */
#define DD_LAW_FLAT_STATE                                                                   \
    DD_LAW_STATE_IMAGE                                                                      \
    void law_outputs(const law_core* c, double* out) { dd_outputs(c->st, out); }

#endif
