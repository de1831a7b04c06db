/*
 * freight_tracker.c: the freight controllers' shared base (freight_tracker.h), the C twin of
 * FreightTracker, FreightBlending and MeanSpeedObserver (controllers/common/).
 */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "freight_tracker.h"
#include "ato_model.h" /* generated: the FMU's value references */

/* -- the nominal train (plants/freight.py FreightTrain on BlendingParams.train) ---------- */

static double friction_at(double v) { /* friction_coefficient_at: plants.kernels.shoe_friction */
    double kmh = fabs(v) / FT_KMH;
    return 0.322 * (kmh + 150.0) / (2.0 * kmh + 150.0);
}

static void traction_limits(double v, double* trac, double* ed) {
    double speed = fabs(v);
    *trac = speed > 0 ? ft_min(FT_MAX_TRACTION_FORCE, FT_MAX_TRACTION_POWER / speed)
                      : FT_MAX_TRACTION_FORCE;
    double e = speed > 0 ? ft_min(FT_MAX_ED_FORCE, FT_MAX_ED_POWER / speed) : FT_MAX_ED_FORCE;
    if (FT_ED_FADE_SPEED > 0 && speed < FT_ED_FADE_SPEED) e *= speed / FT_ED_FADE_SPEED;
    *ed = e;
}

static double target_pressure(double r) {
    double level = FT_MAX_CYLINDER_PRESSURE * ft_min(r / FT_FULL_SERVICE_REDUCTION, 1.0);
    return r >= ft_max(FT_MIN_REDUCTION, 1e-9) ? level : 0.0;
}

static double xpow(double x, double e) { return e == 1.0 ? x : pow(x, e); } /* numpy: x**1 = x */

/* FreightTrain.evolve_pressure of one cylinder (only the branch numpy.where keeps is
 * computed: the same value) */
static double evolve(double pres, double target, double dt) {
    double pmax = FT_MAX_CYLINDER_PRESSURE;
    if (pres < target) {
        double frac = ft_min(pres / pmax, 1.0);
        double t_up = FT_FILL_TIME * xpow(frac, 1.0 / FT_FILL_EXPONENT);
        double up = pmax * xpow(ft_min((t_up + dt) / FT_FILL_TIME, 1.0), FT_FILL_EXPONENT);
        return ft_min(up, target);
    }
    if (pres > target) {
        double frac = ft_min(pres / pmax, 1.0);
        double t_down = FT_RELEASE_TIME * xpow(1.0 - frac, 1.0 / FT_RELEASE_EXPONENT);
        double down = pmax * (1.0 - xpow(ft_min((t_down + dt) / FT_RELEASE_TIME, 1.0),
                                         FT_RELEASE_EXPONENT));
        return ft_max(down, target);
    }
    return pres;
}

/* numpy's pairwise sum of n <= 128 doubles (8 accumulators, then the rest in order) */
static double pairwise_sum(const double* a, int n) {
    double res = 0.0;
    if (n < 8) {
        for (int i = 0; i < n; i++) res += a[i];
        return res;
    }
    double r[8];
    int i;
    for (i = 0; i < 8; i++) r[i] = a[i];
    for (i = 8; i < n - (n % 8); i += 8)
        for (int j = 0; j < 8; j++) r[j] += a[i + j];
    res = ((r[0] + r[1]) + (r[2] + r[3])) + ((r[4] + r[5]) + (r[6] + r[7]));
    for (; i < n; i++) res += a[i];
    return res;
}

static double dot(const double* a, const double* b, int n) { /* index order */
    double s = 0.0;
    for (int i = 0; i < n; i++) s += a[i] * b[i];
    return s;
}

/* -- FreightBlending's model ------------------------------------------------------------- */

static double basic_accel(double v) { return (FT_RES_A + (FT_RES_B + FT_RES_C * v) * v) / FT_M_EFF; }

