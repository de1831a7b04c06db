/*
 * emu_gpc.c: online law of EmuGpc3, the C twin of controllers/datadriven/laws.py GpcLaw over
 * controllers/common/gpc.py Gpc behind emu_control.py EmuGpc (seed-001 GPC baseline): RLS
 * with forgetting f on the incremental ARX model dy(t) = sum A_i dy(t-i) + sum B_j du(t-j)
 * (one covariance P, its trace capped at p_max), and per sample the first move of
 *
 *   dU = (G'G + w I)^-1 G'(R - f)
 *
 * (free response f and step-response matrix G over Ny samples, Nu moves, by simulating the
 * model as Gpc._simulate), references R extrapolated linearly from y_r(t), y_r(t+1) and
 * clipped at 0; optional null-space force sharing on B_1 (truncated inverse of
 * ato_linalg.h with SHARE_INVERSE's eps and cutoff); u clipped to the input box. The core's
 * scalar operations in its order; products summed in index order and the solve by Gaussian
 * elimination, where numpy calls BLAS and LAPACK: see tests/test_native_datadriven.py.
 * State: the drive's (ato_datadriven.h), then Gpc.state_fields: theta (n x n_reg, row-major),
 * P (n_reg x n_reg), y_prev (n), dy_hist (na x n), du_hist (nb x n), u_prev (n), started,
 * updates; then GpcLaw's u (n).
 */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "ato_datadriven.h"
#include "ato_linalg.h"

#define N DD_N

struct law_core {
    dd_drive drive;
    int Ny, Nu, na, nb, nreg;
    double forgetting, weight, b_init, a_init, p0, p_max, excitation, share;
    int count;
    double* st;
    double *theta, *P, *y_prev, *dy_hist, *du_hist, *u_prev, *started, *updates, *u;
    /* scratch */
    double *G, *H, *f, *g, *rhs, *sim_dy, *sim_du, *moves, *Px, *Pn;
};

static double npmax(double a, double b) { return isnan(a) || isnan(b) ? a + b : (b > a ? b : a); }

law_core* law_make(const ato_values* p, double t0, char* err, size_t n) {
    (void)t0;
    const double* v = p->v;
    int Ny = (int)v[ATO_VR_Ny], Nu = (int)v[ATO_VR_Nu];
    if (Nu > Ny) { /* GpcParams.check_relations */
        snprintf(err, n, "Nu = %d must be <= Ny = %d", Nu, Ny);
        return NULL;
    }
    law_core* c = calloc(1, sizeof *c);
    if (!dd_drive_make(&c->drive, p, err, n)) {
        free(c);
        return NULL;
    }
    c->Ny = Ny;
    c->Nu = Nu;
    c->na = (int)v[ATO_VR_na];
    c->nb = (int)v[ATO_VR_nb];
    c->nreg = N * c->na + N * c->nb;
    c->forgetting = v[ATO_VR_forgetting];
    c->weight = v[ATO_VR_control_weight];
    c->b_init = v[ATO_VR_b_init];
    c->a_init = v[ATO_VR_a_init];
    c->p0 = v[ATO_VR_p0];
    c->p_max = v[ATO_VR_p_max];
    c->excitation = v[ATO_VR_excitation];
    c->share = v[ATO_VR_share_gain];
    int nr = c->nreg;
    c->count = DD_DRIVE_STATE + N * nr + nr * nr + N + c->na * N + c->nb * N + N + 2 + N;
    c->st = calloc(c->count, sizeof(double));
    double* at = c->st + DD_DRIVE_STATE;
    c->theta = at; at += N * nr;
    c->P = at; at += nr * nr;
    c->y_prev = at; at += N;
    c->dy_hist = at; at += c->na * N;
    c->du_hist = at; at += c->nb * N;
    c->u_prev = at; at += N;
    c->started = at++;
    c->updates = at++;
    c->u = at;
    for (int i = 0; i < N; i++)
        for (int j = 0; j < N; j++) {
            c->theta[i * nr + j] = c->a_init * (i == j ? 1.0 : 0.0);
            c->theta[i * nr + N * c->na + j] = c->b_init * (i == j ? 1.0 : 0.0);
        }
    for (int i = 0; i < nr; i++)
        for (int j = 0; j < nr; j++) c->P[i * nr + j] = c->p0 * (i == j ? 1.0 : 0.0);
    int rows = Ny * N, cols = Nu * N;
    c->G = malloc(sizeof(double) * rows * cols);
    c->H = malloc(sizeof(double) * cols * cols);
    c->f = malloc(sizeof(double) * rows);
    c->g = malloc(sizeof(double) * rows);
    c->rhs = malloc(sizeof(double) * cols);
    c->sim_dy = malloc(sizeof(double) * c->na * N);
    c->sim_du = malloc(sizeof(double) * c->nb * N);
    c->moves = calloc(Ny * N, sizeof(double));
    c->Px = malloc(sizeof(double) * nr);
    c->Pn = malloc(sizeof(double) * nr * nr);
    return c;
}

