/*
 * stop_mpc.c: online law of StopMpc, StopRmpc and StopRsmpc, the C twin of
 * controllers/mpc/stop_mpc.py (seed 000: ideal MPC, tube robust MPC, robust self-triggered
 * MPC for accurate stopping) with the condensed horizon QP of controllers/common/qp.py
 * (HorizonQP) solved by DAQP (its C sources from the registry's sdist, built into the FMU).
 *
 * Built here from the parameters, as the core builds them: the design model of eq. (9)
 * (exact ZOH of the lag -> v -> s chain by the matrix exponential of the block [[A, B], [0,
 * 0]] T, scaling and squaring of its Taylor series; or the paper's Euler rows), P of the DARE
 * (structure-preserving doubling), the tube feedback K and A_cl, the disturbance set W from
 * the route's grades (resources/routes/<route>.grade) and the Davis and mass spreads, the
 * tightened stage constraints (support functions of R_i^M, eq. 14 / 26), each hold's
 * condensed QP (Phi, Gamma, Psi, the Hessian, the constraint rows) and at every event its
 * vectors, the reference, the delay prediction, the resistance fed forward along the previous
 * plan, the observer and the standstill hold. The one piece of offline design taken from the
 * core is the tube controllers' terminal set (the maximal robust positively invariant set,
 * eq. 16-18, found by LPs): the generated header ato_stop_mpc_sets.h carries the sets the core
 * computes for the designs of the seed 000 scenarios and reproduction runs, each with the
 * data it was computed from (A_cl, the constraint rows C e <= h, the vertices of W); a design
 * whose data match none of them (to 1e-8 of their scale) is refused with a message.
 *
 * The model header defines ATO_STOP_MPC_KIND: 0 ideal (resistance fed forward, no tube),
 * 1 tube (RMPC), 2 self-triggered (RSMPC: the hold M is announced as the next event).
 */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "api.h" /* DAQP */
#include "utils.h" /* DAQP: daqp_update_ldp */
#include "grade.h"
#include "law_common.h"
#include "linalg.h"
#include "ato_model.h"
#include "ato_stop_mpc_sets.h"
#include "vars.h"

#define NX 4
#define A_C 0
#define U_PREV 1
#define V 2
#define S 3
#define GRAVITY 9.81           /* plants.route.GRAVITY */
#define NO_BOUND 1e30          /* a terminal row's lower bound (DAQP's infinity) */
#define MAX_ITER 10000         /* HorizonQP's iteration limit */
#define DAQP_OPTIMAL 1

#if ATO_STOP_MPC_KIND == 0
#define FEEDFORWARD 1
#define TUBE 0
#else
#define FEEDFORWARD 0
#define TUBE 1
#endif
#define SELF_TRIGGERED (ATO_STOP_MPC_KIND == 2)

/* ---- small dense algebra (row-major) -------------------------------------------------- */

static void matmul(const double* a, const double* b, int n, int k, int m, double* out) {
    for (int i = 0; i < n; i++)
        for (int j = 0; j < m; j++) {
            double acc = 0.0;
            for (int l = 0; l < k; l++) acc += a[i * k + l] * b[l * m + j];
            out[i * m + j] = acc;
        }
}

/* b = a^-1 b for the n x n matrix a (n <= 4) and the n x m matrix b, column by column
 * (ato_solve: Gaussian elimination with partial pivoting); 0 when a is singular */
static int solve_many(const double* a, double* b, int n, int m) {
    double a_copy[16], col[4];
    for (int j = 0; j < m; j++) {
        memcpy(a_copy, a, sizeof(double) * n * n);
        for (int i = 0; i < n; i++) col[i] = b[i * m + j];
        if (!ato_solve(a_copy, col, n, col)) return 0;
        for (int i = 0; i < n; i++) b[i * m + j] = col[i];
    }
    return 1;
}

/* e^M of the 5 x 5 matrix m: Taylor series of M / 2^s (||M / 2^s||_1 <= 1/4, 24 terms) squared
 * s times */
#define NE 5
static void expm5(const double* m, double* out) {
    double norm = 0.0;
    for (int j = 0; j < NE; j++) {
        double col = 0.0;
        for (int i = 0; i < NE; i++) col += fabs(m[i * NE + j]);
        norm = ato_max(norm, col);
    }
    int s = 0;
    while (norm > 0.25) { norm /= 2.0; s++; }
    double a[NE * NE], term[NE * NE], tmp[NE * NE];
    double scale = ldexp(1.0, -s);
    for (int i = 0; i < NE * NE; i++) a[i] = m[i] * scale;
    for (int i = 0; i < NE * NE; i++) out[i] = term[i] = (i % (NE + 1) == 0) ? 1.0 : 0.0;
    for (int k = 1; k <= 24; k++) {
        matmul(term, a, NE, NE, NE, tmp);
        for (int i = 0; i < NE * NE; i++) { term[i] = tmp[i] / k; out[i] += term[i]; }
    }
    for (int k = 0; k < s; k++) {
        matmul(out, out, NE, NE, NE, tmp);
        memcpy(out, tmp, sizeof tmp);
    }
}

/* ---- the QP of one hold (controllers/common/qp.py HorizonQP) -------------------------- */

typedef struct {
    int H, nu, rows, n_con;
    int* free_stage;      /* nu */
    double* Phi;          /* (H+1) x 4 x 4 */
    double* Gam;          /* (H+1) x 4 x nu */
    double* Psi;          /* (H+1) x 4 x H */
    double* Qs;           /* (H+1) x 4 x 4 */
    double* Hhalf;        /* nu x nu */
    double* Hd;           /* 2 Hhalf (DAQP's H) */
    double* Acon;         /* rows x nu (below the du box) */
    double* Mq;           /* nu x (H+1) 4 */
    int* row_stage;       /* rows */
    double* row_f;        /* rows x 4 */
    double* row_mask;     /* rows */
    double *lo_all, *hi_all; /* n_con */
    /* DAQP */
    DAQPWorkspace* work;
    DAQPProblem prob;
    double *f, *bu, *bl, *x, *lam;
    int* sense;
} horizon_qp;

typedef struct {
    int feasible;
    double cost;
    double* U;   /* nu (the QP's buffer) */
    double du[256];
    int H;
} qp_result;

