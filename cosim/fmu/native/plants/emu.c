/*
 * emu.c: native model of the EMU plants Emu3 / Emu8, the C twin of plants/emu.py and its
 * compiled kernels (plants/kernels.py emu_steps, emu_outputs): a chain of n power units
 * (n = the number of force[i] inputs of the generated header) joined by spring-damper
 * couplers (seed 001 eq. 1; seed 004 eqs. 1-3).
 *
 *   m_i (1 + gamma) dv_i/dt = u_i - F_Ni(v_i) - F_Ai(s_i) - F_Z(i) + F_Z(i-1) + w_i(t)
 *   F_Ni = a_i + b_i v_i + c_i v_i^2,  F_Ai = m_i g w_add / 1000 (length mean),
 *   F_Zj = k (x_j - x_j+1) + d (v_j - v_j+1)
 *   u_i clipped to the envelope: traction min(F_t, P_t / v) (none in a neutral section),
 *   braking min(F_b, P_b / v); w_i = m_i sigma N(0, 1) held per disturbance interval, drawn
 *   from numpy's default_rng([seed, interval index]) (numpy_random.c)
 *
 * The coupler part is solved exactly over a sub-step (X+ = phi X + gamma f, the matrix
 * exponential of [[A h, B h], [0, 0]]), the other forces at the midpoint predicted by a half
 * step; sub-steps on the absolute grid of max_step and of the disturbance interval; the
 * standstill hold as the core's. Every operation is the kernel's, in its order, except the
 * matrix exponential: the core takes scipy.linalg.expm (LAPACK / BLAS), this file a Pade(13)
 * scaling-and-squaring exponential (Higham 2005), so phi and gamma agree to a few ulp of
 * their norm, not bit for bit; tests/test_native_plants.py states and checks the bound.
 *
 * The configuration parameter selects the train data generated from plants.emu
 * CONFIGURATIONS (<id>_config.h); coupler_stiffness / coupler_damping = -1 keep the
 * configuration's value.
 *
 * A coloured disturbance (disturbance_correlation_time tau > 0; plants.emu.coloured_noise):
 * w_i = m_i sigma sqrt(2/K) sum_k cos(omega_ik t + phi_ik) at the interval's start t, K = 64
 * components drawn once from numpy's default_rng([seed, 0xC010]): omega = tan(pi/2 u) / tau
 * (Lorentzian) or, smooth, |ndtri(1/2 + u/2)| / tau (Gaussian), phi = 2 pi u'; the sum in
 * numpy's pairwise order. ndtri is scipy's inverse normal CDF; here Halley's iteration on
 * libm's erfc from Abramowitz-Stegun 26.2.23, so omega agrees with the core's to a few ulp,
 * not bit for bit (tests/test_native_plants.py states and checks the bound).
 */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "numpy_random.h"
#include "plant_common.h"
#include "ato_model_decl.h"

#define N ATO_N_force  /* units */
#define N2 (2 * N)
#define NB (3 * N)     /* the block matrix of the propagator */
#define N_PROPS 8      /* propagators kept (sub-step lengths) */
#define KEEP (-1.0)    /* cosim.fmu.declare.KEEP */
#define COLOURED 64    /* plants.emu.COLOURED_COMPONENTS */
#define PI 3.141592653589793 /* np.pi */

typedef struct {
    int64_t h_ticks; /* 0: unused */
    double phi[N2][N2], gamma[N2][N], hphi[N2][N2], hgamma[N2][N];
} propagator;

typedef struct {
    /* parameters */
    double m[N], m_eff[N], lengths[N], offsets[N], da[N], db[N], dc[N], ft[N], pt[N], fb[N],
        pb[N], motored[N];
    double k, d, standstill, total_mass, g_kn, sigma;
    int has_neutral;
    int64_t grid, noise_ticks, seed;
    double a_mat[N2][N2], b_mat[N2][N]; /* dX/dt = A X + B f */
    ato_route route;
    ato_profile additional;
    ato_cumulative add_cum;
    propagator props[N_PROPS];
    int next_prop;
    int64_t noise_index; /* the interval whose draws are in noise_cache; -1: none */
    double noise_cache[N];
    int coloured;                      /* tau > 0: the spectrum below, not white draws */
    double omega[N][COLOURED], phase[N][COLOURED];
    /* state (Emu.state_fields) */
    int64_t t;
    double x[N], v[N];
    int32_t held;
    double traction_energy, regenerated_energy;
    double command[N];
} emu;