static double additional_accel(const ft_const* c, double s) {
    return ato_interp(s, c->route->knots, c->route->values, c->route->n);
}

static double resistance_accel(const ft_const* c, double v, double s) {
    return basic_accel(v) + additional_accel(c, s);
}

static double air_force(double pressure, double v) {
    return FT_BRAKE_SCALE_SUM * pressure * friction_at(v);
}

static int air_applied(const ft_state* st) {
    if (st->reduction > 0.0) return 1;
    double m = st->pressure[0];
    for (int i = 1; i < FT_N_VEHICLES; i++) m = ft_max(m, st->pressure[i]);
    return m > FT_RELEASED_PA;
}

static void accel_limits(const ft_state* st, double v, double* lo, double* hi) {
    double speed = ft_max(v, 0.0), trac, ed;
    traction_limits(speed, &trac, &ed);
    double full_air = air_force(FT_MAX_CYLINDER_PRESSURE, speed);
    double h = air_applied(st) ? -air_force(st->pressure_estimate, speed) : trac;
    *lo = -(ed + full_air) / FT_M_EFF;
    *hi = h / FT_M_EFF;
}

static double reduction_for(const ft_const* c, double force, double v) {
    double per_pa = air_force(1.0, v);
    double need = force / per_pa / FT_MAX_CYLINDER_PRESSURE * FT_FULL_SERVICE_REDUCTION;
    double step = c->reduction_step;
    return ft_min(ft_max(ceil(need / step) * step, FT_MIN_REDUCTION), FT_FULL_SERVICE_REDUCTION);
}

static double peak_ahead(const ft_const* c, double s) {
    const ato_profile* p = &c->profile;
    int j = 0;
    while (j < p->n && p->x[j] <= s) j++; /* bisect_right */
    return j < p->n ? c->peak_ahead[j] : 0.0;
}

static double next_stop(const ft_const* c, double s) {
    for (int i = 0; i < c->n_stops; i++)
        if (c->stops[i] >= s - 1e-6) return c->stops[i];
    return INFINITY;
}

static void onset_ahead(const ft_const* c, double s, double* onset, double* stop) {
    for (int i = 0; i < c->n_onsets; i++)
        if (s < c->onset_stop[i]) {
            *onset = c->onset[i];
            *stop = c->onset_stop[i];
            return;
        }
    *onset = *stop = INFINITY;
}

static double planned_reduction(const ft_const* c, double s, double v, double a_res) {
    double ahead = ato_profile_accel(&c->profile, s + v * c->air_preview_time);
    double extra = -FT_M_EFF * (ft_min(ahead, ato_profile_accel(&c->profile, s)) + a_res);
    double trac, ed;
    traction_limits(v, &trac, &ed);
    return reduction_for(c, extra - c->stop_ed_share * ed, v);
}

/* FreightTrain._brake_step over [t0, t1] after step_brakes' command at t0 */
static int step_brakes(ft_state* st, double t0, double t1, double reduction, char* err,
                       size_t n) {
    if (reduction != st->history_r[st->n_history - 1]) {
        if (st->n_history == FT_MAX_HISTORY) {
            snprintf(err, n, "more than %d brake-pipe commands travelling", FT_MAX_HISTORY);
            return 0;
        }
        st->history_t[st->n_history] = t0;
        st->history_r[st->n_history] = reduction;
        st->n_history++;
    }
    double* pres = st->pressure;
    if (st->n_history == 1) {
        double target = target_pressure(st->history_r[0]);
        for (int i = 0; i < FT_N_VEHICLES; i++) pres[i] = evolve(pres[i], target, t1 - t0);
        return 1; /* all equal to the target: evolve returns them unchanged */
    }
    int newest_everywhere = st->n_history;
    for (int i = 0; i < FT_N_VEHICLES; i++) {
        int idx0 = 0, idx1 = 0;
        double arr1 = 0.0;
        for (int k = 0; k < st->n_history; k++) {
            int rising = k == 0 || st->history_r[k] >= st->history_r[k - 1];
            double arrival = st->history_t[k] + (rising ? FT_APPLY_DELAY[i] : FT_RELEASE_DELAY[i]);
            if (arrival <= t0) idx0 = k;
            if (arrival <= t1) idx1 = k;
            if (k == idx1) arr1 = arrival;
        }
        double switch_t = ft_min(ft_max(arr1, t0), t1); /* np.clip */
        double mid = evolve(pres[i], target_pressure(st->history_r[idx0]), switch_t - t0);
        pres[i] = evolve(mid, target_pressure(st->history_r[idx1]), t1 - switch_t);
        if (idx1 < newest_everywhere) newest_everywhere = idx1;
    }
    if (newest_everywhere > 0) {
        int keep = st->n_history - newest_everywhere;
        memmove(st->history_t, st->history_t + newest_everywhere, keep * sizeof(double));
        memmove(st->history_r, st->history_r + newest_everywhere, keep * sizeof(double));
        st->n_history = keep;
    }
    return 1;
}

