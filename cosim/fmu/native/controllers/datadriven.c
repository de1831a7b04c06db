/* datadriven.c: see datadriven.h (controllers/datadriven/emu_control.py). */
#include <math.h>
#include <string.h>

#include "datadriven.h"

static double pymax(double a, double b) { return b > a ? b : a; }
/* numpy.minimum / numpy.maximum: NaN propagates */
static double npmin(double a, double b) { return isnan(a) || isnan(b) ? a + b : (b < a ? b : a); }
static double npmax(double a, double b) { return isnan(a) || isnan(b) ? a + b : (b > a ? b : a); }

double dd_sum(const double* x, int n) {
    double s = 0.0;
    for (int i = 0; i < n; i++) s += x[i];
    return s;
}

int dd_drive_make(dd_drive* d, const ato_values* p, char* err, size_t n) {
    const double* v = p->v;
    memset(d, 0, sizeof *d);
    d->mass = v[ATO_VR_mass];
    d->accel_max = v[ATO_VR_accel_max];
    d->hold_accel = v[ATO_VR_hold_accel];
    d->stop_speed = v[ATO_VR_stop_speed];
    d->output_scale = v[ATO_VR_output_scale];
    d->input_scale = v[ATO_VR_input_scale];
    d->sample_time = v[ATO_VR_sample_time];
    d->next_position = v[ATO_VR_reference_at_next_position] != 0.0;
    return ato_profile_load(&d->profile, p->resources, p->s[ATO_VR_reference], err, n);
}

void dd_drive_free(dd_drive* d) { ato_profile_free(&d->profile); }

/* DataDrivenEmuControl.next_reference (m/s) */
static double next_reference(const dd_drive* d, double x, const double* v, double v_ref,
                             double a_ref) {
    double T = d->sample_time;
    if (!d->next_position) return pymax(v_ref + a_ref * T, 0.0);
    if (!d->profile.distance) return ato_profile_speed(&d->profile, x + T);
    return ato_profile_speed(&d->profile, x + pymax(v[0] * T + 0.5 * a_ref * T * T, 0.0));
}

void dd_sample_inputs(const dd_drive* d, double t, const double* in, dd_sample* s) {
    for (int i = 0; i < DD_N; i++) s->v[i] = in[ATO_VRS_v[i]];
    double x = d->profile.distance ? in[ATO_VR_s] : t;
    double v_ref = s->v_ref = ato_profile_speed(&d->profile, x);
    double a_ref = s->a_ref = ato_profile_accel(&d->profile, x);
    double m = s->m = d->mass / DD_N / d->input_scale; /* unit_mass / input_scale */
    double a_max = d->accel_max * d->input_scale;
    for (int i = 0; i < DD_N; i++) {
        double trac = pymax(in[ATO_VRS_traction_limit[i]], 0.0);
        double brake = pymax(in[ATO_VRS_brake_limit[i]], 0.0);
        s->hi[i] = npmin(a_max, trac / m);
        s->lo[i] = npmin(npmax(-a_max, -brake / m), s->hi[i]);
    }
    double c = d->output_scale;
    for (int i = 0; i < DD_N; i++) s->y[i] = c * s->v[i];
    s->holding = v_ref <= 0.0 && a_ref <= 0.0 && dd_sum(s->v, DD_N) < d->stop_speed * DD_N;
    for (int i = 0; i < DD_N; i++) /* np.clip(full(n, hold_accel c_u), lo, hi) */
        s->hold[i] = npmin(npmax(d->hold_accel * d->input_scale, s->lo[i]), s->hi[i]);
    s->y_r = c * v_ref;
    s->y_r_next = s->holding ? 0.0 : c * next_reference(d, x, s->v, v_ref, a_ref);
}

void dd_commit(const dd_sample* s, const double* u, double* st) {
    for (int i = 0; i < DD_N; i++) st[i] = s->m * u[i];
    st[DD_N] = s->v_ref;
    st[DD_N + 1] = s->a_ref;
    st[DD_N + 2] = dd_sum(s->v, DD_N) / DD_N - s->v_ref;
    st[DD_N + 3] = s->holding;
}

void dd_outputs(const double* st, double* out) {
    for (int i = 0; i < DD_N; i++) out[ATO_VRS_force[i]] = st[i];
    out[ATO_VR_force_demand] = dd_sum(st, DD_N); /* Python's sum(): 0 + f1 + f2 + ... */
    out[ATO_VR_v_ref] = st[DD_N];
    out[ATO_VR_a_ref] = st[DD_N + 1];
    out[ATO_VR_speed_error] = st[DD_N + 2];
}
