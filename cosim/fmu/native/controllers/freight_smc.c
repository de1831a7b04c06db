/*
 * freight_smc.c: online law of FreightSmc, the C twin of controllers/smc/sliding_mode.py
 * (FreightSlidingMode on the fed-back speed of the shared base, freight_tracker.c):
 *
 *   e = v_ref - v_f,   sigma = e + lambda I,   I(k+1) = I(k) + T e(k)
 *   u = a_ref + a_res + lambda e + q sigma + eps sw(sigma)
 *
 * sw = sgn, or sat(sigma / phi) with a boundary layer phi > 0; u within the blending's
 * limits. The core's floating-point operations in its order.
 */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "law_common.h"
#include "freight_tracker.h"
#include "ato_model.h"

typedef struct {
    ft_state base;
    double integral, sigma;
} smc_state;

struct law_core {
    double sample_time, lam, q, eps, boundary_layer;
    ft_const base;
    smc_state st;
};

law_core* law_make(const ato_values* p, double t0, char* err, size_t n) {
    (void)t0;
    const double* v = p->v;
    law_core* c = ft_new(sizeof *c, err, n);
    if (!c) return NULL;
    c->sample_time = v[ATO_VR_sample_time];
    c->lam = v[ATO_VR_lambda];
    c->q = v[ATO_VR_q];
    c->eps = v[ATO_VR_eps];
    c->boundary_layer = v[ATO_VR_boundary_layer];
    if (!(c->q * c->sample_time < 1)) { /* SlidingModeParams.check_relations */
        char a[40];
        snprintf(err, n, "q T = %s must be in [0, 1)", ato_repr(c->q * c->sample_time, a));
        free(c);
        return NULL;
    }
    if (!ft_start(&c->base, &c->st.base, p, err, n)) {
        free(c);
        return NULL;
    }
    return c;
}

FT_LAW_PLAIN(st)

static double switching(double sigma, double phi) {
    if (phi > 0) return ft_max(-1.0, ft_min(1.0, sigma / phi));
    return sigma != 0 ? copysign(1.0, sigma) : 0.0;
}

static double accel_demand(void* law, ft_state* b, double t, double v, double s, double a_res,
                           double lo, double hi) {
    (void)t; (void)v;
    law_core* c = law;
    smc_state* st = &c->st;
    b->a_ref = ato_profile_accel(&c->base.profile, s);
    double e = b->v_ref - b->v_feedback;
    st->sigma = e + c->lam * st->integral;
    double u = (b->a_ref + a_res + c->lam * e + c->q * st->sigma
                + c->eps * switching(st->sigma, c->boundary_layer));
    st->integral += c->sample_time * e;
    return ft_min(ft_max(u, lo), hi);
}

FT_LAW_COMPUTE(accel_demand)