static void qp_free(horizon_qp* q) {
    if (!q) return;
    if (q->work) {
        free_daqp_workspace(q->work);
        free_daqp_ldp(q->work);
        free(q->work);
    }
    free(q->free_stage); free(q->Phi); free(q->Gam); free(q->Psi); free(q->Qs);
    free(q->Hhalf); free(q->Hd); free(q->Acon); free(q->Mq); free(q->row_stage);
    free(q->row_f); free(q->row_mask); free(q->lo_all); free(q->hi_all); free(q->f);
    free(q->bu); free(q->bl); free(q->x); free(q->lam); free(q->sense);
    free(q);
}

/* the horizon QP: model (A, b, g), H stages, free stages, stage scale, Q, R, P; stage rows F
 * (nf x 4, ref mask) with bounds lo/hi per stage 1..H (nf each), terminal rows (nt x 4, may be
 * 0) with lo_term/hi_term, du box */
static horizon_qp* qp_make(const double* A, const double* b, const double* g, int H,
                           const int* free_stage, int nu, const double* scale, const double* Q,
                           double R, const double* P, const double* F, const double* mask,
                           int nf, const double* lo, const double* hi, const double* Ft,
                           int nt, const double* lo_t, const double* hi_t, double du_min,
                           double du_max) {
    horizon_qp* q = calloc(1, sizeof *q);
    q->H = H; q->nu = nu;
    q->rows = nf * H + nt;
    q->n_con = nu + q->rows;
    int N1 = (H + 1) * NX;
    q->free_stage = malloc(sizeof(int) * nu);
    memcpy(q->free_stage, free_stage, sizeof(int) * nu);
    q->Phi = calloc((size_t)(H + 1) * 16, sizeof(double));
    q->Gam = calloc((size_t)(H + 1) * NX * nu, sizeof(double));
    q->Psi = calloc((size_t)(H + 1) * NX * H, sizeof(double));
    q->Qs = calloc((size_t)(H + 1) * 16, sizeof(double));
    /* E[i][j] = 1 when free_stage[j] == i */
    for (int i = 0; i < NX; i++) q->Phi[i * NX + i] = 1.0;
    for (int i = 0; i < H; i++) {
        double* Pn = q->Phi + (i + 1) * 16;
        matmul(A, q->Phi + i * 16, NX, NX, NX, Pn);
        double* Gn = q->Gam + (size_t)(i + 1) * NX * nu;
        matmul(A, q->Gam + (size_t)i * NX * nu, NX, NX, nu, Gn);
        for (int j = 0; j < nu; j++)
            if (free_stage[j] == i)
                for (int r = 0; r < NX; r++) Gn[r * nu + j] += b[r];
        double* Sn = q->Psi + (size_t)(i + 1) * NX * H;
        matmul(A, q->Psi + (size_t)i * NX * H, NX, NX, H, Sn);
        for (int r = 0; r < NX; r++) Sn[r * H + i] += g[r];
    }
    for (int i = 0; i <= H; i++)
        for (int k = 0; k < 16; k++) q->Qs[i * 16 + k] = i < H ? scale[i] * Q[k] : P[k];
    /* Hq = sum_i Gam_i' Qs_i Gam_i + E' diag(scale R) E */
    double* Hq = calloc((size_t)nu * nu, sizeof(double));
    double* QG = malloc(sizeof(double) * NX * nu);
    q->Mq = calloc((size_t)nu * N1, sizeof(double));
    for (int i = 0; i <= H; i++) {
        const double* G = q->Gam + (size_t)i * NX * nu;
        matmul(q->Qs + i * 16, G, NX, NX, nu, QG);
        for (int a = 0; a < nu; a++) {
            for (int c = 0; c < nu; c++) {
                double acc = 0.0;
                for (int r = 0; r < NX; r++) acc += G[r * nu + a] * QG[r * nu + c];
                Hq[a * nu + c] += acc;
            }
            for (int r = 0; r < NX; r++) /* Mq = 2 [Gam_i' Qs_i] (Qs symmetric) */
                q->Mq[(size_t)a * N1 + i * NX + r] = 2.0 * QG[r * nu + a];
        }
    }
    for (int j = 0; j < nu; j++) Hq[j * nu + j] += scale[free_stage[j]] * R;
    q->Hhalf = malloc(sizeof(double) * nu * nu);
    q->Hd = malloc(sizeof(double) * nu * nu);
    for (int a = 0; a < nu; a++)
        for (int c = 0; c < nu; c++) {
            q->Hhalf[a * nu + c] = 0.5 * (Hq[a * nu + c] + Hq[c * nu + a]);
            q->Hd[a * nu + c] = 2.0 * q->Hhalf[a * nu + c];
        }
    free(Hq); free(QG);
    /* constraint rows: stage rows F Gam_i (i = 1..H), terminal rows Ft Gam_H */
    q->Acon = calloc((size_t)q->rows * nu + 1, sizeof(double));
    q->row_stage = malloc(sizeof(int) * (q->rows + 1));
    q->row_f = malloc(sizeof(double) * NX * (q->rows + 1));
    q->row_mask = malloc(sizeof(double) * (q->rows + 1));
    q->lo_all = malloc(sizeof(double) * q->n_con);
    q->hi_all = malloc(sizeof(double) * q->n_con);
    for (int j = 0; j < nu; j++) { q->lo_all[j] = du_min; q->hi_all[j] = du_max; }
    int row = 0;
    for (int i = 1; i <= H + (nt > 0); i++) {
        int terminal = i == H + 1;
        int stage = terminal ? H : i;
        const double* FF = terminal ? Ft : F;
        int nr = terminal ? nt : nf;
        const double* G = q->Gam + (size_t)stage * NX * nu;
        for (int r = 0; r < nr; r++, row++) {
            q->row_stage[row] = stage;
            memcpy(q->row_f + row * NX, FF + r * NX, sizeof(double) * NX);
            q->row_mask[row] = terminal ? 1.0 : mask[r];
            for (int j = 0; j < nu; j++) {
                double acc = 0.0;
                for (int k = 0; k < NX; k++) acc += FF[r * NX + k] * G[k * nu + j];
                q->Acon[(size_t)row * nu + j] = acc;
            }
            q->lo_all[nu + row] = terminal ? lo_t[r] : lo[(i - 1) * nf + r];
            q->hi_all[nu + row] = terminal ? hi_t[r] : hi[(i - 1) * nf + r];
        }
    }
    /* DAQP set up once (H factorised), as HorizonQP._setup_solver */
    q->f = calloc(nu, sizeof(double));
    q->bu = malloc(sizeof(double) * q->n_con);
    q->bl = malloc(sizeof(double) * q->n_con);
    q->x = calloc(nu, sizeof(double));
    q->lam = calloc(q->n_con, sizeof(double));
    q->sense = calloc(q->n_con, sizeof(int));
    for (int j = 0; j < q->n_con; j++) { q->bu[j] = 1.0; q->bl[j] = -1.0; }
    q->work = calloc(1, sizeof(DAQPWorkspace));
    allocate_daqp_settings(q->work);
    q->prob = (DAQPProblem){nu, q->n_con, nu, q->Hd, q->f, q->Acon, q->bu, q->bl, q->sense,
                            NULL, 0, 0};
    double setup_time = 0.0;
    int flag = setup_daqp_main(&q->prob, q->work, &setup_time, 0);
    if (flag < 0) {
        if (q->work->settings == NULL) allocate_daqp_settings(q->work);
        qp_free(q);
        return NULL;
    }
    q->work->settings->iter_limit = MAX_ITER;
    return q;
}

