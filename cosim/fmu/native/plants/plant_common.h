/*
 * plant_common.h: what the native plant models share, each law written once.
 *
 *  - route step profiles (plants.route.StepProfile): read from the FMU's
 *    resources/routes/<route>.profiles (written by cosim/build/native.py from the bundled
 *    routes, IEEE bits in hex), their point value (`at`), pointwise sums (StepProfile.sum),
 *    the cumulative integral and the interpolation the length means use
 *    (StepProfile._cumulative, plants.route._interp_scalar and plants.kernels._interp: the same
 *    operations, slope (x - x_j) + y_j);
 *  - the envelope of a force limit with a power limit, min(F, P / max(|v|, 1e-9));
 *  - the Davis resistance a + (b + c v) v.
 */
#ifndef ATO_PLANT_COMMON_H
#define ATO_PLANT_COMMON_H

#include "plant_backend.h"

#define ATO_GRAVITY 9.81 /* m/s^2, plants.route.GRAVITY */

typedef struct { int n; double* starts; double* values; } ato_profile; /* starts[0] = -inf */
typedef struct { int n; double* xs; double* cum; } ato_cumulative;

typedef struct {
    ato_profile grade, curve_resistance, tunnel_resistance, speed_limit, neutral;
} ato_route;

/* the route named `route` (a bundled name: no path) from m's resources; 0 after logging */
int ato_route_load(ato_inst* m, const char* route, ato_route* out);
void ato_route_free(ato_route* r);
void ato_profile_free(ato_profile* p);

/* index j of the segment holding s: starts[j] <= s < starts[j + 1] (bisect_right - 1) */
int ato_profile_index(const ato_profile* p, double s);
double ato_profile_at(const ato_profile* p, double s);
/* StepProfile.sum(ps[0], ..., ps[k - 1]) into out */
void ato_profile_sum(const ato_profile* const* ps, int k, ato_profile* out);
/* StepProfile._cumulative of p into out */
void ato_cumulative_of(const ato_profile* p, ato_cumulative* out);
void ato_cumulative_free(ato_cumulative* c);
/* np.interp(x, xs, cum) as plants.route._interp_scalar computes it */
double ato_interp(const ato_cumulative* c, double x);
/* StepProfile.mean_over_scalar(front, length), length > 0 */
double ato_mean_over(const ato_cumulative* c, double front, double length);

/* largest force (N) of a force limit f_max (N) and a power limit p_max (W) at speed v (m/s):
 * min(F, P / max(|v|, 1e-9)) */
static inline double ato_envelope(double f_max, double p_max, double v) {
    return ato_min(f_max, p_max / ato_max(fabs(v), 1e-9));
}

/* Davis resistance a + (b + c v) v (plants.resistance.Davis.force) */
static inline double ato_davis(double a, double b, double c, double v) {
    return a + (b + c * v) * v;
}

#endif