/* -- predicted stop (FreightBlending.predicted_stop, _integrate_stop) --------------------- */

#define STOP_H 0.25
#define STOP_N 721 /* int(180 / 0.25) + 1 */

static void air_scale_schedule(const ft_state* st, int release, double released_for,
                               double* air_scale) {
    const double* pres = st->pressure;
    if (!release) {
        double a = dot(pres, FT_BRAKE_SCALE, FT_N_VEHICLES);
        for (int k = 0; k < STOP_N; k++) air_scale[k] = a;
        return;
    }
    double wait[FT_N_VEHICLES], empty = -INFINITY;
    for (int i = 0; i < FT_N_VEHICLES; i++) {
        wait[i] = ft_max(FT_RELEASE_DELAY[i] - released_for, 0.0);
        double e = wait[i] + FT_RELEASE_TIME * ft_min(pres[i] / FT_MAX_CYLINDER_PRESSURE, 1.0);
        empty = i == 0 ? e : ft_max(empty, e);
    }
    int n_air = (int)(empty / STOP_H) + 2;
    if (n_air > STOP_N) n_air = STOP_N;
    for (int k = 0; k < STOP_N; k++) {
        if (k >= n_air) {
            air_scale[k] = 0.0;
            continue;
        }
        double sum = 0.0;
        for (int i = 0; i < FT_N_VEHICLES; i++) {
            double dt = ft_max((double)k * STOP_H - wait[i], 0.0);
            sum += evolve(pres[i], 0.0, dt) * FT_BRAKE_SCALE[i];
        }
        air_scale[k] = sum;
    }
}

static double predicted_stop(const ft_const* c, const ft_state* st, double v, double s,
                             int release, double share, double released_for) {
    double air_scale[STOP_N];
    air_scale_schedule(st, release, released_for, air_scale);
    double h = STOP_H;
    double decay = exp(-h / FT_TRACTION_TIME_CONSTANT);
    double force = ft_min(st->force, 0.0);
    int lag_steps = (int)nearbyint(FT_TRACTION_DELAY / h); /* Python round: half to even */
    const double* knots = c->route->knots;
    const double* values = c->route->values;
    int nk = c->route->n;
    double vk = ft_max(v, 0.0), sk = s;
    for (int k = 0; k < STOP_N - 1; k++) {
        if (release && k >= lag_steps) {
            double speed = fabs(vk);
            double ed = speed > 0 ? ft_min(FT_MAX_ED_FORCE, FT_MAX_ED_POWER / speed)
                                  : FT_MAX_ED_FORCE;
            if (FT_ED_FADE_SPEED > 0 && speed < FT_ED_FADE_SPEED) ed *= speed / FT_ED_FADE_SPEED;
            double target = -share * ed;
            force = target + (force - target) * decay;
        }
        double air = air_scale[k];
        double mu = friction_at(vk);
        double a0 = ((air * mu - force) / FT_M_EFF
                     + ((FT_RES_A + (FT_RES_B + FT_RES_C * vk) * vk) / FT_M_EFF
                        + ato_interp(sk, knots, values, nk)));
        if (a0 <= 0.0 && vk <= 0.0) return sk;
        double vm = vk - 0.5 * h * a0;
        if (vm <= 0.0) return sk + vk * vk / (2.0 * a0);
        mu = friction_at(vm);
        double am = ((air * mu - force) / FT_M_EFF
                     + ((FT_RES_A + (FT_RES_B + FT_RES_C * vm) * vm) / FT_M_EFF
                        + ato_interp(sk + 0.5 * h * vk, knots, values, nk)));
        double v1 = vk - h * am;
        if (v1 <= 0.0) return sk + vk * vk / (2.0 * am);
        sk += 0.5 * h * (vk + v1);
        vk = v1;
    }
    return INFINITY;
}