/* HorizonQP.solve: x0, ref ((H+1) x 4), d (H or NULL), warm dual (n_con or NULL) */
static void qp_solve(horizon_qp* q, const double* x0, const double* ref, const double* d,
                     const double* warm, qp_result* res, double* err_e, double* qv) {
    int H = q->H, nu = q->nu, N1 = (H + 1) * NX;
    double* xf = err_e; /* the free response first, then e = xf - ref */
    for (int i = 0; i <= H; i++)
        for (int r = 0; r < NX; r++) {
            double acc = 0.0;
            for (int k = 0; k < NX; k++) acc += q->Phi[i * 16 + r * NX + k] * x0[k];
            if (d)
                for (int k = 0; k < H; k++) acc += q->Psi[(size_t)i * NX * H + r * H + k] * d[k];
            xf[i * NX + r] = acc;
        }
    for (int row = 0; row < q->rows; row++) {
        int i = q->row_stage[row];
        double fx = 0.0, fr = 0.0;
        for (int k = 0; k < NX; k++) {
            fx += q->row_f[row * NX + k] * xf[i * NX + k];
            fr += q->row_mask[row] * q->row_f[row * NX + k] * ref[i * NX + k];
        }
        double base = fx - fr;
        q->bl[nu + row] = q->lo_all[nu + row] - base;
        q->bu[nu + row] = q->hi_all[nu + row] - base;
    }
    for (int j = 0; j < nu; j++) { q->bl[j] = q->lo_all[j]; q->bu[j] = q->hi_all[j]; }
    for (int k = 0; k < N1; k++) err_e[k] = xf[k] - ref[k];
    for (int j = 0; j < nu; j++) {
        double acc = 0.0;
        for (int k = 0; k < N1; k++) acc += q->Mq[(size_t)j * N1 + k] * err_e[k];
        qv[j] = acc;
        q->f[j] = acc;
    }
    res->feasible = 0;
    res->cost = INFINITY;
    res->H = H;
    res->U = q->x;
    double gap = INFINITY;
    for (int j = 0; j < q->n_con; j++) gap = ato_min(gap, q->bu[j] - q->bl[j]);
    if (gap < -1e-12) { memset(q->lam, 0, sizeof(double) * q->n_con); return; }
    for (int j = 0; j < q->n_con; j++) q->bu[j] = ato_max(q->bl[j], q->bu[j]);
    /* hot start from the active set of the warm dual (its sign), cold when that fails */
    int warm_start = warm != NULL;
    for (;;) {
        for (int j = 0; j < q->n_con; j++)
            q->sense[j] = warm_start ? (warm[j] > 0.0 ? 1 : warm[j] < 0.0 ? 3 : 0) : 0;
        daqp_update_ldp(DAQP_UPDATE_v | DAQP_UPDATE_d | DAQP_UPDATE_sense, q->work, &q->prob);
        DAQPResult r = {q->x, q->lam, 0, 0, 0, 0, 0, 0, 0};
        daqp_solve(&r, q->work);
        if (r.exitflag == DAQP_OPTIMAL || !warm_start) {
            int finite = 1;
            for (int j = 0; j < nu; j++) finite &= isfinite(q->x[j]);
            res->feasible = r.exitflag == DAQP_OPTIMAL && finite;
            break;
        }
        warm_start = 0;
    }
    if (!res->feasible) { memset(q->lam, 0, sizeof(double) * q->n_con); return; }
    for (int i = 0; i < H; i++) res->du[i] = 0.0;
    for (int j = 0; j < nu; j++) res->du[q->free_stage[j]] = q->x[j];
    /* J = U' Hhalf U + q' U + e' Qblk e */
    double uhu = 0.0, qu = 0.0, eqe = 0.0;
    for (int a = 0; a < nu; a++) {
        double acc = 0.0;
        for (int c = 0; c < nu; c++) acc += q->Hhalf[a * nu + c] * q->x[c];
        uhu += q->x[a] * acc;
        qu += qv[a] * q->x[a];
    }
    for (int i = 0; i <= H; i++)
        for (int r = 0; r < NX; r++) {
            double acc = 0.0;
            for (int k = 0; k < NX; k++) acc += q->Qs[i * 16 + r * NX + k] * err_e[i * NX + k];
            eqe += err_e[i * NX + r] * acc;
        }
    res->cost = uhu + qu + eqe;
}

/* ---- the law ------------------------------------------------------------------------------ */

struct law_core {
    /* parameters */
    int N, l, max_hold, known, observer;
    double T, c, a0, stop_point, u_min, u_max, du_max, v_max, se_max, pe_max, mass, da, db,
        dc, beta, L, init_cmd, ss_speed, ss_window, ss_cmd, r_du;
    /* design */
    double A[16], b[4], g[4], Q[16], P[16], K[4], Acl[16], w_vert[8], spread[2];
    double F[16], ref_mask[4], x_lo[4], x_hi[4];
    int nt;
    const double *Ft, *ht;
    ato_grade grade;
    horizon_qp** qps; /* [0]: fallback, [1..max_hold] */
    int Hmax, ncon_total;
    int* warm_off; /* per hold 0..max_hold: offset of its warm dual in the state */
    /* scratch */
    double *ref, *d, *e, *qv, *xs;
    /* state: one block of doubles (offsets below) */
    size_t n_state;
    double* st;
    int o_hist, o_obs_in, o_plan, o_warm_ok, o_warm;
};