void law_free(law_core* c) {
    dd_drive_free(&c->drive);
    free(c->st); free(c->G); free(c->H); free(c->f); free(c->g); free(c->rhs);
    free(c->sim_dy); free(c->sim_du); free(c->moves); free(c->Px); free(c->Pn);
    free(c);
}
DD_LAW_FLAT_STATE

/* Gpc.observe */
static void observe(law_core* c, const double* y, int adapt) {
    if (*c->started == 0.0) {
        memcpy(c->y_prev, y, sizeof(double) * N);
        *c->started = 1.0;
        return;
    }
    int nr = c->nreg;
    double dy[N], x[ATO_LINALG_MAX * 2], tx[N];
    for (int i = 0; i < N; i++) dy[i] = y[i] - c->y_prev[i];
    memcpy(c->y_prev, y, sizeof dy);
    memcpy(x, c->dy_hist, sizeof(double) * c->na * N); /* dy(t-1)..., du(t-1)... */
    memcpy(x + c->na * N, c->du_hist, sizeof(double) * c->nb * N);
    double xx = 0.0;
    for (int j = 0; j < nr; j++) xx += x[j] * x[j];
    if (adapt && sqrt(xx) > c->excitation) {
        double f = c->forgetting, xPx = 0.0, k[ATO_LINALG_MAX * 2];
        ato_matvec(c->P, nr, nr, x, c->Px);
        for (int j = 0; j < nr; j++) xPx += x[j] * c->Px[j];
        for (int j = 0; j < nr; j++) k[j] = c->Px[j] / (f + xPx);
        ato_matvec(c->theta, N, nr, x, tx);
        for (int i = 0; i < N; i++) {
            double innov = dy[i] - tx[i];
            for (int j = 0; j < nr; j++) c->theta[i * nr + j] = c->theta[i * nr + j] + innov * k[j];
        }
        for (int i = 0; i < nr; i++)
            for (int j = 0; j < nr; j++)
                c->Pn[i * nr + j] = (c->P[i * nr + j] - k[i] * c->Px[j]) / f;
        double trace = 0.0;
        for (int i = 0; i < nr; i++)
            for (int j = 0; j < nr; j++)
                c->P[i * nr + j] = 0.5 * (c->Pn[i * nr + j] + c->Pn[j * nr + i]);
        for (int i = 0; i < nr; i++) trace += c->P[i * nr + i];
        if (trace > c->p_max) {
            double scale = c->p_max / trace;
            for (int i = 0; i < nr * nr; i++) c->P[i] *= scale;
        }
        *c->updates += 1.0;
    }
    memmove(c->dy_hist + N, c->dy_hist, sizeof(double) * (c->na - 1) * N);
    memcpy(c->dy_hist, dy, sizeof dy);
}

