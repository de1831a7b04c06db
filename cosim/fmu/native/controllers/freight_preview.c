/*
 * freight_preview.c: online law of FreightPreview, the C twin of
 * controllers/preview/preview.py (the optimal preview servo, eqs. 33-35, on the fed-back speed
 * of the shared base, freight_tracker.c):
 *
 *   Delta u(k) = F0 x0(k) + sum_j F_R(j) Delta R(k+j) + sum_j F_d(j) Delta d(k+j)
 *   u(k) = u(k-1) + Delta u(k)      within the envelope,   x0 = [e, Delta z]
 *
 * R the reference speeds where the reference is j T after the measured position, d the
 * modelled resistance there and (air_brake_preview) the air-brake deceleration the blending's
 * brake-pipe model predicts, its planned stop application included; u then the locomotive's
 * part. The gains are the Python core's for the declared default design (resources/preview/
 * default.gains, written at build time); other design parameters need the Python FMU.
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
    int started;
    double z[FT_NZ], z_prev[FT_NZ], u_prev, d_prev;
} preview_state;

struct law_core {
    double sample_time;
    int m_r, m_d, horizon, air_brake_preview;
    double F0[1 + FT_NZ];
    double *FR, *Fd;
    double *t_pts, *x_pts; /* the reference's times at its points (finite ones) */
    int n_pts;
    double *R, *d, *air, *times, *sj; /* scratch over the horizon */
    ft_const base;
    preview_state st;
};

/* "key count values..." lines of the gains file; returns the values of key (malloc'ed) */
static double* read_key(const char* path, const char* want, int* count, char* err, size_t n) {
    FILE* f = fopen(path, "r");
    if (!f) {
        snprintf(err, n, "preview gains %s not found", path);
        return NULL;
    }
    char key[64];
    while (fscanf(f, "%63s", key) == 1) {
        if (key[0] == '#') {
            int ch;
            while ((ch = fgetc(f)) != EOF && ch != '\n') {}
            continue;
        }
        int k = 0;
        if (fscanf(f, "%d", &k) != 1 || k < 0) break;
        double* x = malloc((k ? k : 1) * sizeof(double));
        for (int i = 0; i < k; i++)
            if (fscanf(f, "%lf", &x[i]) != 1) {
                free(x);
                fclose(f);
                snprintf(err, n, "preview gains %s: %s has fewer than %d values", path, key, k);
                return NULL;
            }
        if (strcmp(key, want) == 0) {
            fclose(f);
            *count = k;
            return x;
        }
        free(x);
    }
    fclose(f);
    snprintf(err, n, "preview gains %s: no %s", path, want);
    return NULL;
}

void law_free(law_core* c) {
    ft_free(&c->base);
    free(c->FR);
    free(c->Fd);
    free(c->t_pts);
    free(c->x_pts);
    free(c->R);
    free(c->d);
    free(c->air);
    free(c->times);
    free(c->sj);
    free(c);
}