/* scalar state slots */
enum { ST_COMMAND, ST_LAST_T, ST_HAS_LAST, ST_ANCHOR_T, ST_ANCHOR_S, ST_HOLD, ST_SOLVES,
       ST_INFEASIBLE, ST_STANDSTILL, ST_LAST_VREF, ST_INF_AFTER, ST_EV_MOVING, ST_EV_STAND,
       ST_D_HAT, ST_HAS_OBS, ST_OBS_X, ST_PLAN_LEN = ST_OBS_X + 4, ST_SCALARS };

static double davis(const law_core* c, double v) { return c->da + (c->db + c->dc * v) * v; }

/* known resistance a_r (m/s^2): Davis + grade + the observer's estimate */
static double resistance(const law_core* c, double v, double s) {
    return davis(c, ato_max(v, 0.0)) / c->mass + ato_grade_accel(&c->grade, s) +
           c->st[ST_D_HAT];
}

static void step_model(const law_core* c, double* x, double du, double a_r) {
    double y[4];
    for (int r = 0; r < NX; r++) {
        double acc = 0.0;
        for (int k = 0; k < NX; k++) acc += c->A[r * NX + k] * x[k];
        y[r] = acc + c->b[r] * du + c->g[r] * a_r;
    }
    memcpy(x, y, sizeof y);
}

static double curve_speed(const law_core* c, double s) {
    return sqrt(2.0 * c->a0 * ato_max(c->stop_point - s, 0.0));
}

/* reference x_s for stages 0..stages at time t (a_r along the stages or NULL) */
static void reference(const law_core* c, double t, int stages, const double* a_r, double* ref) {
    double v0 = curve_speed(c, c->st[ST_ANCHOR_S]);
    for (int i = 0; i <= stages; i++) {
        double elapsed = t - c->st[ST_ANCHOR_T] + (double)(c->l + i) * c->T;
        double v = v0 - c->a0 * elapsed;
        double a_cs = (a_r ? a_r[i] : 0.0) - c->a0;
        ref[i * NX + A_C] = a_cs;
        ref[i * NX + U_PREV] = -a_cs / c->c;
        ref[i * NX + V] = v;
        ref[i * NX + S] = c->stop_point - v * v / (2.0 * c->a0);
    }
}

/* max over W's two vertices w of f' M w */
static double support_term(const law_core* c, const double* M, const double* f) {
    double best = -INFINITY;
    for (int w = 0; w < 2; w++) {
        double acc = 0.0;
        for (int r = 0; r < NX; r++) {
            double mw = 0.0;
            for (int k = 0; k < NX; k++) mw += M[r * NX + k] * c->w_vert[w * NX + k];
            acc += f[r] * mw;
        }
        best = ato_max(best, acc);
    }
    return best;
}

/* support in the direction f of R_i^M = (+)_j M_j W (StopMpc.reach_mats: A^j, j < i, when
 * i <= hold; else A_cl^(i - hold) A^j, j < hold, and A_cl^j, j < i - hold) */
static double support(const law_core* c, int i, int hold, const double* f) {
    double total = 0.0, Ap[16], Ac[16], head[16], tmp[16];
    int n_a = i <= hold ? i : hold, n_cl = i <= hold ? 0 : i - hold;
    memset(head, 0, sizeof head);
    for (int k = 0; k < NX; k++) head[k * NX + k] = 1.0;
    for (int k = 0; k < n_cl; k++) {
        matmul(head, c->Acl, NX, NX, NX, tmp);
        memcpy(head, tmp, sizeof tmp);
    }
    memcpy(Ap, head, sizeof Ap); /* head A^j */
    memset(Ac, 0, sizeof Ac);
    for (int k = 0; k < NX; k++) Ac[k * NX + k] = 1.0;
    for (int j = 0; j < n_a; j++) {
        total += support_term(c, Ap, f);
        matmul(Ap, c->A, NX, NX, NX, tmp); memcpy(Ap, tmp, sizeof tmp);
    }
    for (int j = 0; j < n_cl; j++) { /* A_cl^j */
        total += support_term(c, Ac, f);
        matmul(Ac, c->Acl, NX, NX, NX, tmp); memcpy(Ac, tmp, sizeof tmp);
    }
    return total;
}

static horizon_qp* make_qp(law_core* c, int hold) {
    int N = c->N;
    if (hold == 0) { /* the fallback: horizon N, the command bounds only */
        int H = N, *free_stage = malloc(sizeof(int) * N);
        double *scale = malloc(sizeof(double) * H), *lo = malloc(sizeof(double) * H),
               *hi = malloc(sizeof(double) * H);
        for (int i = 0; i < H; i++) {
            free_stage[i] = i;
            scale[i] = 1.0;
            lo[i] = c->u_min;
            hi[i] = c->u_max;
        }
        double F[4] = {0.0, 1.0, 0.0, 0.0}, mask[1] = {0.0};
        horizon_qp* q = qp_make(c->A, c->b, c->g, H, free_stage, N, scale, c->Q, c->r_du, c->P,
                                F, mask, 1, lo, hi, NULL, 0, NULL, NULL, -c->du_max, c->du_max);
        free(free_stage); free(scale); free(lo); free(hi);
        return q;
    }
    int H = hold + N - 1, nu = N;
    int* free_stage = malloc(sizeof(int) * nu);
    free_stage[0] = 0;
    for (int i = hold, j = 1; i < H; i++, j++) free_stage[j] = i;
    double beta = SELF_TRIGGERED ? c->beta : 1.0;
    double* scale = malloc(sizeof(double) * H);
    for (int i = 0; i < H; i++) scale[i] = i < hold ? 1.0 / beta : 1.0;
    double *lo = malloc(sizeof(double) * H * 4), *hi = malloc(sizeof(double) * H * 4);
    for (int i = 1; i <= H; i++)
        for (int r = 0; r < 4; r++) {
            double dlo = 0.0, dhi = 0.0;
            if (TUBE) {
                double neg[4];
                for (int k = 0; k < NX; k++) neg[k] = -c->F[r * NX + k];
                dlo = support(c, i, hold, neg);
                dhi = support(c, i, hold, c->F + r * NX);
            }
            lo[(i - 1) * 4 + r] = c->x_lo[r] + dlo;
            hi[(i - 1) * 4 + r] = c->x_hi[r] - dhi;
        }
    double *lo_t = NULL, *hi_t = NULL;
    if (c->nt > 0) {
        lo_t = malloc(sizeof(double) * c->nt);
        hi_t = malloc(sizeof(double) * c->nt);
        for (int r = 0; r < c->nt; r++) {
            hi_t[r] = c->ht[r] - support(c, H, hold, c->Ft + r * NX);
            lo_t[r] = -NO_BOUND;
        }
    }
    horizon_qp* q = qp_make(c->A, c->b, c->g, H, free_stage, nu, scale, c->Q, c->r_du, c->P,
                            c->F, c->ref_mask, 4, lo, hi, c->Ft, c->nt, lo_t, hi_t, -c->du_max,
                            c->du_max);
    free(free_stage); free(scale); free(lo); free(hi); free(lo_t); free(hi_t);
    return q;
}