/* numpy's sum of a contiguous float64 array (pairwise_sum for n <= 128: 8 accumulators) */
static double np_sum(const double* a, int n) {
    if (n < 8) {
        double res = 0.0;
        for (int i = 0; i < n; i++) res += a[i];
        return res;
    }
    double r[8];
    for (int j = 0; j < 8; j++) r[j] = a[j];
    int i;
    for (i = 8; i < n - (n % 8); i += 8)
        for (int j = 0; j < 8; j++) r[j] += a[i + j];
    double res = ((r[0] + r[1]) + (r[2] + r[3])) + ((r[4] + r[5]) + (r[6] + r[7]));
    for (; i < n; i++) res += a[i];
    return res;
}

/* -- matrix exponential (Pade 13, scaling and squaring) ------------------------------------ */
static void matmul(int n, const double* a, const double* b, double* out) {
    for (int r = 0; r < n; r++)
        for (int c = 0; c < n; c++) {
            double acc = 0.0;
            for (int k = 0; k < n; k++) acc += a[r * n + k] * b[k * n + c];
            out[r * n + c] = acc;
        }
}

/* solve P X = Q (n x n, LU with partial pivoting) into Q */
static void solve(int n, double* p, double* q) {
    for (int col = 0; col < n; col++) {
        int piv = col;
        for (int r = col + 1; r < n; r++)
            if (fabs(p[r * n + col]) > fabs(p[piv * n + col])) piv = r;
        if (piv != col)
            for (int c = 0; c < n; c++) {
                double t = p[col * n + c]; p[col * n + c] = p[piv * n + c]; p[piv * n + c] = t;
                t = q[col * n + c]; q[col * n + c] = q[piv * n + c]; q[piv * n + c] = t;
            }
        for (int r = col + 1; r < n; r++) {
            double f = p[r * n + col] / p[col * n + col];
            if (f == 0.0) continue;
            for (int c = col; c < n; c++) p[r * n + c] -= f * p[col * n + c];
            for (int c = 0; c < n; c++) q[r * n + c] -= f * q[col * n + c];
        }
    }
    for (int col = n - 1; col >= 0; col--)
        for (int c = 0; c < n; c++) {
            double acc = q[col * n + c];
            for (int k = col + 1; k < n; k++) acc -= p[col * n + k] * q[k * n + c];
            q[col * n + c] = acc / p[col * n + col];
        }
}

static void expm(int n, const double* a_in, double* out) {
    static const double b[14] = {
        64764752532480000.0, 32382376266240000.0, 7771770303897600.0, 1187353796428800.0,
        129060195264000.0, 10559470521600.0, 670442572800.0, 33522128640.0, 1323241920.0,
        40840800.0, 960960.0, 16380.0, 182.0, 1.0};
    size_t sz = (size_t)n * (size_t)n;
    double* w = malloc(8 * sz * sizeof(double));
    double *a = w, *a2 = w + sz, *a4 = w + 2 * sz, *a6 = w + 3 * sz, *u = w + 4 * sz,
           *v = w + 5 * sz, *t = w + 6 * sz, *t2 = w + 7 * sz;
    double norm = 0.0; /* 1-norm */
    for (int c = 0; c < n; c++) {
        double col = 0.0;
        for (int r = 0; r < n; r++) col += fabs(a_in[r * n + c]);
        if (col > norm) norm = col;
    }
    int s = 0;
    if (norm > 5.371920351148152) s = (int)ceil(log2(norm / 5.371920351148152));
    double scale = ldexp(1.0, -s);
    for (size_t i = 0; i < sz; i++) a[i] = a_in[i] * scale;
    matmul(n, a, a, a2);
    matmul(n, a2, a2, a4);
    matmul(n, a2, a4, a6);
    for (size_t i = 0; i < sz; i++) t[i] = b[13] * a6[i] + b[11] * a4[i] + b[9] * a2[i];
    matmul(n, a6, t, t2);
    for (size_t i = 0; i < sz; i++) t2[i] += b[7] * a6[i] + b[5] * a4[i] + b[3] * a2[i];
    for (int i = 0; i < n; i++) t2[i * n + i] += b[1];
    matmul(n, a, t2, u);
    for (size_t i = 0; i < sz; i++) t[i] = b[12] * a6[i] + b[10] * a4[i] + b[8] * a2[i];
    matmul(n, a6, t, v);
    for (size_t i = 0; i < sz; i++) v[i] += b[6] * a6[i] + b[4] * a4[i] + b[2] * a2[i];
    for (int i = 0; i < n; i++) v[i * n + i] += b[0];
    for (size_t i = 0; i < sz; i++) {
        t[i] = v[i] - u[i];   /* P = V - U */
        out[i] = v[i] + u[i]; /* Q = V + U */
    }
    solve(n, t, out);
    for (int k = 0; k < s; k++) {
        matmul(n, out, out, t);
        memcpy(out, t, sz * sizeof(double));
    }
    free(w);
}