/* stop point of a final approach to release the air brake for, or NaN (none) */
static double final_approach(const ft_const* c, const ft_state* st, double v, double s) {
    double stop = next_stop(c, s);
    if (!(st->reduction > 0.0 && 0.0 < stop - s && stop - s <= c->final_approach_distance))
        return NAN;
    if (predicted_stop(c, st, v, s, 0, 1.0, 0.0) >= stop - c->stop_tolerance) return NAN;
    return predicted_stop(c, st, v, s, 1, 1.0, 0.0) <= stop - c->stop_tolerance ? stop : NAN;
}

static double approach_force(const ft_const* c, const ft_state* st, double t, double v,
                             double s) {
    double released_for = t - st->changed_at;
    double gap = st->approach_stop - s;
    double coast = predicted_stop(c, st, v, s, 1, 0.0, released_for);
    if (coast <= st->approach_stop) return 0.0;
    double full = predicted_stop(c, st, v, s, 1, 1.0, released_for);
    double share;
    if (full >= st->approach_stop || !isfinite(coast) || coast - full <= 1e-9 || gap <= 0.0)
        share = 1.0;
    else
        share = (coast - st->approach_stop) / (coast - full);
    double trac, ed;
    traction_limits(ft_max(v, 0.0), &trac, &ed);
    return -share * ed;
}