/* P of the DARE by structure-preserving doubling; 0 when it does not converge */
static int dare(const double* A, const double* b, const double* Q, double r, double* P) {
    double Ak[16], G[16], Hk[16], W[16], X1[16], X2[16], t1[16], t2[16];
    memcpy(Ak, A, sizeof Ak);
    memcpy(Hk, Q, sizeof Hk);
    for (int i = 0; i < NX; i++)
        for (int j = 0; j < NX; j++) G[i * NX + j] = b[i] * b[j] / r;
    for (int it = 0; it < 200; it++) {
        matmul(G, Hk, NX, NX, NX, W);
        for (int i = 0; i < NX; i++) W[i * NX + i] += 1.0;
        memcpy(X1, Ak, sizeof X1);
        if (!solve_many(W, X1, NX, NX)) return 0; /* X1 = W^-1 A */
        memcpy(X2, G, sizeof X2);
        if (!solve_many(W, X2, NX, NX)) return 0; /* X2 = W^-1 G */
        double At[16];
        for (int i = 0; i < NX; i++)
            for (int j = 0; j < NX; j++) At[i * NX + j] = Ak[j * NX + i];
        double Gn[16], Hn[16], An[16];
        matmul(Ak, X2, NX, NX, NX, t1);
        matmul(t1, At, NX, NX, NX, t2);
        for (int k = 0; k < 16; k++) Gn[k] = G[k] + t2[k];
        matmul(At, Hk, NX, NX, NX, t1);
        matmul(t1, X1, NX, NX, NX, t2);
        for (int k = 0; k < 16; k++) Hn[k] = Hk[k] + t2[k];
        matmul(Ak, X1, NX, NX, NX, An);
        double diff = 0.0, scale = 0.0;
        for (int k = 0; k < 16; k++) {
            diff = ato_max(diff, fabs(Hn[k] - Hk[k]));
            scale = ato_max(scale, fabs(Hn[k]));
        }
        memcpy(Ak, An, sizeof Ak); memcpy(G, Gn, sizeof G); memcpy(Hk, Hn, sizeof Hk);
        if (!isfinite(scale)) return 0;
        if (diff <= 1e-16 * scale) {
            for (int i = 0; i < NX; i++) /* symmetric, as the DARE's solution is */
                for (int j = 0; j < NX; j++)
                    P[i * NX + j] = 0.5 * (Hk[i * NX + j] + Hk[j * NX + i]);
            return 1;
        }
    }
    return 0;
}

static int close_to(const double* a, const double* b, int n) {
    double scale = 0.0, diff = 0.0;
    for (int k = 0; k < n; k++) {
        scale = ato_max(scale, fabs(b[k]));
        diff = ato_max(diff, fabs(a[k] - b[k]));
    }
    return diff <= 1e-8 * ato_max(scale, 1e-300);
}