/* exp([[A h, B h], [0, 0]]) = [[phi, gamma], [0, I]] */
static void zoh(const emu* e, double h, double phi[N2][N2], double gamma[N2][N]) {
    double big[NB * NB], out[NB * NB];
    memset(big, 0, sizeof big);
    for (int r = 0; r < N2; r++) {
        for (int c = 0; c < N2; c++) big[r * NB + c] = e->a_mat[r][c] * h;
        for (int c = 0; c < N; c++) big[r * NB + N2 + c] = e->b_mat[r][c] * h;
    }
    expm(NB, big, out);
    for (int r = 0; r < N2; r++) {
        for (int c = 0; c < N2; c++) phi[r][c] = out[r * NB + c];
        for (int c = 0; c < N; c++) gamma[r][c] = out[r * NB + N2 + c];
    }
}

static const propagator* propagator_for(emu* e, int64_t h_ticks) {
    for (int i = 0; i < N_PROPS; i++)
        if (e->props[i].h_ticks == h_ticks) return &e->props[i];
    propagator* p = &e->props[e->next_prop];
    e->next_prop = (e->next_prop + 1) % N_PROPS;
    double h = ato_to_seconds(h_ticks);
    zoh(e, h, p->phi, p->gamma);
    zoh(e, 0.5 * h, p->hphi, p->hgamma);
    p->h_ticks = h_ticks;
    return p;
}

/* -- forces (kernels.py _emu_route, _emu_neutral, _emu_limits, _emu_force, _emu_holds) ---- */
static void route_force(const emu* e, const double* x, double* out) {
    for (int i = 0; i < N; i++) {
        double front = x[i] - e->offsets[i];
        double c_front = ato_interp(&e->add_cum, front);
        double c_rear = ato_interp(&e->add_cum, front - e->lengths[i]);
        out[i] = e->m[i] * (e->g_kn * ((c_front - c_rear) / e->lengths[i]));
    }
}

static void neutral_at(const emu* e, const double* x, int* out) {
    for (int i = 0; i < N; i++)
        out[i] = e->has_neutral && ato_profile_at(&e->route.neutral,
                                                  x[i] - e->offsets[i] - 0.5 * e->lengths[i])
                                   > 0;
}

static void limits(const emu* e, const double* v, const int* neutral, double* hi, double* lo) {
    for (int i = 0; i < N; i++) {
        hi[i] = neutral[i] ? 0.0 : ato_envelope(e->ft[i], e->pt[i], v[i]);
        lo[i] = ato_envelope(e->fb[i], e->pb[i], v[i]);
    }
}

static void force(const emu* e, const double* applied, const double* v, const double* route,
                  const double* noise, double* out) {
    for (int i = 0; i < N; i++) {
        double sign = ato_min(ato_max(v[i] * (1.0 / e->standstill), -1.0), 1.0);
        double resist = e->da[i] * sign + e->db[i] * v[i] + e->dc[i] * v[i] * fabs(v[i]);
        out[i] = ato_max(applied[i], 0.0) + ato_min(applied[i], 0.0) * sign - resist - route[i]
                 + noise[i];
    }
}

