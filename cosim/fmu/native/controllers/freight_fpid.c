/*
 * freight_fpid.c: online law of FreightFpid, the C twin of controllers/fuzzy/fuzzy_pid.py
 * (FreightFuzzyPid on the fed-back speed of the shared base, freight_tracker.c): a PI whose
 * gains the Mamdani rule surfaces tune from E = e / e_scale and EC = de/dt / ec_scale,
 *
 *   Kp = max(kp + kp_scale dKp(E, EC), 0),   Ki = max(ki + ki_scale dKi(E, EC), 0)
 *   u  = a_ff + a_res + Kp e + Ki int(e) dt           (conditional integration)
 *
 * the surfaces interpolated bilinearly on the node grid the core tabulates them on (the
 * generated ato_fuzzy_rules.h: the core's tables at the declared fuzzy_nodes). The core's
 * floating-point operations in its order.
 */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "ato_fuzzy_rules.h"
#include "law_common.h"
#include "freight_tracker.h"
#include "ato_model.h"

typedef struct {
    ft_state base;
    double integral, prev_error, kp_now, ki_now;
    int has_prev;
} fpid_state;

struct law_core {
    double sample_time, kp, ki, kp_scale, ki_scale, e_scale, ec_scale, preview_time;
    int reference_feedforward;
    ft_const base;
    fpid_state st;
};

law_core* law_make(const ato_values* p, double t0, char* err, size_t n) {
    (void)t0;
    const double* v = p->v;
    if (v[ATO_VR_fuzzy_nodes] != FZ_NODES) {
        char a[40];
        snprintf(err, n, "fuzzy_nodes = %s: the native FMU carries the rule surfaces on %d "
                 "nodes per axis only (another grid needs the Python FMU)",
                 ato_repr(v[ATO_VR_fuzzy_nodes], a), FZ_NODES);
        return NULL;
    }
    law_core* c = ft_new(sizeof *c, err, n);
    if (!c) return NULL;
    c->sample_time = v[ATO_VR_sample_time];
    c->kp = v[ATO_VR_kp];
    c->ki = v[ATO_VR_ki];
    c->kp_scale = v[ATO_VR_kp_scale];
    c->ki_scale = v[ATO_VR_ki_scale];
    c->e_scale = v[ATO_VR_e_scale];
    c->ec_scale = v[ATO_VR_ec_scale];
    c->preview_time = v[ATO_VR_preview_time];
    c->reference_feedforward = v[ATO_VR_reference_feedforward] != 0.0;
    if (!ft_start(&c->base, &c->st.base, p, err, n)) {
        free(c);
        return NULL;
    }
    c->st.kp_now = c->kp;
    c->st.ki_now = c->ki;
    return c;
}

FT_LAW_PLAIN(st)

/* RuleSurface.__call__ */
static double surface(const double* t, double E, double EC) {
    int n = FZ_NODES - 1;
    double x = (ft_min(ft_max(E, -3.0), 3.0) + 3.0) / FZ_STEP;
    double y = (ft_min(ft_max(EC, -3.0), 3.0) + 3.0) / FZ_STEP;
    int i = (int)x < n - 1 ? (int)x : n - 1;
    int j = (int)y < n - 1 ? (int)y : n - 1;
    double fx = x - i, fy = y - j;
#define T_(a, b) t[(a) * FZ_NODES + (b)]
    return (1 - fx) * ((1 - fy) * T_(i, j) + fy * T_(i, j + 1))
           + fx * ((1 - fy) * T_(i + 1, j) + fy * T_(i + 1, j + 1));
#undef T_
}

static double accel_demand(void* law, ft_state* b, double t, double v, double s, double a_res,
                           double lo, double hi) {
    (void)t;
    law_core* c = law;
    fpid_state* st = &c->st;
    double T = c->sample_time, a_ff;
    if (c->reference_feedforward) {
        b->a_ref = a_ff = ft_reference_feedforward(&c->base, v, s, c->preview_time);
    } else {
        b->a_ref = ato_profile_accel(&c->base.profile, s);
        a_ff = 0.0;
    }
    double e = b->v_ref - b->v_feedback;
    double ec = st->has_prev ? (e - st->prev_error) / T : 0.0;
    st->prev_error = e;
    st->has_prev = 1;
    double E = e / c->e_scale, EC = ec / c->ec_scale;
    st->kp_now = ft_max(c->kp + c->kp_scale * surface(FZ_KP, E, EC), 0.0);
    st->ki_now = ft_max(c->ki + c->ki_scale * surface(FZ_KI, E, EC), 0.0);
    double integral = st->integral + e * T;
    double raw = a_ff + a_res + st->kp_now * e + st->ki_now * integral;
    double u = ft_min(ft_max(raw, lo), hi);
    if (!((raw > hi && e > 0) || (raw < lo && e < 0))) st->integral = integral;
    return u;
}

FT_LAW_COMPUTE(accel_demand)