law_core* law_make(const ato_values* p, double t0, char* err, size_t n) {
    (void)t0;
    const double* v = p->v;
    law_core* c = calloc(1, sizeof *c);
    c->N = (int)v[ATO_VR_N];
    c->T = v[ATO_VR_sample_time];
    c->c = v[ATO_VR_brake_gain];
    c->a0 = v[ATO_VR_ref_decel];
    c->stop_point = v[ATO_VR_stop_point];
    c->u_min = v[ATO_VR_u_min];
    c->u_max = v[ATO_VR_u_max];
    c->du_max = v[ATO_VR_du_max];
    c->v_max = v[ATO_VR_v_max];
    c->se_max = v[ATO_VR_speed_error_max];
    c->pe_max = v[ATO_VR_position_error_max];
    c->mass = v[ATO_VR_mass];
    c->da = v[ATO_VR_davis_a];
    c->db = v[ATO_VR_davis_b];
    c->dc = v[ATO_VR_davis_c];
#if SELF_TRIGGERED
    c->beta = v[ATO_VR_beta];
#else
    c->beta = 1.0;
#endif
    c->L = v[ATO_VR_observer_gain];
    c->init_cmd = v[ATO_VR_initial_command];
    c->ss_speed = v[ATO_VR_standstill_speed];
    c->ss_window = v[ATO_VR_standstill_window];
    c->ss_cmd = v[ATO_VR_standstill_command];
    c->r_du = v[ATO_VR_r_du];
    const char* solver = p->s[ATO_VR_qp_solver];
    const char* design = p->s[ATO_VR_design_model];
    char a[40], b[40];
    if (strcmp(solver, "daqp") != 0) {
        snprintf(err, n, "qp_solver = '%s': the native build solves with DAQP only (\"daqp\"; "
                 "use the Python FMU for OSQP)", solver);
        goto fail;
    }
    if (!ato_check_less("u_min", c->u_min, "u_max", c->u_max, err, n)) goto fail;
    /* delay_samples */
    double ratio = v[ATO_VR_brake_delay] / c->T;
    c->l = (int)nearbyint(ratio);
    if (c->l < 0 || fabs(ratio - c->l) > 1e-9) {
        snprintf(err, n, "brake_delay = %s s is not a whole number of samples of sample_time = "
                 "%s s", ato_repr(v[ATO_VR_brake_delay], a), ato_repr(c->T, b));
        goto fail;
    }
    if (!ato_grade_load(p->resources, p->s[ATO_VR_route], &c->grade, err, n)) goto fail;
    /* design model (controllers.common.design_model.brake_delay_model) */
    double tau = v[ATO_VR_brake_time_constant];
    double blk[25] = {0}, phi[25];
    blk[0 * 5 + 0] = -1.0 / tau; blk[1 * 5 + 0] = 1.0; blk[2 * 5 + 1] = 1.0;
    blk[0 * 5 + 3] = -c->c / tau; blk[1 * 5 + 4] = -1.0;
    for (int k = 0; k < 25; k++) blk[k] *= c->T;
    expm5(blk, phi);
    const int idx[3] = {A_C, V, S};
    memset(c->A, 0, sizeof c->A);
    for (int i = 0; i < 3; i++) {
        for (int j = 0; j < 3; j++) c->A[idx[i] * NX + idx[j]] = phi[i * 5 + j];
        c->A[idx[i] * NX + U_PREV] = phi[i * 5 + 3];
        c->b[idx[i]] = phi[i * 5 + 3];
        c->g[idx[i]] = phi[i * 5 + 4];
    }
    c->A[U_PREV * NX + U_PREV] = 1.0;
    c->b[U_PREV] = 1.0;
    c->g[U_PREV] = 0.0;
    if (strcmp(design, "euler") == 0) {
        for (int k = 0; k < NX; k++) { c->A[V * NX + k] = 0.0; c->A[S * NX + k] = 0.0; }
        c->A[V * NX + A_C] = c->T; c->A[V * NX + V] = 1.0;
        c->A[S * NX + V] = c->T; c->A[S * NX + S] = 1.0;
        c->b[V] = c->b[S] = 0.0;
        c->g[V] = -c->T; c->g[S] = 0.0;
    }
    memset(c->Q, 0, sizeof c->Q);
    c->Q[V * NX + V] = v[ATO_VR_q_speed];
    c->Q[S * NX + S] = v[ATO_VR_q_position];
    if (!dare(c->A, c->b, c->Q, c->r_du, c->P)) {
        snprintf(err, n, "the LQR feedback of (A, b, Q, R) does not stabilise the design model: "
                 "check q_speed, q_position, r_du");
        goto fail;
    }
    double Pb[4], bPb = 0.0;
    for (int i = 0; i < NX; i++) {
        Pb[i] = 0.0;
        for (int k = 0; k < NX; k++) Pb[i] += c->P[i * NX + k] * c->b[k];
        bPb += c->b[i] * Pb[i];
    }
    for (int j = 0; j < NX; j++) { /* K = -(b'P A) / (r + b'P b) */
        double acc = 0.0;
        for (int k = 0; k < NX; k++) acc += Pb[k] * c->A[k * NX + j];
        c->K[j] = -acc / (c->r_du + bPb);
    }
    for (int i = 0; i < NX; i++)
        for (int j = 0; j < NX; j++) c->Acl[i * NX + j] = c->A[i * NX + j] + c->b[i] * c->K[j];
    /* resistance model and W */
    int nominal = v[ATO_VR_nominal_resistance] != 0.0;
    c->known = FEEDFORWARD || (TUBE && nominal);
    c->observer = v[ATO_VR_disturbance_observer] != 0.0 && c->known;
    double gmin = INFINITY, gmax = -INFINITY, gabs = 0.0;
    for (int k = 0; k < c->grade.n; k++) {
        double ag = GRAVITY * c->grade.values[k] / 1000.0;
        gmin = ato_min(gmin, ag); gmax = ato_max(gmax, ag);
        gabs = ato_max(gabs, fabs(c->grade.values[k]));
    }
    {
        double a_w = davis(c, c->v_max) / c->mass, d = v[ATO_VR_davis_uncertainty],
               m = v[ATO_VR_mass_uncertainty];
        double a_g = v[ATO_VR_grade_uncertainty] * GRAVITY * gabs / 1000.0;
        c->spread[0] = a_w * ((1.0 - d) / (1.0 + m) - 1.0) - a_g;
        c->spread[1] = a_w * ((1.0 + d) / (1.0 - m) - 1.0) + a_g;
    }
    double w_lo = 0.0, w_hi = 0.0;
    if (!TUBE) {
    } else if (!nominal) {
        double du = v[ATO_VR_davis_uncertainty];
        w_lo = gmin + davis(c, 0.0) / c->mass * (1.0 - du);
        w_hi = gmax + davis(c, c->v_max) / c->mass * (1.0 + du);
    } else if (c->observer) {
        double width = c->spread[1] - c->spread[0];
        w_lo = -width; w_hi = width;
    } else {
        w_lo = c->spread[0]; w_hi = c->spread[1];
    }
    for (int k = 0; k < NX; k++) {
        c->w_vert[k] = c->g[k] * w_lo;
        c->w_vert[NX + k] = c->g[k] * w_hi;
    }
    static const double Frows[16] = {0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 1, 0, 0, 0, 0, 1};
    memcpy(c->F, Frows, sizeof Frows);
    c->ref_mask[0] = c->ref_mask[1] = 0.0; c->ref_mask[2] = c->ref_mask[3] = 1.0;
    c->x_lo[0] = c->u_min; c->x_lo[1] = -INFINITY; c->x_lo[2] = -c->se_max; c->x_lo[3] = -c->pe_max;
    c->x_hi[0] = c->u_max; c->x_hi[1] = c->v_max; c->x_hi[2] = c->se_max; c->x_hi[3] = c->pe_max;
    if (TUBE) { /* the terminal set: shipped, matched by the data it was computed from */
        double Ct[8 * 4] = {0}, h[8];
        int nC = 6;
        for (int k = 0; k < NX; k++) {
            Ct[0 * 4 + k] = k == V; Ct[1 * 4 + k] = -(k == V);
            Ct[2 * 4 + k] = k == S; Ct[3 * 4 + k] = -(k == S);
            Ct[4 * 4 + k] = c->K[k]; Ct[5 * 4 + k] = -c->K[k];
        }
        h[0] = h[1] = c->se_max; h[2] = h[3] = c->pe_max; h[4] = h[5] = c->du_max;
        if (c->known) {
            double a_lo = gmin + davis(c, 0.0) / c->mass;
            double a_hi = gmax + davis(c, c->v_max) / c->mass;
            double us_lo = (c->a0 - a_hi) / c->c, us_hi = (c->a0 - a_lo) / c->c;
            for (int k = 0; k < NX; k++) {
                Ct[6 * 4 + k] = k == U_PREV;
                Ct[7 * 4 + k] = -(k == U_PREV);
            }
            h[6] = c->u_max - us_hi; h[7] = us_lo - c->u_min;
            nC = 8;
        }
        c->nt = 0;
        for (int e = 0; e < SM_N_SETS; e++) {
            const sm_set* set = &SM_SETS[e];
            if (set->n_c == nC && close_to(c->Acl, set->a_cl, 16) &&
                close_to(Ct, set->c, nC * 4) && close_to(h, set->h, nC) &&
                close_to(c->w_vert, set->w, 8)) {
                c->nt = set->n_rows;
                c->Ft = set->rows;
                c->ht = set->rhs;
                break;
            }
        }
        if (c->nt == 0) {
            snprintf(err, n, "no terminal set is shipped for this design (the native build "
                     "carries the maximal robust invariant sets the core computes for the "
                     "seed 000 scenarios' designs; another one needs LPs): use the Python "
                     "FMU for these parameters");
            goto fail;
        }
    }
    c->max_hold = SELF_TRIGGERED ? c->N - 1 : 1;
    if (c->max_hold < 1) c->max_hold = 1;
    c->Hmax = c->max_hold + c->N - 1 > c->N ? c->max_hold + c->N - 1 : c->N;
    c->qps = calloc(c->max_hold + 1, sizeof(horizon_qp*));
    c->warm_off = malloc(sizeof(int) * (c->max_hold + 1));
    int off = 0;
    for (int h = 0; h <= c->max_hold; h++) {
        c->warm_off[h] = off;
        int H = h == 0 ? c->N : h + c->N - 1;
        off += h == 0 ? c->N + H : c->N + 4 * H + c->nt;
    }
    c->ncon_total = off;
    int N1 = (c->Hmax + 1) * NX;
    c->ref = malloc(sizeof(double) * N1);
    c->e = malloc(sizeof(double) * N1);
    c->d = malloc(sizeof(double) * (c->Hmax + 1));
    c->qv = malloc(sizeof(double) * (c->N + 1));
    c->xs = malloc(sizeof(double) * N1);
    c->o_hist = ST_SCALARS;
    c->o_obs_in = c->o_hist + c->l + 1;
    c->o_plan = c->o_obs_in + c->l + 1;
    c->o_warm_ok = c->o_plan + c->Hmax;
    c->o_warm = c->o_warm_ok + c->max_hold + 1;
    c->n_state = (size_t)c->o_warm + c->ncon_total;
    c->st = calloc(c->n_state, sizeof(double));
    for (int k = 0; k <= c->l; k++) c->st[c->o_hist + k] = c->init_cmd;
    c->st[ST_COMMAND] = c->init_cmd;
    c->st[ST_HOLD] = 1;
    if (c->Hmax > 256) {
        snprintf(err, n, "N = %d: the native build plans at most 256 stages", c->N);
        goto fail;
    }
    return c;
fail:
    law_free(c);
    return NULL;
}