static int holds(const emu* e, const double* u) {
    double route[N], hi[N], lo[N], zero[N] = {0};
    int neutral[N];
    route_force(e, e->x, route);
    neutral_at(e, e->x, neutral);
    limits(e, zero, neutral, hi, lo);
    double pos = 0.0, neg = 0.0, rf = 0.0, dsum = 0.0;
    for (int i = 0; i < N; i++) {
        double a = ato_max(ato_min(u[i], hi[i]), -lo[i]);
        pos += ato_max(a, 0.0);
        neg += -ato_min(a, 0.0);
        rf += route[i];
        dsum += e->da[i];
    }
    return fabs(pos - rf) <= neg + dsum;
}

/* scipy.special.ndtri(p) for p in [1/2, 1): x >= 0 with Phi(x) = p, i.e. erfc(x / sqrt 2) / 2
 * = q = 1 - p (exact for p >= 1/2); Abramowitz-Stegun 26.2.23 (|error| < 4.5e-4), then
 * Halley's iteration on f(x) = erfc(x / sqrt 2) / 2 - q (f' = -phi, f'' = x phi) */
static double ndtri_upper(double p) {
    double q = 1.0 - p;
    if (q >= 0.5) return 0.0;
    if (q <= 0.0) return INFINITY; /* ndtri(1) */
    double t = sqrt(-2.0 * log(q));
    double x = t - (2.515517 + (0.802853 + 0.010328 * t) * t) /
                       (1.0 + (1.432788 + (0.189269 + 0.001308 * t) * t) * t);
    for (int i = 0; i < 8; i++) {
        double phi = exp(-0.5 * x * x) / sqrt(2.0 * PI);
        double d = (0.5 * erfc(x / sqrt(2.0)) - q) / phi;
        double step = d / (1.0 - 0.5 * x * d);
        x += step;
        if (fabs(step) <= 1e-17 * x) break;
    }
    return x;
}

/* the spectrum of the coloured disturbance (plants.emu._coloured_spectrum) */
static void coloured_spectrum(emu* e, double tau, int smooth) {
    uint64_t ints[2] = {(uint64_t)e->seed, 0xC010};
    ato_pcg64 g;
    ato_pcg64_seed(&g, ints, 2);
    for (int i = 0; i < N; i++)
        for (int k = 0; k < COLOURED; k++) {
            double u = ato_pcg64_double(&g);
            e->omega[i][k] = smooth ? fabs(ndtri_upper(0.5 + 0.5 * u)) / tau
                                    : tan(0.5 * PI * u) / tau;
        }
    for (int i = 0; i < N; i++)
        for (int k = 0; k < COLOURED; k++) e->phase[i][k] = ato_pcg64_double(&g) * 2.0 * PI;
}

/* the disturbance force (N) of the interval holding tick (Emu._noise) */
static const double* noise_at(emu* e, int64_t tick) {
    static const double zeros[N] = {0};
    if (e->sigma == 0.0) return zeros;
    int64_t index = ato_floordiv(tick, e->noise_ticks);
    if (index != e->noise_index && e->coloured) { /* coloured_noise at the interval's start */
        double t = ato_to_seconds(index * e->noise_ticks), terms[COLOURED];
        for (int i = 0; i < N; i++) {
            for (int k = 0; k < COLOURED; k++)
                terms[k] = cos(e->omega[i][k] * t + e->phase[i][k]);
            double unit = sqrt(2.0 / COLOURED) * np_sum(terms, COLOURED);
            e->noise_cache[i] = e->m[i] * e->sigma * unit;
        }
        e->noise_index = index;
    } else if (index != e->noise_index) {
        uint64_t ints[2] = {(uint64_t)e->seed, (uint64_t)index};
        ato_pcg64 g;
        ato_pcg64_seed(&g, ints, 2);
        for (int i = 0; i < N; i++)
            e->noise_cache[i] = e->m[i] * e->sigma * ato_standard_normal(&g);
        e->noise_index = index;
    }
    return e->noise_cache;
}

static void affine(const double phi[N2][N2], const double gamma[N2][N], const double* state,
                   const double* f, double* out) {
    for (int r = 0; r < N2; r++) {
        double acc = 0.0;
        for (int c = 0; c < N2; c++) acc += phi[r][c] * state[c];
        double acc2 = 0.0;
        for (int c = 0; c < N; c++) acc2 += gamma[r][c] * f[c];
        out[r] = acc + acc2;
    }
}

