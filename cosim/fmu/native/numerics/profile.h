/*
 * profile.h: a reference profile (plants/route.py ReferenceProfile) read from the FMU's
 * resources/references/<name>.ref, which the build writes from the bundled profiles.
 *
 * kind distance: v^2 linear in position between the points; kind time: v linear in time;
 * outside the points the end speeds hold with zero acceleration. speed() is numpy.interp's
 * arithmetic (slope (f1 - f0) / (x1 - x0) times (x - x0) plus f0; a point's own value at a
 * point); accel() the constant of the segment.
 */
#ifndef ATO_PROFILE_H
#define ATO_PROFILE_H

#include <stddef.h>

typedef struct ato_profile {
    int distance; /* 1: speed against position, 0: against time */
    int n;
    double* x;
    double* v;
    double* f;     /* the interpolated values: v^2 (distance) or v (time) */
    double* accel; /* per segment (n - 1) */
    double* cum;   /* time profiles: integral of v from x[0] to each point (m) */
} ato_profile;

/* Load the bundled profile `name` from `resources`; 0 after a message in err. */
int ato_profile_load(ato_profile* p, const char* resources, const char* name, char* err,
                     size_t err_size);
void ato_profile_free(ato_profile* p);
double ato_profile_speed(const ato_profile* p, double x);
double ato_profile_accel(const ato_profile* p, double x);
/* s_ref(t) = int_0^t v_ref (m) of a time profile (controllers/hybrid/hybrid_mpc.py
 * reference_position: v linear between points, the end speeds outside them) */
double ato_profile_position(const ato_profile* p, double t);
/* numpy.searchsorted(xs, x, side="right") of the increasing xs[0..n-1] */
int ato_bisect_right(const double* xs, int n, double x);
/* numpy.interp(x, xp, fp) for a scalar x */
double ato_interp(double x, const double* xp, const double* fp, int n);

#endif