law_core* law_make(const ato_values* p, double t0, char* err, size_t n) {
    (void)t0;
    const double* v = p->v;
    law_core* c = ft_new(sizeof *c, err, n);
    if (!c) return NULL;
    char path[4096], a[40], b[40];
    snprintf(path, sizeof path, "%s/preview/default.gains", p->resources);
    /* the design the gains were computed for (FreightPreview.NATIVE_DESIGN) */
    static const struct { const char* key; int vr; const char* name; } design[] = {
        {"sample_time", ATO_VR_sample_time, "sample_time"}, {"q_e", ATO_VR_q_e, "q_e"},
        {"q_dz", ATO_VR_q_dz, "q_dz"}, {"h", ATO_VR_h, "h"},
        {"preview_steps", ATO_VR_M_R, "M_R"}, {"disturbance_steps", ATO_VR_M_d, "M_d"},
        {"traction_delay", ATO_VR_traction_delay, "traction_delay"},
        {"traction_time_constant", ATO_VR_traction_time_constant, "traction_time_constant"}};
    for (size_t i = 0; i < sizeof design / sizeof design[0]; i++) {
        int k = 0;
        double* x = read_key(path, design[i].key, &k, err, n);
        if (!x) goto fail;
        double want = x[0];
        free(x);
        if (v[design[i].vr] != want) {
            snprintf(err, n, "%s = %s: the native FMU carries the preview gains of the default "
                     "design (%s = %s) only (another design needs the Python FMU)",
                     design[i].name, ato_repr(v[design[i].vr], a), design[i].name,
                     ato_repr(want, b));
            goto fail;
        }
    }
    if (v[ATO_VR_traction_delay] != FT_TRACTION_DELAY
        || v[ATO_VR_traction_time_constant] != FT_TRACTION_TIME_CONSTANT) {
        snprintf(err, n, "traction_delay, traction_time_constant = %s, %s: the native FMU's "
                 "observer model is the nominal train's", ato_repr(v[ATO_VR_traction_delay], a),
                 ato_repr(v[ATO_VR_traction_time_constant], b));
        goto fail;
    }
    c->sample_time = v[ATO_VR_sample_time];
    c->m_r = (int)v[ATO_VR_M_R];
    c->m_d = (int)v[ATO_VR_M_d];
    c->horizon = (c->m_r > c->m_d ? c->m_r : c->m_d) + 1;
    c->air_brake_preview = v[ATO_VR_air_brake_preview] != 0.0;
    int k = 0;
    double* f0 = read_key(path, "F0", &k, err, n);
    if (!f0) goto fail;
    if (k != 1 + FT_NZ) {
        free(f0);
        snprintf(err, n, "preview gains %s: F0 has %d values, the design model %d", path, k,
                 1 + FT_NZ);
        goto fail;
    }
    memcpy(c->F0, f0, sizeof c->F0);
    free(f0);
    if (!(c->FR = read_key(path, "FR", &k, err, n))) goto fail;
    if (k != c->m_r) {
        snprintf(err, n, "preview gains %s: FR has %d values, M_R = %d", path, k, c->m_r);
        goto fail;
    }
    if (!(c->Fd = read_key(path, "Fd", &k, err, n))) goto fail;
    if (k != c->m_d + 1) {
        snprintf(err, n, "preview gains %s: Fd has %d values, M_d + 1 = %d", path, k,
                 c->m_d + 1);
        goto fail;
    }
    if (!ft_make(&c->base, p, err, n)) goto fail;
    /* ReferenceProfile.times(): the finite ones */
    const ato_profile* pr = &c->base.profile;
    c->t_pts = malloc(pr->n * sizeof(double));
    c->x_pts = malloc(pr->n * sizeof(double));
    int H = c->horizon;
    c->R = malloc(H * sizeof(double));
    c->d = malloc(H * sizeof(double));
    c->air = malloc(H * sizeof(double));
    c->times = malloc(H * sizeof(double));
    c->sj = malloc(H * sizeof(double));
    if (!c->t_pts || !c->x_pts || !c->R || !c->d || !c->air || !c->times || !c->sj) {
        snprintf(err, n, "out of memory");
        goto fail;
    }
    double time = 0.0;
    for (int i = 0; i < pr->n; i++) {
        if (i > 0) {
            double dx = pr->x[i] - pr->x[i - 1], vsum = pr->v[i - 1] + pr->v[i];
            time += vsum > 0 ? 2.0 * dx / vsum : INFINITY;
        }
        if (isfinite(time)) {
            c->t_pts[c->n_pts] = time;
            c->x_pts[c->n_pts] = pr->x[i];
            c->n_pts++;
        }
    }
    ft_reset(&c->st.base);
    return c;
fail:
    law_free(c);
    return NULL;
}

ATO_LAW_PLAIN_STATE(st)

static double dot(const double* a, const double* b, int n) { /* index order */
    double s = 0.0;
    for (int i = 0; i < n; i++) s += a[i] * b[i];
    return s;
}

/* FreightPreview.ahead: R(k+j), d(k+j) */
static void ahead(law_core* c, double s) {
    const ft_const* b = &c->base;
    double t0 = ato_interp(s, c->x_pts, c->t_pts, c->n_pts);
    for (int j = 0; j < c->horizon; j++) {
        c->sj[j] = j == 0 ? s
                          : ato_interp(t0 + (double)j * c->sample_time, c->t_pts, c->x_pts,
                                       c->n_pts);
        c->R[j] = ato_profile_speed(&b->profile, c->sj[j]);
        c->d[j] = -ft_basic_accel(c->R[j]) - ft_additional_accel(b, c->sj[j]);
    }
}