void law_free(law_core* c) {
    if (!c) return;
    if (c->qps)
        for (int h = 0; h <= c->max_hold; h++) qp_free(c->qps[h]);
    free(c->qps); free(c->warm_off); ato_grade_free(&c->grade);
    free(c->ref); free(c->e); free(c->d); free(c->qv); free(c->xs); free(c->st);
    free(c);
}

size_t law_state_size(const law_core* c) { return c->n_state * sizeof(double); }
void law_get_state(const law_core* c, void* out) { memcpy(out, c->st, law_state_size(c)); }
void law_set_state(law_core* c, const void* in) { memcpy(c->st, in, law_state_size(c)); }

/* x_{0|k} = x(k + l) from the measurement and the commands still in the dead time */
static void delay_prediction(const law_core* c, double a_c, double v, double s, double* x) {
    x[0] = a_c; x[1] = c->st[c->o_hist]; x[2] = v; x[3] = s;
    for (int k = 1; k <= c->l; k++) {
        double a_r = c->known ? resistance(c, x[V], x[S]) : 0.0;
        step_model(c, x, c->st[c->o_hist + k] - x[U_PREV], a_r);
    }
}

/* one QP of hold `hold` (0: the fallback); 0 after a message when DAQP cannot be set up */
static int solve_hold(law_core* c, int hold, const double* x0, double t, qp_result* res,
                      char* err, size_t n) {
    if (!c->qps[hold]) {
        c->qps[hold] = make_qp(c, hold);
        if (!c->qps[hold]) {
            snprintf(err, n, "DAQP setup failed: Hessian not positive definite? check r_du > 0");
            return 0;
        }
    }
    horizon_qp* q = c->qps[hold];
    int H = q->H;
    /* the known resistance along the previous plan (shifted) */
    if (c->known) {
        double x[4];
        memcpy(x, x0, sizeof x);
        int plan_len = (int)c->st[ST_PLAN_LEN];
        for (int i = 0; i < H; i++) {
            c->d[i] = resistance(c, x[V], x[S]);
            double u = i + 1 < plan_len ? c->st[c->o_plan + i + 1] : 0.0;
            step_model(c, x, u, c->d[i]);
        }
        c->d[H] = c->d[H - 1];
    }
    reference(c, t, H, c->known ? c->d : NULL, c->ref);
    double* warm = c->st[c->o_warm_ok + hold] != 0.0 ? c->st + c->o_warm + c->warm_off[hold] : NULL;
    qp_solve(q, x0, c->ref, c->known ? c->d : NULL, warm, res, c->e, c->qv);
    c->st[ST_SOLVES] += 1;
    if (res->feasible) {
        memcpy(c->st + c->o_warm + c->warm_off[hold], q->lam, sizeof(double) * q->n_con);
        c->st[c->o_warm_ok + hold] = 1.0;
    }
    return 1;
}

static void set_plan(law_core* c, const double* du, int len) {
    for (int i = 0; i < len; i++) c->st[c->o_plan + i] = du[i];
    c->st[ST_PLAN_LEN] = len;
}

