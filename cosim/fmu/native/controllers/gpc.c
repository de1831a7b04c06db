/* gpc.c: the GPC of controllers/common/gpc.py (see gpc.h). */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "gpc.h"
#include "linalg.h"

int gpc_check(const gpc_params* p, char* err, size_t err_size) {
    if (p->Nu <= p->Ny) return 1;
    snprintf(err, err_size, "Nu = %d must be <= Ny = %d", p->Nu, p->Ny);
    return 0;
}

int gpc_state_count(const gpc_params* p) {
    int nreg = p->n * p->na + p->m * p->nb;
    return p->n * nreg + nreg * nreg + p->n + p->na * p->n + p->nb * p->m + p->m + 2;
}

static double* doubles(int count) { return calloc(count > 0 ? count : 1, sizeof(double)); }

void gpc_make(gpc_core* g, const gpc_params* p, double* st) {
    memset(g, 0, sizeof *g);
    g->p = *p;
    int n = p->n, m = p->m, nr = n * p->na + m * p->nb;
    g->nreg = nr;
    double* at = st;
    g->theta = at; at += n * nr;
    g->P = at; at += nr * nr;
    g->y_prev = at; at += n;
    g->dy_hist = at; at += p->na * n;
    g->du_hist = at; at += p->nb * m;
    g->u_prev = at; at += m;
    g->started = at++;
    g->updates = at;
    memset(st, 0, sizeof(double) * gpc_state_count(p));
    for (int i = 0; i < n; i++) {
        for (int j = 0; j < n; j++) g->theta[i * nr + j] = p->a_init * (i == j ? 1.0 : 0.0);
        for (int j = 0; j < m; j++)
            g->theta[i * nr + n * p->na + j] = p->b_init * (i == j ? 1.0 : 0.0);
    }
    for (int i = 0; i < nr; i++)
        for (int j = 0; j < nr; j++) g->P[i * nr + j] = p->p0 * (i == j ? 1.0 : 0.0);
    int rows = p->Ny * n, cols = p->Nu * m;
    g->G = doubles(rows * cols);
    g->H = doubles(cols * cols);
    g->f = doubles(rows);
    g->g = doubles(rows);
    g->refs = doubles(rows);
    g->sim_dy = doubles(p->na * n);
    g->sim_du = doubles(p->nb * m);
    g->moves = doubles(p->Ny * m);
    g->Px = doubles(nr);
    g->Pn = doubles(nr * nr);
    g->x = doubles(nr);
    g->k = doubles(nr);
    g->dy = doubles(n);
    g->tx = doubles(n);
    g->y = doubles(n);
}

void gpc_free(gpc_core* g) {
    double* scratch[] = {g->G, g->H, g->f, g->g, g->refs, g->sim_dy, g->sim_du, g->moves,
                         g->Px, g->Pn, g->x, g->k, g->dy, g->tx, g->y};
    for (size_t i = 0; i < sizeof scratch / sizeof scratch[0]; i++) free(scratch[i]);
}

void gpc_observe(gpc_core* g, const double* y, int adapt) {
    int n = g->p.n;
    if (*g->started == 0.0) {
        memcpy(g->y_prev, y, sizeof(double) * n);
        *g->started = 1.0;
        return;
    }
    int nr = g->nreg;
    double *dy = g->dy, *x = g->x, *k = g->k;
    for (int i = 0; i < n; i++) dy[i] = y[i] - g->y_prev[i];
    memcpy(g->y_prev, y, sizeof(double) * n);
    memcpy(x, g->dy_hist, sizeof(double) * g->p.na * n); /* dy(t-1)..., du(t-1)... */
    memcpy(x + g->p.na * n, g->du_hist, sizeof(double) * g->p.nb * g->p.m);
    double xx = 0.0;
    for (int j = 0; j < nr; j++) xx += x[j] * x[j];
    if (adapt && sqrt(xx) > g->p.excitation) {
        double f = g->p.forgetting, xPx = 0.0;
        ato_matvec(g->P, nr, nr, x, g->Px);
        for (int j = 0; j < nr; j++) xPx += x[j] * g->Px[j];
        for (int j = 0; j < nr; j++) k[j] = g->Px[j] / (f + xPx);
        ato_matvec(g->theta, n, nr, x, g->tx);
        for (int i = 0; i < n; i++) {
            double innov = dy[i] - g->tx[i];
            for (int j = 0; j < nr; j++) g->theta[i * nr + j] = g->theta[i * nr + j] + innov * k[j];
        }
        for (int i = 0; i < nr; i++)
            for (int j = 0; j < nr; j++)
                g->Pn[i * nr + j] = (g->P[i * nr + j] - k[i] * g->Px[j]) / f;
        double trace = 0.0;
        for (int i = 0; i < nr; i++)
            for (int j = 0; j < nr; j++)
                g->P[i * nr + j] = 0.5 * (g->Pn[i * nr + j] + g->Pn[j * nr + i]);
        for (int i = 0; i < nr; i++) trace += g->P[i * nr + i];
        if (trace > g->p.p_max) {
            double scale = g->p.p_max / trace;
            for (int i = 0; i < nr * nr; i++) g->P[i] *= scale;
        }
        *g->updates += 1.0;
    }
    memmove(g->dy_hist + n, g->dy_hist, sizeof(double) * (g->p.na - 1) * n);
    memcpy(g->dy_hist, dy, sizeof(double) * n);
}