/* FreightBlending.blend (locomotive = False) */
static int blend(const ft_const* c, ft_state* st, double t, double T, double v, double s,
                 double force, double v_ref, double a_ref, double a_res, int locomotive,
                 char* err, size_t n) {
    const ato_profile* prof = &c->profile;
    double speed = ft_max(v, 0.0), trac, ed, onset, onset_stop, planned;
    traction_limits(speed, &trac, &ed);
    onset_ahead(c, s, &onset, &onset_stop);
    if (s + 0.5 * speed * T < onset) {
        double ahead = ft_min(s + speed * c->air_preview_time, onset - 1e-6);
        planned = FT_M_EFF * (ft_min(ato_profile_accel(prof, s), ato_profile_accel(prof, ahead))
                              + a_res);
        if (!isfinite(onset)) planned = ft_min(planned, FT_M_EFF * (a_ref + a_res));
    } else {
        planned = FT_M_EFF * (ft_min(ft_min(a_ref, ato_profile_accel(prof, s)),
                                     ato_profile_accel(prof, s + speed * c->air_preview_time))
                              + a_res);
    }
    int over = v - v_ref > c->overspeed;
    double need = ft_max(-planned, over ? -force : 0.0);
    int applied = st->reduction > 0.0;
    double since = t - st->changed_at;
    st->holding = (v < c->stop_speed && ato_profile_accel(prof, s) <= 0.0
                   && ((v_ref < c->stop_speed && peak_ahead(c, s) < c->stop_speed)
                       || st->reduction > 0.0
                       || (st->final_approach
                           && (v <= 0.0 || st->approach_stop - s <= c->stop_tolerance))));
    double stop;
    if (st->holding) {
        if (st->reduction < c->hold_reduction) {
            st->reduction = c->hold_reduction;
            st->changed_at = t;
        }
        st->final_approach = 0;
        force = 0.0;
    } else if (st->final_approach) {
        /* released for the final approach: no new application before the stop */
    } else if (applied && !isnan(stop = final_approach(c, st, v, s))) {
        st->reduction = 0.0;
        st->changed_at = t;
        st->final_approach = 1;
        st->approach_stop = stop;
    } else if (applied) {
        double extra = -planned - c->ed_share * ed;
        if (extra > air_force(st->pressure_estimate, speed) && extra > 0)
            st->reduction = ft_max(st->reduction, reduction_for(c, extra, speed));
        else if (since >= c->min_apply_time && need < c->release_share * ed) {
            st->reduction = 0.0;
            st->changed_at = t;
        }
    } else if (since >= c->min_release_time && onset <= s + 0.5 * speed * T
               && s + 0.5 * speed * T < ft_min(onset + speed * T, onset_stop)) {
        st->reduction = planned_reduction(c, s, speed, a_res);
        st->changed_at = t;
    } else if (since >= c->min_release_time && need > c->ed_share * ed) {
        st->reduction = -planned > c->ed_share * ed
                            ? reduction_for(c, -planned - c->ed_share * ed, speed)
                            : FT_MIN_REDUCTION;
        st->changed_at = t;
    }
    if (!step_brakes(st, t, t + T, st->reduction, err, n)) return 0;
    st->pressure_estimate = pairwise_sum(st->pressure, FT_N_VEHICLES) / FT_N_VEHICLES;
    if (st->final_approach) {
        force = approach_force(c, st, t, v, s);
    } else if (!st->holding && air_applied(st)) {
        double air = locomotive ? 0.0
                                : dot(FT_BRAKE_SCALE, st->pressure, FT_N_VEHICLES)
                                      * friction_at(speed);
        force = ft_min(force + air, 0.0);
    }
    st->force = ft_min(ft_max(force, -ed), trac);
    return 1;
}

/* -- MeanSpeedObserver ---------------------------------------------------------------------- */

static double observer_update(const ft_const* c, ft_state* st, double v_head) {
    if (!st->started) {
        for (int i = 0; i < FT_NZ; i++) st->z[i] = 0.0;
        st->z[0] = v_head;
        st->started = 1;
        return v_head;
    }
    double T = c->sample_time, vc = st->z[0];
    double scale = ft_max(ft_min(vc / FT_STICTION_SPEED, 1.0), -1.0);
    double s_mid = st->s + 0.5 * T * vc;
    double d = st->bias - (scale * (basic_accel(fabs(vc)) + st->air * friction_at(vc) / FT_M_EFF)
                           + additional_accel(c, s_mid));
    double z[FT_NZ];
    for (int i = 0; i < FT_NZ; i++) {
        double az = 0.0;
        for (int j = 0; j < FT_NZ; j++) az += FT_A[i * FT_NZ + j] * st->z[j];
        z[i] = az + FT_B[i] * st->u + FT_E[i] * d;
    }
    memcpy(st->z, z, sizeof z);
    double r = v_head - st->z[0];
    st->z[0] += c->speed_gain * r;
    st->bias += c->bias_gain * r;
    return st->z[0];
}

/* -- the model for the laws that preview it ---------------------------------------------- */

int ft_air_applied(const ft_state* st) { return air_applied(st); }
void ft_traction_limits(double v, double* trac, double* ed) { traction_limits(v, trac, ed); }
double ft_basic_accel(double v) { return basic_accel(v); }
double ft_additional_accel(const ft_const* c, double s) { return additional_accel(c, s); }
double ft_resistance_accel(const ft_const* c, double v, double s) {
    return resistance_accel(c, v, s);
}
double ft_friction_at(double v) { return friction_at(v); }
void ft_onset_ahead(const ft_const* c, double s, double* onset, double* stop) {
    onset_ahead(c, s, onset, stop);
}
double ft_planned_reduction(const ft_const* c, double s, double v, double a_res) {
    return planned_reduction(c, s, v, a_res);
}