/* one sub-step of h_ticks from tick (kernels.py emu_steps) */
static void substep(emu* e, int64_t tick, int64_t h_ticks, const double* u, int all_le,
                    int any_lt) {
    const double* noise = noise_at(e, tick);
    if (e->held) {
        if (holds(e, u)) return;
        e->held = 0;
    }
    const propagator* p = propagator_for(e, h_ticks);
    double h = ato_to_seconds(h_ticks);
    double state[N2], mid[N2], next[N2], x_mid[N], v_mid[N], route[N], hi[N], lo[N],
        applied[N], f[N];
    int neutral[N];
    for (int i = 0; i < N; i++) {
        state[i] = e->x[i];
        state[N + i] = e->v[i];
        x_mid[i] = e->x[i] + 0.5 * h * e->v[i];
    }
    route_force(e, x_mid, route);
    neutral_at(e, x_mid, neutral);
    limits(e, e->v, neutral, hi, lo);
    for (int i = 0; i < N; i++) applied[i] = ato_max(ato_min(u[i], hi[i]), -lo[i]);
    force(e, applied, e->v, route, noise, f);
    affine(p->hphi, p->hgamma, state, f, mid);
    for (int i = 0; i < N; i++) v_mid[i] = mid[N + i];
    limits(e, v_mid, neutral, hi, lo);
    for (int i = 0; i < N; i++) applied[i] = ato_max(ato_min(u[i], hi[i]), -lo[i]);
    force(e, applied, v_mid, route, noise, f);
    affine(p->phi, p->gamma, state, f, next);
    double trac = 0.0, regen = 0.0, mv_before = 0.0, mv_after = 0.0;
    for (int i = 0; i < N; i++) {
        trac += ato_max(applied[i], 0.0) * v_mid[i];
        regen += ato_min(-ato_min(applied[i], 0.0), hi[i]) * e->motored[i]
                 * ato_max(v_mid[i], 0.0);
        mv_before += e->m[i] * e->v[i];
        mv_after += e->m[i] * next[N + i];
        e->x[i] = next[i];
        e->v[i] = next[N + i];
    }
    e->traction_energy += h * trac;
    e->regenerated_energy += h * regen;
    double v_mean = mv_after / e->total_mass;
    int creeping = v_mean <= e->standstill && all_le && any_lt;
    if ((v_mean <= 0.0 && mv_before > 0.0) || creeping) {
        if (holds(e, u)) {
            for (int i = 0; i < N; i++) e->v[i] = 0.0;
            e->held = 1;
        }
    }
}

static int step(ato_inst* m, void* core, int64_t t, int64_t h) {
    emu* e = core;
    if (t != e->t) {
        ATO_ERROR(m, "doStep at t=%.17g s but plant is at t=%.17g s", ato_to_seconds(t),
                  ato_to_seconds(e->t));
        return 0;
    }
    double u[N];
    int all_le = 1, any_lt = 0;
    for (int i = 0; i < N; i++) {
        u[i] = m->r[ATO_VRS_force[i]];
        if (u[i] > 0.0) all_le = 0;
        if (u[i] < 0.0) any_lt = 1;
    }
    int64_t grids[2] = {e->grid, e->sigma != 0.0 ? e->noise_ticks : 0};
    int64_t* cuts;
    size_t n = ato_substep_ends(t, h, grids, 2, &cuts);
    int64_t now = t;
    for (size_t i = 0; i < n; i++) {
        substep(e, now, cuts[i] - now, u, all_le, any_lt);
        now = cuts[i];
    }
    free(cuts);
    memcpy(e->command, u, sizeof u);
    e->t = t + h;
    return 1;
}