/* FreightPreview.air_ahead into c->air; returns its length (0: none acts or is planned) */
static int air_ahead(law_core* c, double t, double s) {
    const ft_const* b = &c->base;
    ft_state* st = &c->st.base;
    double T = c->sample_time, planned_t = 0.0, planned_r = 0.0;
    int has_planned = 0;
    if (!ft_air_applied(st)) {
        double onset, stop;
        ft_onset_ahead(b, s, &onset, &stop);
        if (!isfinite(onset)) return 0;
        double t_s = ato_interp(s, c->x_pts, c->t_pts, c->n_pts);
        double t_on = ato_interp(onset, c->x_pts, c->t_pts, c->n_pts);
        double lead = T * nearbyint((t_on - t_s) / T); /* Python round: half to even */
        if (lead > (double)(c->horizon - 1) * T || onset < s) return 0;
        double v_on = ato_profile_speed(&b->profile, onset);
        double a_res = ft_resistance_accel(b, v_on, onset);
        planned_t = t + lead;
        planned_r = ft_planned_reduction(b, onset, v_on, a_res);
        has_planned = 1;
    }
    for (int j = 0; j < c->horizon; j++)
        c->times[j] = t + (double)j * T + 0.5 * T;
    ft_air_force_ahead(st, t, c->times, c->R, c->horizon, has_planned, planned_t, planned_r,
                       c->air);
    for (int j = 0; j < c->horizon; j++) c->air[j] /= FT_M_EFF;
    return c->horizon;
}

static double accel_demand(void* law, ft_state* b, double t, double v, double s, double a_res,
                           double lo, double hi) {
    law_core* c = law;
    preview_state* st = &c->st;
    b->a_ref = ato_profile_accel(&c->base.profile, s);
    ahead(c, s);
    c->R[0] = b->v_ref;
    c->d[0] = -a_res;
    int n_air = 0;
    if (c->air_brake_preview) {
        n_air = air_ahead(c, t, s);
        for (int j = 0; j < n_air; j++) c->d[j] -= c->air[j];
        double trac, ed;
        ft_traction_limits(ft_max(v, 0.0), &trac, &ed);
        lo = -ed / FT_M_EFF;
        hi = ft_air_applied(b) ? 0.0 : trac / FT_M_EFF;
    }
    double vf = b->v_feedback;
    if (!st->started) {
        for (int i = 0; i < FT_NZ; i++) st->z[i] = st->z_prev[i] = 0.0;
        st->z[0] = st->z_prev[0] = vf;
        st->d_prev = c->d[0];
        st->started = 1;
    } else {
        double z[FT_NZ];
        for (int i = 0; i < FT_NZ; i++) {
            double az = 0.0;
            for (int j = 0; j < FT_NZ; j++) az += FT_A[i * FT_NZ + j] * st->z[j];
            z[i] = az + FT_B[i] * st->u_prev + FT_E[i] * st->d_prev;
        }
        memcpy(st->z, z, sizeof z);
        st->z[0] = vf;
    }
    double x0[1 + FT_NZ];
    x0[0] = b->v_ref - vf;
    for (int i = 0; i < FT_NZ; i++) x0[1 + i] = st->z[i] - st->z_prev[i];
    double sr = 0.0, sd = 0.0;
    for (int j = 0; j < c->m_r; j++) sr += c->FR[j] * (c->R[j + 1] - c->R[j]);
    for (int j = 0; j <= c->m_d; j++)
        sd += c->Fd[j] * (c->d[j] - (j == 0 ? st->d_prev : c->d[j - 1]));
    double du = dot(c->F0, x0, 1 + FT_NZ) + sr + sd;
    double u = ft_min(ft_max(st->u_prev + du, lo), hi);
    memcpy(st->z_prev, st->z, sizeof st->z);
    st->u_prev = u;
    st->d_prev = c->d[0];
    if (!c->air_brake_preview) return u;
    b->has_locomotive = 1;
    b->locomotive_demand = u;
    return u - (n_air ? c->air[0] : 0.0);
}

FT_LAW_COMPUTE(accel_demand)