void ft_air_force_ahead(const ft_state* st, double t, const double* times, const double* speeds,
                        int m, int has_planned, double planned_t, double planned_r,
                        double* out) {
    int nh = st->n_history;
    double ht[FT_MAX_HISTORY + 1], hr[FT_MAX_HISTORY + 1];
    memcpy(ht, st->history_t, nh * sizeof(double));
    memcpy(hr, st->history_r, nh * sizeof(double));
    if (has_planned && planned_r != hr[nh - 1]) {
        ht[nh] = planned_t;
        hr[nh] = planned_r;
        nh++;
    }
    double(*arrivals)[FT_N_VEHICLES] = malloc(2 * (size_t)nh * sizeof *arrivals);
    double(*overtaken)[FT_N_VEHICLES] = arrivals + nh;
    if (!arrivals) { /* out of memory: no air brake foreseen */
        for (int j = 0; j < m; j++) out[j] = 0.0;
        return;
    }
    int seen[FT_N_VEHICLES], seen_min = nh;
    for (int i = 0; i < FT_N_VEHICLES; i++) {
        seen[i] = 0;
        for (int k = 0; k < nh; k++) {
            int rising = k == 0 || hr[k] >= hr[k - 1];
            arrivals[k][i] = ht[k] + (rising ? FT_APPLY_DELAY[i] : FT_RELEASE_DELAY[i]);
            if (arrivals[k][i] <= t) seen[i] = k;
        }
        if (seen[i] < seen_min) seen_min = seen[i];
        overtaken[nh - 1][i] = arrivals[nh - 1][i];
        for (int k = nh - 2; k >= 0; k--)
            overtaken[k][i] = ft_min(arrivals[k][i], overtaken[k + 1][i]);
    }
    for (int j = 0; j < m; j++) {
        double sum = 0.0;
        for (int i = 0; i < FT_N_VEHICLES; i++) {
            double target = target_pressure(hr[seen[i]]);
            double pres = st->pressure[i], now = t;
            for (int k = seen_min + 1; k < nh; k++) {
                int kk = k + 1 < nh - 1 ? k + 1 : nh - 1;
                int acts = k > seen[i] && (k == nh - 1 || arrivals[k][i] < overtaken[kk][i]);
                double arrive = acts ? arrivals[k][i] : INFINITY;
                if (arrive > now && arrive <= times[j]) {
                    pres = evolve(pres, target, arrive - now);
                    now = arrive;
                }
                if (arrive <= times[j]) target = target_pressure(hr[k]);
            }
            pres = evolve(pres, target, ft_max(times[j] - now, 0.0));
            sum += pres * FT_BRAKE_SCALE[i];
        }
        out[j] = sum * friction_at(speeds[j]);
    }
    free(arrivals);
}

/* -- FreightTracker ------------------------------------------------------------------------ */

double ft_reference_feedforward(const ft_const* c, double v, double s, double preview_time) {
    return ato_profile_accel(&c->profile, s + ft_max(v, 0.0) * preview_time);
}

void ft_reset(ft_state* st) {
    memset(st, 0, sizeof *st);
    st->changed_at = -INFINITY;
    st->approach_stop = INFINITY;
    st->n_history = 1;
    st->history_t[0] = -1e18;
    st->history_r[0] = 0.0;
}