/* kernels.py emu_outputs and Emu._outputs_compiled */
static void outputs(ato_inst* m, void* core) {
    emu* e = core;
    double* r = m->r;
    double tl[N], bl[N], applied[N], fz[N > 1 ? N - 1 : 1], a[N], route[N], f[N];
    int neutral[N];
    const double* noise = e->held ? (const double[N]){0} : noise_at(e, e->t);
    neutral_at(e, e->x, neutral);
    limits(e, e->v, neutral, tl, bl);
    for (int i = 0; i < N; i++) applied[i] = ato_max(ato_min(e->command[i], tl[i]), -bl[i]);
    double max_fz = 0.0;
    for (int j = 0; j < N - 1; j++) {
        fz[j] = e->k * (e->x[j] - e->x[j + 1]) + e->d * (e->v[j] - e->v[j + 1]);
        max_fz = ato_max(max_fz, fabs(fz[j]));
    }
    if (e->held) {
        for (int i = 0; i < N; i++) a[i] = 0.0;
    } else {
        route_force(e, e->x, route);
        force(e, applied, e->v, route, noise, f);
        for (int j = 0; j < N - 1; j++) f[j] -= fz[j];
        for (int j = 0; j < N - 1; j++) f[j + 1] += fz[j];
        for (int i = 0; i < N; i++) a[i] = f[i] / e->m_eff[i];
    }
    double mv = 0.0, ma = 0.0, m_sum = 0.0, pos = 0.0, regen = 0.0, s_tl = 0.0, s_bl = 0.0;
    for (int i = 0; i < N; i++) {
        mv += e->m[i] * e->v[i];
        ma += e->m_eff[i] * a[i];
        m_sum += e->m_eff[i];
        pos += ato_max(applied[i] * e->v[i], 0.0);
        regen += ato_min(-ato_min(applied[i], 0.0), tl[i]) * e->motored[i] * e->v[i];
        s_tl += tl[i];
        s_bl += bl[i];
    }
    double front = e->x[0] - e->offsets[0];
    r[ATO_VR_v] = mv / e->total_mass;
    r[ATO_VR_s] = front;
    r[ATO_VR_a] = ma / m_sum;
    r[ATO_VR_v_head] = e->v[0];
    r[ATO_VR_s_tail] = e->x[N - 1] - e->offsets[N - 1] - e->lengths[N - 1];
    r[ATO_VR_power] = pos - regen;
    r[ATO_VR_traction_energy] = e->traction_energy;
    r[ATO_VR_regenerated_energy] = e->regenerated_energy;
    r[ATO_VR_max_abs_coupler_force] = max_fz;
    r[ATO_VR_total_traction_limit] = s_tl;
    r[ATO_VR_total_brake_limit] = s_bl;
    r[ATO_VR_speed_limit] = ato_profile_at(&e->route.speed_limit, front);
    r[ATO_VR_grade] = ato_profile_at(&e->route.grade, front);
    r[ATO_VR_neutral] = ato_profile_at(&e->route.neutral, front - 0.5 * e->lengths[0]);
    for (int i = 0; i < N; i++) {
        r[ATO_VRS_v[i]] = e->v[i];
        r[ATO_VRS_s[i]] = e->x[i] - e->offsets[i];
        r[ATO_VRS_a[i]] = a[i];
        r[ATO_VRS_applied_force[i]] = applied[i];
        r[ATO_VRS_traction_limit[i]] = tl[i];
        r[ATO_VRS_brake_limit[i]] = bl[i];
    }
    for (int j = 0; j < N - 1; j++) r[ATO_VRS_coupler_force[j]] = fz[j];
}

static void destroy(void* core) {
    emu* e = core;
    ato_route_free(&e->route);
    ato_profile_free(&e->additional);
    ato_cumulative_free(&e->add_cum);
    free(e);
}

static const double* field(const ato_config* c, int f, int* n) {
    *n = c->field[f].n;
    return c->field[f].values;
}

