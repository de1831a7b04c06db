/* The freight sub-step kernel of plants/kernels.py (freight_steps) in C: the kernel of the
 * native FreightTrain FMU (freight.c calls it once per communication step, as the Python core
 * calls the numba kernel) and of the numba-vs-C comparison of benchmarks/bench_kernels.py
 * (built with gcc, called through ctypes). Same equations, same operations in the same order,
 * no fast-math, no FMA contraction (-ffp-contract=off), so its results can be compared with
 * the numba kernel's bit for bit. */
#include <math.h>
#include <stdint.h>

#include "freight_kernel.h"

#define KMH (1.0 / 3.6)

/* as Python's min/max (the first argument on ties) */
static inline double dmin(double a, double b) { return b < a ? b : a; }
static inline double dmax(double a, double b) { return b > a ? b : a; }

/* np.interp(x, xs, cum) walking from the segment hint *j */
static double interp(double x, const double *xs, const double *cum, const double *slopes,
                     int64_t nx, int64_t *j) {
    if (x < xs[0]) { *j = 0; return cum[0]; }
    if (x >= xs[nx - 1]) { *j = nx - 2; return cum[nx - 1]; }
    int64_t k = *j;
    while (k < nx - 2 && x >= xs[k + 1]) k++;
    while (k > 0 && x < xs[k]) k--;
    *j = k;
    if (xs[k] == x) return cum[k];
    return slopes[k] * (x - xs[k]) + cum[k];
}

static double target_pressure(double r, const double *cp) {
    if (r >= dmax(cp[C_R_MIN], 1e-9)) return cp[C_PMAX] * dmin(r / cp[C_R_FULL], 1.0);
    return 0.0;
}

/* x^e; x itself for e = 1 (what pow returns there, without the call) */
static inline double xpow(double x, double e) { return e == 1.0 ? x : pow(x, e); }

static double evolve(double pres, double target, double dt, const double *cp) {
    double pmax = cp[C_PMAX];
    double frac = dmin(pres / pmax, 1.0);
    if (pres < target) {
        double t_up = cp[C_FILL_T] * xpow(frac, 1.0 / cp[C_FILL_E]);
        double up = pmax * xpow(dmin((t_up + dt) / cp[C_FILL_T], 1.0), cp[C_FILL_E]);
        return dmin(up, target);
    }
    if (pres > target) {
        double t_down = cp[C_REL_T] * xpow(1.0 - frac, 1.0 / cp[C_REL_E]);
        double down = pmax * (1.0 - xpow(dmin((t_down + dt) / cp[C_REL_T], 1.0), cp[C_REL_E]));
        return dmax(down, target);
    }
    return pres;
}

static void traction(double f0, double demand, double v_head, double h, const double *cp,
                     double *f1, double *mean) {
    double speed = fabs(v_head), trac, ed;
    if (speed > 0) {
        trac = dmin(cp[C_F_MAX], cp[C_P_MAX] / speed);
        ed = dmin(cp[C_ED_MAX], cp[C_ED_P_MAX] / speed);
    } else {
        trac = cp[C_F_MAX];
        ed = cp[C_ED_MAX];
    }
    if (cp[C_ED_FADE] > 0 && speed < cp[C_ED_FADE]) ed *= speed / cp[C_ED_FADE];
    double target = dmin(dmax(demand, -ed), trac);
    if (cp[C_MODEL] == 0.0) {
        double tau = cp[C_TAU], decay = exp(-h / tau);
        *f1 = target + (f0 - target) * decay;
        *mean = target + (f0 - target) * tau / h * (1.0 - decay);
        return;
    }
    double rate = cp[C_RAMP_RATE], gap = target - f0, step = rate * h;
    if (fabs(gap) <= step) {
        double t_reach = fabs(gap) / rate;
        *f1 = target;
        *mean = target - gap * t_reach / (2.0 * h);
        return;
    }
    *f1 = f0 + copysign(step, gap);
    *mean = 0.5 * (f0 + *f1);
}