static int planned_onsets(ft_const* c) {
    const ato_profile* p = &c->profile;
    int m = p->n - 1;
    int* harder = malloc((m > 0 ? m : 1) * sizeof(int));
    c->onset = malloc((m > 0 ? m : 1) * sizeof(double));
    c->onset_stop = malloc((m > 0 ? m : 1) * sizeof(double));
    c->n_onsets = 0;
    if (!harder || !c->onset || !c->onset_stop) return 0;
    if (c->stop_ed_share <= 0.0) {
        free(harder);
        return 1;
    }
    for (int k = 0; k < m; k++) {
        double mid = 0.5 * (p->x[k] + p->x[k + 1]);
        double u = sqrt(0.5 * (p->v[k] * p->v[k] + p->v[k + 1] * p->v[k + 1]));
        double trac, ed;
        traction_limits(u, &trac, &ed);
        double need = -(p->accel[k] + basic_accel(u) + additional_accel(c, mid)) * FT_M_EFF;
        harder[k] = need > c->stop_ed_share * ed + 1e-3 * FT_MAX_ED_FORCE;
    }
    for (int j = 0; j < m; j++) {
        if (!(p->v[j + 1] <= 0.0 && p->v[j] > 0.0)) continue;
        int k = j;
        while (k > 0 && harder[k - 1] && p->v[k] > 0.0) k--;
        if (harder[j]) {
            c->onset[c->n_onsets] = p->x[k];
            c->onset_stop[c->n_onsets] = next_stop(c, p->x[k]);
            c->n_onsets++;
        }
    }
    free(harder);
    return 1;
}

int ft_make(ft_const* c, const ato_values* p, char* err, size_t n) {
    const double* v = p->v;
    char a[40], b[40];
    memset(c, 0, sizeof *c);
    c->air_preview_time = v[ATO_VR_air_preview_time];
    c->ed_share = v[ATO_VR_ed_share];
    c->release_share = v[ATO_VR_release_share];
    c->min_apply_time = v[ATO_VR_min_apply_time];
    c->min_release_time = v[ATO_VR_min_release_time];
    c->reduction_step = v[ATO_VR_reduction_step];
    c->overspeed = v[ATO_VR_overspeed];
    c->stop_speed = v[ATO_VR_stop_speed];
    c->hold_reduction = v[ATO_VR_hold_reduction];
    c->final_approach_distance = v[ATO_VR_final_approach_distance];
    c->stop_tolerance = v[ATO_VR_stop_tolerance];
    c->stop_ed_share = v[ATO_VR_stop_ed_share];
    c->sample_time = v[ATO_VR_sample_time];
    c->mean_weight = v[ATO_VR_mean_weight];
    double tc = v[ATO_VR_observer_correction_time];
    if (!(0 < c->release_share && c->release_share < c->ed_share)) {
        snprintf(err, n, "need 0 < release_share (%s) < ed_share (%s)",
                 ato_repr(c->release_share, a), ato_repr(c->ed_share, b));
        return 0;
    }
    if (c->sample_time != FT_DESIGN_SAMPLE_TIME) {
        snprintf(err, n, "sample_time = %s: the native FMU carries the mean-speed observer's "
                 "design model for sample_time = %s only (another one needs the Python FMU)",
                 ato_repr(c->sample_time, a), ato_repr(FT_DESIGN_SAMPLE_TIME, b));
        return 0;
    }
    if (!(c->sample_time > 0 && tc > 0)) {
        snprintf(err, n, "need sample_time > 0 and correction_time > 0 (got %s, %s)",
                 ato_repr(c->sample_time, a), ato_repr(tc, b));
        return 0;
    }
    c->speed_gain = 2.0 * c->sample_time / tc;
    c->bias_gain = c->sample_time / (tc * tc);
    if (c->speed_gain >= 1.0) {
        snprintf(err, n, "correction_time = %s s must exceed 2 sample times (%s s)",
                 ato_repr(tc, a), ato_repr(2 * c->sample_time, b));
        return 0;
    }
    const char* route = p->s[ATO_VR_route];
    for (int i = 0; i < FT_N_ROUTES; i++)
        if (route && strcmp(route, FT_ROUTES[i].route) == 0) c->route = &FT_ROUTES[i];
    if (!c->route) {
        snprintf(err, n, "route = '%s': the native FMU knows the bundled routes with a "
                 "speed-distance reference profile only (a route file needs the Python FMU)",
                 route ? route : "");
        return 0;
    }
    if (!ato_profile_load(&c->profile, p->resources, c->route->reference, err, n)) return 0;
    if (!c->profile.distance) {
        snprintf(err, n, "freight blending needs a speed-distance reference profile");
        return 0;
    }
    const ato_profile* pr = &c->profile;
    c->stops = malloc(pr->n * sizeof(double));
    c->peak_ahead = malloc(pr->n * sizeof(double));
    if (!c->stops || !c->peak_ahead) {
        snprintf(err, n, "out of memory");
        return 0;
    }
    for (int i = 0; i < pr->n; i++)
        if (pr->v[i] <= 0.0) c->stops[c->n_stops++] = pr->x[i];
    for (int i = pr->n - 1; i >= 0; i--)
        c->peak_ahead[i] = i == pr->n - 1 ? pr->v[i] : fmax(pr->v[i], c->peak_ahead[i + 1]);
    if (!planned_onsets(c)) {
        snprintf(err, n, "out of memory");
        return 0;
    }
    return 1;
}