/* Emu.from_parameters: build(emu_config(configuration), values), EmuParams.check, __init__ */
static void* create(ato_inst* mi) {
    const double* r = mi->r;
    const char* name = mi->str[ATO_VR_configuration];
    const ato_config* cfg = NULL;
    for (int i = 0; i < ATO_N_CONFIGS; i++)
        if (strcmp(ATO_CONFIGS[i].name, name) == 0) cfg = &ATO_CONFIGS[i];
    if (!cfg) {
        char known[512] = "";
        for (int i = 0; i < ATO_N_CONFIGS; i++) {
            strncat(known, i ? ", " : "", sizeof known - strlen(known) - 1);
            strncat(known, ATO_CONFIGS[i].name, sizeof known - strlen(known) - 1);
        }
        ATO_ERROR(mi, "bad parameter: configuration '%s' unknown (known: %s)", name, known);
        return NULL;
    }
    int n;
    const double* masses = field(cfg, ATO_CFG_MASSES, &n);
    if (n != N) {
        ATO_ERROR(mi, "bad parameter: configuration '%s' has %d units, this FMU has %d", name,
                  n, N);
        return NULL;
    }
    double k = r[ATO_VR_coupler_stiffness], d = r[ATO_VR_coupler_damping];
    const struct { const char* name; double* value; int f; } keep[] = {
        {"coupler_stiffness", &k, ATO_CFG_COUPLER_STIFFNESS},
        {"coupler_damping", &d, ATO_CFG_COUPLER_DAMPING}};
    for (int i = 0; i < 2; i++) {
        if (*keep[i].value == KEEP) {
            *keep[i].value = field(cfg, keep[i].f, &n)[0];
        } else if (*keep[i].value < 0) {
            ATO_ERROR(mi, "bad parameter: %s = %.17g must be >= 0 (or -1: configuration value)",
                      keep[i].name, *keep[i].value);
            return NULL;
        }
    }
    const struct { const char* name; int vr; int positive; } scalars[] = {
        {"rotating_mass_factor", ATO_VR_rotating_mass_factor, 0},
        {"mass_factor", ATO_VR_mass_factor, 1},
        {"davis_a_factor", ATO_VR_davis_a_factor, 0},
        {"davis_b_factor", ATO_VR_davis_b_factor, 0},
        {"davis_c_factor", ATO_VR_davis_c_factor, 0},
        {"disturbance_accel_std", ATO_VR_disturbance_accel_std, 0},
        {"disturbance_correlation_time", ATO_VR_disturbance_correlation_time, 0},
        {"max_step", ATO_VR_max_step, 1},
        {"disturbance_interval", ATO_VR_disturbance_interval, 1}, {"v0", ATO_VR_v0, 0}};
    for (size_t i = 0; i < sizeof scalars / sizeof scalars[0]; i++) {
        double x = r[scalars[i].vr];
        if (scalars[i].positive ? !(x > 0) : !(x >= 0)) {
            ATO_ERROR(mi, "bad parameter: %s = %.17g must be %s 0", scalars[i].name, x,
                      scalars[i].positive ? ">" : ">=");
            return NULL;
        }
    }
    if (r[ATO_VR_disturbance_seed] < 0) {
        ATO_ERROR(mi, "bad parameter: disturbance_seed = %.17g must be >= 0 (numpy "
                  "SeedSequence)", r[ATO_VR_disturbance_seed]);
        return NULL;
    }
    emu* e = calloc(1, sizeof(emu));
    if (!ato_route_load(mi, mi->str[ATO_VR_route], &e->route)) {
        free(e);
        return NULL;
    }
    const ato_profile* parts[] = {&e->route.grade, &e->route.curve_resistance,
                                  &e->route.tunnel_resistance};
    ato_profile_sum(parts, 3, &e->additional); /* Route.additional */
    ato_cumulative_of(&e->additional, &e->add_cum);
    double gamma_rot = r[ATO_VR_rotating_mass_factor];
    const struct { double* dst; int f; } per_unit[] = {
        {e->lengths, ATO_CFG_LENGTHS}, {e->da, ATO_CFG_DAVIS_A}, {e->db, ATO_CFG_DAVIS_B},
        {e->dc, ATO_CFG_DAVIS_C}, {e->ft, ATO_CFG_MAX_TRACTION_FORCE},
        {e->pt, ATO_CFG_MAX_TRACTION_POWER}, {e->fb, ATO_CFG_MAX_BRAKE_FORCE},
        {e->pb, ATO_CFG_MAX_BRAKE_POWER}};
    for (size_t f = 0; f < sizeof per_unit / sizeof per_unit[0]; f++)
        memcpy(per_unit[f].dst, field(cfg, per_unit[f].f, &n), N * sizeof(double));
    double offset = 0.0;
    for (int i = 0; i < N; i++) {
        /* plant mismatch: masses and Davis terms scaled (EmuParams.mass_factor, ...) */
        e->m[i] = masses[i] * r[ATO_VR_mass_factor];
        e->m_eff[i] = e->m[i] * (1.0 + gamma_rot);
        e->da[i] *= r[ATO_VR_davis_a_factor];
        e->db[i] *= r[ATO_VR_davis_b_factor];
        e->dc[i] *= r[ATO_VR_davis_c_factor];
        e->offsets[i] = offset; /* [0, cumsum(lengths)[:-1]] */
        offset = i == 0 ? e->lengths[0] : offset + e->lengths[i];
        e->motored[i] = e->ft[i] > 0 ? 1.0 : 0.0;
    }
    e->k = k;
    e->d = d;
    e->standstill = field(cfg, ATO_CFG_STANDSTILL_SPEED, &n)[0];
    e->total_mass = np_sum(e->m, N);
    e->g_kn = ATO_GRAVITY / 1000.0;
    e->sigma = r[ATO_VR_disturbance_accel_std];
    e->seed = (int64_t)r[ATO_VR_disturbance_seed];
    e->has_neutral = r[ATO_VR_cut_traction_in_neutral] != 0.0 && e->route.neutral.n > 1;
    e->grid = ato_to_ticks(r[ATO_VR_max_step]);
    e->noise_ticks = ato_to_ticks(r[ATO_VR_disturbance_interval]);
    e->noise_index = -1;
    e->coloured = r[ATO_VR_disturbance_correlation_time] > 0 && e->sigma != 0.0;
    if (e->coloured)
        coloured_spectrum(e, r[ATO_VR_disturbance_correlation_time],
                          r[ATO_VR_disturbance_smooth] != 0.0);
    /* A = [[0, I], [-k M^-1 L, -d M^-1 L]], B = [[0], [M^-1]] (L: the chain's Laplacian) */
    double lap[N][N];
    memset(lap, 0, sizeof lap);
    for (int j = 0; j < N - 1; j++) {
        lap[j][j] += 1;
        lap[j + 1][j + 1] += 1;
        lap[j][j + 1] -= 1;
        lap[j + 1][j] -= 1;
    }
    for (int i = 0; i < N; i++) {
        double minv = 1.0 / e->m_eff[i];
        e->a_mat[i][N + i] = 1.0;
        for (int j = 0; j < N; j++) {
            e->a_mat[N + i][j] = -k * minv * lap[i][j];
            e->a_mat[N + i][N + j] = -d * minv * lap[i][j];
        }
        e->b_mat[N + i][i] = minv;
    }
    e->t = mi->start_ticks;
    for (int i = 0; i < N; i++) {
        e->x[i] = r[ATO_VR_s0];
        e->v[i] = r[ATO_VR_v0];
    }
    e->held = r[ATO_VR_v0] == 0.0;
    return e;
}