static void coupler(double gap, const double *cp, double *k, double *c, double *off) {
    double slack = cp[C_SLACK];
    *k = cp[C_K]; *c = cp[C_C]; *off = 0.0;
    if (slack > 0) {
        double half = 0.5 * slack;
        if (gap > half) *off = half;
        else if (gap < -half) *off = -half;
        else { *k = 0.0; *c = 0.0; }
    }
}

static int holds(double trac, const double *mean_p, int braking, const double *x,
                 const double *length, const double *wpk, const double *brake_scale,
                 const double *res_a, const double *xs, const double *cum, const double *slopes,
                 int64_t nx, int64_t *hint_f, int64_t *hint_r, int64_t n) {
    if (!braking) return 0;
    double grade = 0.0, capacity = 0.0;
    for (int64_t i = 0; i < n; i++) {
        double cf = interp(x[i], xs, cum, slopes, nx, &hint_f[i]);
        double cr = interp(x[i] - length[i], xs, cum, slopes, nx, &hint_r[i]);
        grade -= wpk[i] * ((cf - cr) / length[i]);
        capacity += brake_scale[i] * mean_p[i] * 0.322 + res_a[i];
    }
    return fabs(trac + grade) <= capacity;
}

void freight_steps(int64_t n, int64_t n_sub, int64_t K, int64_t nx, double *x, double *v,
                   double *pres, double *sc, const double *hs, const double *t0s,
                   const double *t1s, const double *demands, const double *arrivals,
                   const double *values, const double *m_eff, const double *length,
                   const double *res_a, const double *res_b, const double *res_c,
                   const double *wpk, const double *brake_scale, const double *xs,
                   const double *cum, const double *slopes, int64_t *hint_f, int64_t *hint_r,
                   const double *cp, double *work, double *targets) {
    int64_t first = (int64_t)sc[S_FIRST];
    double f_trac = sc[S_TRACTION];
    double *start = work + W_START * n, *mean_p = work + W_MEAN_P * n, *y = work + W_Y * n;
    double *w = work + W_W * n, *diag = work + W_DIAG * n, *cprime = work + W_CPRIME * n;
    double *rprime = work + W_RPRIME * n, *v1 = work + W_V1 * n;
    for (int64_t k = first; k < K; k++) targets[k] = target_pressure(values[k], cp);
    double m_total = 0.0;
    for (int64_t i = 0; i < n; i++) m_total += m_eff[i];
    double stiction = cp[C_STICTION];
    int slackless = !(cp[C_SLACK] > 0);
    double factored_h = -1.0;
    for (int64_t s = 0; s < n_sub; s++) {
        double h = hs[s], t0 = t0s[s], t1 = t1s[s], f1, f_mean;
        traction(f_trac, demands[s], v[0], h, cp, &f1, &f_mean);
        /* air brake */
        for (int64_t i = 0; i < n; i++) start[i] = pres[i];
        if (K - first == 1) {
            double target = targets[first];
            int same = 1;
            for (int64_t i = 0; i < n; i++) if (pres[i] != target) { same = 0; break; }
            if (!same)
                for (int64_t i = 0; i < n; i++) pres[i] = evolve(pres[i], target, t1 - t0, cp);
        } else {
            int64_t newest = K;
            for (int64_t i = 0; i < n; i++) {
                int64_t idx0 = first, idx1 = first;
                for (int64_t k = first + 1; k < K; k++) {
                    if (arrivals[k * n + i] <= t0) idx0 = k;
                    if (arrivals[k * n + i] <= t1) idx1 = k;
                }
                double sw = dmin(dmax(arrivals[idx1 * n + i], t0), t1);
                double mid = evolve(pres[i], targets[idx0], sw - t0, cp);
                pres[i] = evolve(mid, targets[idx1], t1 - sw, cp);
                if (idx1 < newest) newest = idx1;
            }
            if (newest > first) first = newest;
        }
        int braking = 0;
        for (int64_t i = 0; i < n; i++) {
            mean_p[i] = 0.5 * (start[i] + pres[i]);
            if (mean_p[i] != 0.0) braking = 1;
        }
        if (sc[S_HELD] != 0.0) {
            if (holds(f_mean, mean_p, braking, x, length, wpk, brake_scale, res_a, xs, cum,
                      slopes, nx, hint_f, hint_r, n)) {
                f_trac = f1;
                sc[S_ACCEL] = 0.0;
                continue;
            }
            sc[S_HELD] = 0.0;
        }
        for (int64_t j = 0; j < n - 1; j++) {
            double gap = x[j] - length[j] - x[j + 1], dv = v[j] - v[j + 1], k, c, off;
            coupler(gap, cp, &k, &c, &off);
            y[j] = k * (gap - off) + (0.25 * h * k + 0.5 * c) * dv;
            w[j] = 0.25 * h * h * k + 0.5 * h * c;
        }
        int refactor = !slackless || h != factored_h;
        factored_h = h;
        for (int64_t i = 0; i < n; i++) {
            double speed = fabs(v[i]);
            double diss = res_a[i] + (res_b[i] + res_c[i] * speed) * speed;
            if (braking) {
                double kmh = fabs(v[i]) / KMH;
                diss = diss + brake_scale[i] * mean_p[i] * (0.322 * (kmh + 150.0)
                                                             / (2.0 * kmh + 150.0));
            }
            double direction = dmax(dmin(v[i] / stiction, 1.0), -1.0);
            double front = x[i] + 0.5 * h * v[i];
            double cf = interp(front, xs, cum, slopes, nx, &hint_f[i]);
            double cr = interp(front - length[i], xs, cum, slopes, nx, &hint_r[i]);
            double force = -diss * direction - wpk[i] * ((cf - cr) / length[i]);
            if (i == 0) force += f_mean;
            if (i < n - 1) force -= y[i];
            if (i > 0) force += y[i - 1];
            double rhs = m_eff[i] * v[i] + h * force;
            if (refactor) {
                double d = m_eff[i];
                if (i > 0) d += w[i - 1];
                if (i < n - 1) d += w[i];
                if (i > 0) d += w[i - 1] * cprime[i - 1];
                diag[i] = d;
                cprime[i] = i < n - 1 ? -w[i] / d : 0.0;
            }
            if (i > 0) rhs += w[i - 1] * rprime[i - 1];
            rprime[i] = rhs / diag[i];
        }
        v1[n - 1] = rprime[n - 1];
        for (int64_t i = n - 2; i >= 0; i--) v1[i] = rprime[i] - cprime[i] * v1[i + 1];
        sc[S_ENERGY] += f_mean * 0.5 * (v[0] + v1[0]) * h;
        double momentum = 0.0, mean_v1 = 0.0;
        for (int64_t i = 0; i < n; i++) {
            momentum += m_eff[i] * (v1[i] - v[i]);
            mean_v1 += m_eff[i] * v1[i];
            x[i] = x[i] + 0.5 * h * (v[i] + v1[i]);
        }
        sc[S_ACCEL] = momentum / (h * m_total);
        f_trac = f1;
        int hold = fabs(mean_v1 / m_total) <= stiction
            && holds(f1, mean_p, braking, x, length, wpk, brake_scale, res_a, xs, cum, slopes,
                     nx, hint_f, hint_r, n);
        if (hold) sc[S_HELD] = 1.0;
        double peak_draft = sc[S_PEAK_DRAFT], peak_buff = sc[S_PEAK_BUFF];
        for (int64_t i = 0; i < n; i++) {
            v[i] = hold ? 0.0 : v1[i];
            if (i > 0) {
                int64_t j = i - 1;
                double g = x[j] - length[j] - x[i], d = v[j] - v[i], k, c, off;
                coupler(g, cp, &k, &c, &off);
                double fc = k * (g - off) + c * d;
                if (fc > peak_draft) peak_draft = fc;
                if (-fc > peak_buff) peak_buff = -fc;
            }
        }
        sc[S_PEAK_DRAFT] = peak_draft;
        sc[S_PEAK_BUFF] = peak_buff;
    }
    sc[S_TRACTION] = f_trac;
    sc[S_FIRST] = (double)first;
}
