/*
 * freight_tracker.h: the base the native freight speed controllers share, the C twin of
 * controllers/common/freight_blending.py (FreightTracker, FreightBlending) and
 * controllers/common/mean_observer.py (MeanSpeedObserver):
 *
 *   v_f = (1 - w) v_head + w v_c    (v_c: the train-mean observer, force balance of the whole
 *                                    train on the design model of eq. 15/18 with a critically
 *                                    damped correction toward the head speed)
 *   a_dem = the law's demand on v_f (resistance included), within the blending's limits
 *   (force_demand, pipe_reduction) = blend(M (1 + gamma) a_dem)   (traction / ED / air brake,
 *                                    the brake-pipe model of the nominal train, holding brake,
 *                                    planned stop application, final approach)
 *
 * The nominal train's data, the routes' additional-resistance knots and the observer's design
 * model come from the generated ato_freight_tracker.h (the Python core's own numbers); the
 * reference profile from resources/references. The core's floating-point operations in its
 * order, except numpy's dot and matrix-vector products (BLAS: another summation order) and
 * numpy's vectorised pow (another rounding than libm's): docs/native_fmus.md.
 */
#ifndef FREIGHT_TRACKER_H
#define FREIGHT_TRACKER_H

#include <stddef.h>

#include "ato_freight_tracker.h"
#include "law.h"
#include "profile.h"

#define FT_MAX_HISTORY 256 /* brake-pipe commands still travelling along the train */

typedef struct {
    /* blending parameters */
    double air_preview_time, ed_share, release_share, min_apply_time, min_release_time,
        reduction_step, overspeed, stop_speed, hold_reduction, final_approach_distance,
        stop_tolerance, stop_ed_share;
    double sample_time, mean_weight, speed_gain, bias_gain;
    ato_profile profile;
    const ft_route* route;
    int n_stops, n_onsets;
    double *stops, *peak_ahead, *onset, *onset_stop;
} ft_const;

typedef struct {
    /* FreightBlending */
    double reduction, pressure_estimate, changed_at, force, approach_stop;
    int holding, final_approach, n_history;
    double pressure[FT_N_VEHICLES];
    double history_t[FT_MAX_HISTORY], history_r[FT_MAX_HISTORY];
    /* FreightTracker */
    double v_ref, a_ref, demand, speed_error, v_feedback;
    int has_locomotive;        /* the law set locomotive_demand (counts the air brake itself) */
    double locomotive_demand;  /* m/s^2, the locomotive's part of the demand */
    /* MeanSpeedObserver */
    int started;
    double z[FT_NZ], bias, u, air, s;
} ft_state;

/* The law's demand (m/s^2) within [lo, hi]; sets st->a_ref (FreightTracker.accel_demand). */
typedef double (*ft_demand)(void* law, ft_state* st, double t, double v, double s,
                            double a_res, double lo, double hi);

/* The shared parameters and data (FreightTracker.__init__); 0 after a message in err. */
int ft_make(ft_const* c, const ato_values* p, char* err, size_t err_size);
void ft_free(ft_const* c);
void ft_reset(ft_state* st);
/* FreightTracker.compute: observer, the law's demand, blending; 0 after a message in err */
int ft_compute(const ft_const* c, ft_state* st, double t, double v, double s, ft_demand law,
               void* law_data, char* err, size_t err_size);
void ft_outputs(const ft_state* st, double* out);
/* a freight law's core: size bytes, zeroed; NULL after "out of memory" in err */
void* ft_new(size_t size, char* err, size_t err_size);
/* the end of a law's law_make: the shared part made (ft_make) and the state st reset; 0 after
 * a message in err, the shared part freed */
int ft_start(ft_const* c, ft_state* st, const ato_values* p, char* err, size_t err_size);

/* The law functions the freight laws have alike, for a core with the shared part in `base`
 * and its state in ST (a struct whose ft_state is ST.base). FT_LAW_PLAIN: law_free and the
 * plain state of a core that holds nothing else on the heap; FT_LAW_COMPUTE: law_outputs and
 * law_compute over the law's demand DEMAND (an ft_demand defined before). */
#define FT_LAW_PLAIN(ST)                                                                        \
    void law_free(law_core* c) {                                                                \
        ft_free(&c->base);                                                                      \
        free(c);                                                                                \
    }                                                                                           \
    ATO_LAW_PLAIN_STATE(ST)
#define FT_LAW_COMPUTE(DEMAND)                                                                  \
    void law_outputs(const law_core* c, double* out) { ft_outputs(&c->st.base, out); }         \
    int law_compute(law_core* c, double t, const ato_values* p, double* out, char* err,        \
                    size_t n) {                                                                 \
        if (!ft_compute(&c->base, &c->st.base, t, p->v[ATO_VR_v], p->v[ATO_VR_s], DEMAND, c,  \
                        err, n))                                                                \
            return 0;                                                                           \
        law_outputs(c, out);                                                                    \
        return 1;                                                                               \
    }
/* ReferenceProfile.accel(s + max(v, 0) t_p) (controllers/pid/freight_pid.py) */
double ft_reference_feedforward(const ft_const* c, double v, double s, double preview_time);

/* FreightBlending's model, for a law that previews it */
int ft_air_applied(const ft_state* st);
void ft_traction_limits(double v, double* trac, double* ed);
double ft_basic_accel(double v);
double ft_additional_accel(const ft_const* c, double s);
double ft_resistance_accel(const ft_const* c, double v, double s);
double ft_friction_at(double v);
void ft_onset_ahead(const ft_const* c, double s, double* onset, double* stop);
double ft_planned_reduction(const ft_const* c, double s, double v, double a_res);
/* FreightBlending.air_force_ahead: the air-brake force (N) at times[j] (>= t) and speeds[j],
 * j < m, with the planned command (planned_t, planned_r) when has_planned */
void ft_air_force_ahead(const ft_state* st, double t, const double* times, const double* speeds,
                        int m, int has_planned, double planned_t, double planned_r,
                        double* out);

static inline double ft_max(double a, double b) { return b > a ? b : a; } /* Python max */
static inline double ft_min(double a, double b) { return b < a ? b : a; } /* Python min */

#endif