/* the fallback (StopMpc.fallback): du_0 and the plan (plan_len 0: none) */
static int fallback(law_core* c, const double* x0, double t, double* du0, double* plan,
                    int* plan_len, char* err, size_t n) {
    qp_result res;
    if (!solve_hold(c, 0, x0, t, &res, err, n)) return 0;
    if (res.feasible) {
        *du0 = res.du[0];
        memcpy(plan, res.du, sizeof(double) * res.H);
        *plan_len = res.H;
        return 1;
    }
    double ref[4];
    reference(c, t, 0, NULL, ref);
    double du = 0.0;
    for (int k = 0; k < NX; k++) du += c->K[k] * (x0[k] - ref[k]);
    *du0 = ato_min(ato_max(du, -c->du_max), c->du_max);
    *plan_len = 0;
    return 1;
}

/* the one-state disturbance observer (StopMpc.observe) */
static void observe(law_core* c, double v, int elapsed) {
    if (c->st[ST_HAS_OBS] == 0.0 || elapsed <= 0 || v <= c->ss_speed) return;
    double x[4], sens[4] = {0, 0, 0, 0};
    memcpy(x, c->st + ST_OBS_X, sizeof x);
    int n_in = c->l + 1;
    for (int k = 0; k < elapsed; k++) {
        double u = c->st[c->o_obs_in + (k < n_in ? k : n_in - 1)];
        step_model(c, x, u - x[U_PREV], resistance(c, x[V], x[S]));
        double y[4];
        for (int r = 0; r < NX; r++) {
            double acc = 0.0;
            for (int j = 0; j < NX; j++) acc += c->A[r * NX + j] * sens[j];
            y[r] = acc + c->g[r];
        }
        memcpy(sens, y, sizeof y);
    }
    if (x[V] <= c->ss_speed || fabs(sens[V]) < 1e-12) return;
    double d = c->st[ST_D_HAT] + c->L * (v - x[V]) / sens[V];
    c->st[ST_D_HAT] = ato_min(ato_max(d, c->spread[0]), c->spread[1]);
}

int law_compute(law_core* c, double t, const ato_values* p, double* out, char* err, size_t n) {
    double v = p->v[ATO_VR_v], s = p->v[ATO_VR_s], a_c = p->v[ATO_VR_a_c];
    double* st = c->st;
    int L1 = c->l + 1;
    if (st[ST_HAS_LAST] != 0.0) { /* the held command acted for the samples since the last */
        int elapsed = (int)nearbyint((t - st[ST_LAST_T]) / c->T);
        if (elapsed > 0) {
            int keep = elapsed >= L1 ? 0 : L1 - elapsed;
            memmove(st + c->o_hist, st + c->o_hist + (L1 - keep), sizeof(double) * keep);
            for (int k = keep; k < L1; k++) st[c->o_hist + k] = st[ST_COMMAND];
        }
        if (c->observer) observe(c, v, elapsed);
    } else {
        st[ST_ANCHOR_T] = t;
        st[ST_ANCHOR_S] = s;
        st[ST_HAS_LAST] = 1.0;
    }
    st[ST_LAST_T] = t;
    double ref_now[4];
    reference(c, t - c->l * c->T, 0, NULL, ref_now);
    int rest = ref_now[V] <= 0.0 || c->stop_point - s <= c->ss_window;
    double u, x0[4];
    int hold;
    qp_result res;
    if (st[ST_STANDSTILL] != 0.0 || (v <= c->ss_speed && rest)) {
        st[ST_STANDSTILL] = 1.0;
        st[ST_EV_STAND] += 1;
        delay_prediction(c, a_c, v, s, x0);
        if (!solve_hold(c, 1, x0, t, &res, err, n)) return 0;
        if (!res.feasible) st[ST_INF_AFTER] += 1;
        u = ato_max(st[ST_COMMAND], c->ss_cmd);
        hold = c->max_hold;
        set_plan(c, NULL, 0);
    } else {
        st[ST_EV_MOVING] += 1;
        delay_prediction(c, a_c, v, s, x0);
        double du, plan[256];
        int plan_len = 0;
        if (!solve_hold(c, 1, x0, t, &res, err, n)) return 0;
        hold = 1;
        if (!res.feasible) {
            st[ST_INFEASIBLE] += 1;
            if (!fallback(c, x0, t, &du, plan, &plan_len, err, n)) return 0;
        } else {
            du = res.du[0];
            memcpy(plan, res.du, sizeof(double) * res.H);
            plan_len = res.H;
            for (int h = c->max_hold; h > 1; h--) { /* RSMPC: the longest hold with J^M <= J^1 */
                qp_result r2;
                if (!solve_hold(c, h, x0, t, &r2, err, n)) return 0;
                if (r2.feasible && r2.cost <= res.cost) {
                    du = r2.du[0];
                    hold = h;
                    memcpy(plan, r2.du, sizeof(double) * r2.H);
                    plan_len = r2.H;
                    break;
                }
            }
        }
        set_plan(c, plan, plan_len); /* after the solves: each fed forward along the last */
        u = ato_min(ato_max(x0[U_PREV] + du, c->u_min), c->u_max);
    }
    if (c->observer) { /* what the next event compares its measured speed with */
        st[ST_OBS_X + 0] = a_c; st[ST_OBS_X + 1] = st[c->o_hist]; st[ST_OBS_X + 2] = v;
        st[ST_OBS_X + 3] = s;
        for (int k = 1; k < L1; k++) st[c->o_obs_in + k - 1] = st[c->o_hist + k];
        st[c->o_obs_in + L1 - 1] = u;
        st[ST_HAS_OBS] = 1.0;
    }
    st[ST_COMMAND] = u;
    st[ST_HOLD] = hold;
    st[ST_LAST_VREF] = curve_speed(c, s);
    law_outputs(c, out);
    return hold;
}

void law_outputs(const law_core* c, double* out) {
    const double* st = c->st;
    out[ATO_VR_brake_command] = st[ST_COMMAND];
    out[ATO_VR_v_ref] = st[ST_LAST_VREF];
    out[ATO_VR_qp_solves] = st[ST_SOLVES];
    out[ATO_VR_qp_infeasible] = st[ST_INFEASIBLE];
    out[ATO_VR_hold_steps] = st[ST_HOLD];
    out[ATO_VR_qp_infeasible_after_stop] = st[ST_INF_AFTER];
    out[ATO_VR_events_moving] = st[ST_EV_MOVING];
    out[ATO_VR_events_standstill] = st[ST_EV_STAND];
    out[ATO_VR_resistance_estimate] = st[ST_D_HAT];
}