/* Gpc._simulate: y(t+1..t+Ny) into out (Ny x n) for the moves (Ny x m) */
static void simulate(gpc_core* g, const double* moves, double* out) {
    int n = g->p.n, m = g->p.m, nr = g->nreg, ka = n * g->p.na;
    double *y = g->y, *dy = g->dy;
    memcpy(g->sim_dy, g->dy_hist, sizeof(double) * g->p.na * n);
    memcpy(g->sim_du, g->du_hist, sizeof(double) * g->p.nb * m);
    memcpy(y, g->y_prev, sizeof(double) * n);
    for (int j = 0; j < g->p.Ny; j++) {
        memmove(g->sim_du + m, g->sim_du, sizeof(double) * (g->p.nb - 1) * m);
        memcpy(g->sim_du, moves + j * m, sizeof(double) * m);
        for (int i = 0; i < n; i++) {
            double a = 0.0, b = 0.0;
            for (int q = 0; q < ka; q++) a += g->theta[i * nr + q] * g->sim_dy[q];
            for (int q = 0; q < m * g->p.nb; q++) b += g->theta[i * nr + ka + q] * g->sim_du[q];
            dy[i] = a + b;
        }
        memmove(g->sim_dy + n, g->sim_dy, sizeof(double) * (g->p.na - 1) * n);
        memcpy(g->sim_dy, dy, sizeof(double) * n);
        for (int i = 0; i < n; i++) {
            y[i] = y[i] + dy[i];
            out[j * n + i] = y[i];
        }
    }
}

int gpc_plan(gpc_core* g, const double* refs, double* u) {
    int m = g->p.m, rows = g->p.Ny * g->p.n, cols = g->p.Nu * m;
    /* Gpc.prediction_matrices */
    memset(g->moves, 0, sizeof(double) * g->p.Ny * m);
    simulate(g, g->moves, g->f);
    for (int k = 0; k < g->p.Nu; k++)
        for (int j = 0; j < m; j++) {
            g->moves[k * m + j] = 1.0;
            simulate(g, g->moves, g->g);
            g->moves[k * m + j] = 0.0;
            for (int r = 0; r < rows; r++) g->G[r * cols + k * m + j] = g->g[r] - g->f[r];
        }
    for (int r = 0; r < rows; r++) g->g[r] = refs[r] - g->f[r]; /* R - f */
    double* rhs = g->moves; /* G'(R - f), then dU */
    for (int i = 0; i < cols; i++) {
        for (int j = 0; j < cols; j++) {
            double s = 0.0;
            for (int r = 0; r < rows; r++) s += g->G[r * cols + i] * g->G[r * cols + j];
            g->H[i * cols + j] = s + g->p.weight * (i == j ? 1.0 : 0.0);
        }
        double s = 0.0;
        for (int r = 0; r < rows; r++) s += g->G[r * cols + i] * g->g[r];
        rhs[i] = s;
    }
    if (!ato_solve(g->H, rhs, cols, rhs)) return 0;
    for (int i = 0; i < m; i++) u[i] = g->u_prev[i] + rhs[i];
    return 1;
}

void gpc_applied(gpc_core* g, const double* u) {
    int m = g->p.m;
    memmove(g->du_hist + m, g->du_hist, sizeof(double) * (g->p.nb - 1) * m);
    for (int i = 0; i < m; i++) g->du_hist[i] = u[i] - g->u_prev[i];
    memcpy(g->u_prev, u, sizeof(double) * m);
}
