/* ffdl.c: see ffdl.h (controllers/common/ffdl.py FfdlEstimator). */
#include <math.h>
#include <string.h>

#include "ffdl.h"
#include "linalg.h"

#define N DD_N

static double pymin(double a, double b) { return b < a ? b : a; }
static int width(const ffdl_params* f) { return N * (f->L_y + f->L_u); }

void ffdl_params_read(ffdl_params* f, const double* v, int disturbance) {
    double gy = v[ATO_VR_output_scale] / DD_KMH_PER_MPS, gu = v[ATO_VR_input_scale];
    double g = gy / gu; /* rescaled(): the factor on Phi_2 */
    f->mu = v[ATO_VR_mu];
    f->step = v[ATO_VR_lambda];
    f->L_y = (int)v[ATO_VR_L_y];
    f->L_u = (int)v[ATO_VR_L_u];
    f->phi1_init = v[ATO_VR_phi1_init];
    f->phi2_init = v[ATO_VR_phi2_init];
    f->reset_threshold = v[ATO_VR_reset_threshold] * g;
    f->excitation = v[ATO_VR_excitation] * pymin(gy, gu);
    f->eps = v[ATO_VR_pinv_regularisation] * g * g;
    f->cutoff = v[ATO_VR_pinv_cutoff];
    f->innovation_dd_hat = v[ATO_VR_innovation_dd_hat] != 0.0;
    f->disturbance = disturbance;
}

int ffdl_state_count(const ffdl_params* f) {
    int w = width(f);
    return N * w + N + f->L_y * N + f->L_u * N + N + w + N + N + 2;
}

void ffdl_bind(ffdl_est* e, const ffdl_params* f, double* at) {
    int w = width(f);
    e->phi = at; at += N * w;
    e->y_prev = at; at += N;
    e->dy_hist = at; at += f->L_y * N;
    e->du_hist = at; at += f->L_u * N;
    e->u_prev = at; at += N;
    e->dH_prev = at; at += w;
    e->dd_hat = at; at += N;
    e->dd_hat_prev = at; at += N;
    e->resets = at++;
    e->started = at;
}

static void initial_phi(const ffdl_est* e, const ffdl_params* f) {
    int w = width(f), k = f->L_y * N;
    for (int i = 0; i < N; i++)
        for (int j = 0; j < w; j++)
            e->phi[i * w + j] = j == i ? f->phi1_init * 1.0 : j == k + i ? f->phi2_init * 1.0
                              : j < N ? f->phi1_init * 0.0 : (j >= k && j < k + N)
                              ? f->phi2_init * 0.0 : 0.0;
}

void ffdl_init(const ffdl_est* e, const ffdl_params* f) {
    memset(e->phi, 0, sizeof(double) * ffdl_state_count(f));
    initial_phi(e, f);
}

void ffdl_observe(const ffdl_est* e, const ffdl_params* f, const double* y, int adapt) {
    if (*e->started == 0.0) { /* start(y, u_prev) */
        memcpy(e->y_prev, y, sizeof(double) * N);
        *e->started = 1.0;
        return;
    }
    int w = width(f), k = f->L_y * N;
    double dy[N], prior[N];
    for (int i = 0; i < N; i++) dy[i] = y[i] - e->y_prev[i];
    memcpy(e->y_prev, y, sizeof(double) * N);
    const double* dH = e->dH_prev; /* dH(t-1) */
    double norm2 = 0.0;
    for (int j = 0; j < w; j++) norm2 += dH[j] * dH[j];
    ato_matvec(e->phi, N, w, dH, prior); /* eq. 14's prediction with Phi(t-1) */
    if (adapt && f->step > 0 && sqrt(norm2) > f->excitation) {
        int known = f->disturbance && f->innovation_dd_hat;
        double den = f->mu + norm2;
        for (int i = 0; i < N; i++) {
            double eps = (dy[i] - (known ? e->dd_hat[i] : 0.0)) - prior[i];
            for (int j = 0; j < w; j++)
                e->phi[i * w + j] = e->phi[i * w + j] + f->step * (eps * dH[j]) / den;
        }
        int reset = 0;
        for (int i = 0; i < N; i++) reset |= e->phi[i * w + k + i] < f->reset_threshold;
        if (reset) {
            initial_phi(e, f);
            *e->resets += 1.0;
        }
    }
    memcpy(e->dd_hat_prev, e->dd_hat, sizeof(double) * N);
    if (!f->disturbance) {
        for (int i = 0; i < N; i++) e->dd_hat[i] = 0.0;
    } else {
        double now[N];
        if (f->innovation_dd_hat) ato_matvec(e->phi, N, w, dH, now);
        for (int i = 0; i < N; i++) e->dd_hat[i] = dy[i] - (f->innovation_dd_hat ? now[i]
                                                                               : prior[i]);
    }
    memmove(e->dy_hist + N, e->dy_hist, sizeof(double) * (f->L_y - 1) * N);
    memcpy(e->dy_hist, dy, sizeof dy);
}

void ffdl_applied(const ffdl_est* e, const ffdl_params* f, const double* u) {
    double du[N];
    for (int i = 0; i < N; i++) du[i] = u[i] - e->u_prev[i];
    memcpy(e->u_prev, u, sizeof du);
    memmove(e->du_hist + N, e->du_hist, sizeof(double) * (f->L_u - 1) * N);
    memcpy(e->du_hist, du, sizeof du);
    memcpy(e->dH_prev, e->dy_hist, sizeof(double) * f->L_y * N);
    memcpy(e->dH_prev + f->L_y * N, e->du_hist, sizeof(double) * f->L_u * N);
}

void ffdl_free_response(const ffdl_est* e, const ffdl_params* f, double* out) {
    int w = width(f), k = f->L_y * N;
    for (int i = 0; i < N; i++) {
        double s = 0.0;
        for (int j = 0; j < k; j++) s += e->phi[i * w + j] * e->dy_hist[j];
        out[i] = s;
    }
    if (f->L_u > 1)
        for (int i = 0; i < N; i++) {
            double s = 0.0;
            for (int j = 0; j < (f->L_u - 1) * N; j++) s += e->phi[i * w + k + N + j] * e->du_hist[j];
            out[i] = out[i] + s;
        }
}

void ffdl_input_block(const ffdl_est* e, const ffdl_params* f, double* m) {
    int w = width(f), k = f->L_y * N;
    for (int i = 0; i < N; i++)
        for (int j = 0; j < N; j++) m[i * N + j] = e->phi[i * w + k + j];
}