static void save(const void* core, ato_buf* b) {
    const emu* e = core;
    ato_put(b, &e->t, sizeof e->t);
    ato_put(b, e->x, sizeof e->x);
    ato_put(b, e->v, sizeof e->v);
    ato_put(b, &e->held, sizeof e->held);
    ato_put(b, &e->traction_energy, sizeof e->traction_energy);
    ato_put(b, &e->regenerated_energy, sizeof e->regenerated_energy);
    ato_put(b, e->command, sizeof e->command);
}

static int load(void* core, ato_rd* r) {
    emu* e = core;
    ato_take(r, &e->t, sizeof e->t);
    ato_take(r, e->x, sizeof e->x);
    ato_take(r, e->v, sizeof e->v);
    ato_take(r, &e->held, sizeof e->held);
    ato_take(r, &e->traction_energy, sizeof e->traction_energy);
    ato_take(r, &e->regenerated_energy, sizeof e->regenerated_energy);
    ato_take(r, e->command, sizeof e->command);
    return r->ok;
}

const ato_model ATO_MODEL = {
    {ATO_MODEL_IDENTIFIER, ATO_GUID, "ATO-" ATO_MODEL_IDENTIFIER "-state-1", ATO_N_VARS,
     ATO_VARS},
    create, destroy, step, outputs, save, load,
};