void* ft_new(size_t size, char* err, size_t err_size) {
    void* c = calloc(1, size);
    if (!c) snprintf(err, err_size, "out of memory");
    return c;
}

int ft_start(ft_const* c, ft_state* st, const ato_values* p, char* err,
             size_t err_size) {
    if (!ft_make(c, p, err, err_size)) {
        ft_free(c);
        return 0;
    }
    ft_reset(st);
    return 1;
}

void ft_free(ft_const* c) {
    ato_profile_free(&c->profile);
    free(c->stops);
    free(c->peak_ahead);
    free(c->onset);
    free(c->onset_stop);
}

int ft_compute(const ft_const* c, ft_state* st, double t, double v, double s, ft_demand law,
               void* law_data, char* err, size_t n) {
    double w = c->mean_weight;
    double vc = observer_update(c, st, v);
    st->v_feedback = w == 0.0 ? v : (1.0 - w) * v + w * vc;
    double before[FT_N_VEHICLES];
    memcpy(before, st->pressure, sizeof before);
    /* _track */
    double speed = ft_max(v, 0.0), lo, hi;
    st->v_ref = ato_profile_speed(&c->profile, s);
    st->speed_error = v - st->v_ref;
    double a_res = resistance_accel(c, speed, s);
    accel_limits(st, speed, &lo, &hi);
    st->demand = law(law_data, st, t, v, s, a_res, lo, hi);
    int loco = st->has_locomotive;
    if (!blend(c, st, t, c->sample_time, v, s,
               FT_M_EFF * (loco ? st->locomotive_demand : st->demand), st->v_ref, st->a_ref,
               a_res, loco, err, n))
        return 0;
    /* observer.record */
    double mean[FT_N_VEHICLES];
    for (int i = 0; i < FT_N_VEHICLES; i++) mean[i] = 0.5 * (before[i] + st->pressure[i]);
    st->u = st->force / FT_M_EFF;
    st->air = dot(FT_BRAKE_SCALE, mean, FT_N_VEHICLES);
    st->s = s;
    return 1;
}

void ft_outputs(const ft_state* st, double* out) {
    out[ATO_VR_force_demand] = st->force;
    out[ATO_VR_pipe_reduction] = st->reduction;
    out[ATO_VR_accel_demand] = st->demand;
    out[ATO_VR_v_ref] = st->v_ref;
    out[ATO_VR_a_ref] = st->a_ref;
    out[ATO_VR_speed_error] = st->speed_error;
    out[ATO_VR_air_brake_estimate] = st->pressure_estimate;
    out[ATO_VR_v_mean_estimate] = st->started ? st->z[0] : 0.0;
}