/* Gpc._simulate: y(t+1..t+Ny) into out (Ny x n) for the moves (Ny x n) */
static void simulate(law_core* c, const double* moves, double* out) {
    int nr = c->nreg, ka = N * c->na;
    double y[N], dy[N];
    memcpy(c->sim_dy, c->dy_hist, sizeof(double) * c->na * N);
    memcpy(c->sim_du, c->du_hist, sizeof(double) * c->nb * N);
    memcpy(y, c->y_prev, sizeof y);
    for (int j = 0; j < c->Ny; j++) {
        memmove(c->sim_du + N, c->sim_du, sizeof(double) * (c->nb - 1) * N);
        memcpy(c->sim_du, moves + j * N, sizeof(double) * N);
        for (int i = 0; i < N; i++) {
            double a = 0.0, b = 0.0;
            for (int q = 0; q < ka; q++) a += c->theta[i * nr + q] * c->sim_dy[q];
            for (int q = 0; q < N * c->nb; q++) b += c->theta[i * nr + ka + q] * c->sim_du[q];
            dy[i] = a + b;
        }
        memmove(c->sim_dy + N, c->sim_dy, sizeof(double) * (c->na - 1) * N);
        memcpy(c->sim_dy, dy, sizeof dy);
        for (int i = 0; i < N; i++) {
            y[i] = y[i] + dy[i];
            out[j * N + i] = y[i];
        }
    }
}

/* GpcLaw.hold / Gpc.applied */
static void applied(law_core* c, const double* u) {
    memmove(c->du_hist + N, c->du_hist, sizeof(double) * (c->nb - 1) * N);
    for (int i = 0; i < N; i++) c->du_hist[i] = u[i] - c->u_prev[i];
    memcpy(c->u_prev, u, sizeof(double) * N);
}

int law_compute(law_core* c, double t, const ato_values* p, double* out, char* err, size_t n) {
    dd_sample smp;
    dd_sample_inputs(&c->drive, t, p->v, &smp);
    if (smp.holding) {
        observe(c, smp.y, 0);
        applied(c, smp.hold);
        memcpy(c->u, smp.hold, sizeof(double) * N);
    } else {
        observe(c, smp.y, 1);
        int rows = c->Ny * N, cols = c->Nu * N;
        /* Gpc.prediction_matrices and plan */
        memset(c->moves, 0, sizeof(double) * rows);
        simulate(c, c->moves, c->f);
        for (int k = 0; k < c->Nu; k++)
            for (int j = 0; j < N; j++) {
                c->moves[k * N + j] = 1.0;
                simulate(c, c->moves, c->g);
                c->moves[k * N + j] = 0.0;
                for (int r = 0; r < rows; r++) c->G[r * cols + k * N + j] = c->g[r] - c->f[r];
            }
        for (int r = 0; r < rows; r++) { /* R - f, R = max(y_r + j (y_r(t+1) - y_r), 0) */
            double ref = npmax(smp.y_r + (double)(r / N + 1) * (smp.y_r_next - smp.y_r), 0.0);
            c->g[r] = ref * 1.0 - c->f[r];
        }
        for (int i = 0; i < cols; i++) {
            for (int j = 0; j < cols; j++) {
                double s = 0.0;
                for (int r = 0; r < rows; r++) s += c->G[r * cols + i] * c->G[r * cols + j];
                c->H[i * cols + j] = s + c->weight * (i == j ? 1.0 : 0.0);
            }
            double s = 0.0;
            for (int r = 0; r < rows; r++) s += c->G[r * cols + i] * c->g[r];
            c->rhs[i] = s;
        }
        if (!ato_solve(c->H, c->rhs, cols, c->rhs)) {
            snprintf(err, n, "GPC: G'G + w I is singular (Singular matrix)");
            return 0;
        }
        double u[N];
        for (int i = 0; i < N; i++) u[i] = c->u_prev[i] + c->rhs[i];
        if (c->share > 0) {
            double M[N * N], Mr[N * N], K[N * N], sh[N];
            int kept, ka = N * c->na;
            for (int i = 0; i < N; i++)
                for (int j = 0; j < N; j++) M[i * N + j] = c->theta[i * c->nreg + ka + j];
            ato_truncated_gain(M, N, DD_SHARE_EPS, DD_SHARE_CUTOFF, Mr, K, &kept);
            ato_null_space_share(c->u, Mr, K, N, c->share, sh);
            for (int i = 0; i < N; i++) u[i] = u[i] - sh[i];
        }
        for (int i = 0; i < N; i++) c->u[i] = ato_npclip(u[i], smp.lo[i], smp.hi[i]);
        applied(c, c->u);
    }
    dd_commit(&smp, c->u, c->st);
    dd_outputs(c->st, out);
    return 1;
}
