/*
 * hybrid_mpc.c: online law of Gmpc3 and MbMpc3, the C twin of controllers/hybrid/hybrid_mpc.py
 * (HybridMpc, seed 004, eq. 15; MoveBlockingMpc, eq. 17) and of the MIQP it solves,
 * controllers/hybrid/miqp.py (HybridMiqp), over the control model of
 * controllers/hybrid/model.py (ChainModel in MLD form, eq. 13).
 *
 * Per sample: the state x = [v, x] rebuilt from the speeds and coupler forces, the mode
 * schedule (braking from brake_from until the mean speed is down; "optimise": free binaries),
 * the references of the horizon, and the condensed MIQP of the blocking cut at the schedule's
 * mode changes (split_blocks) in U with the mode and segment binaries, solved by DAQP's branch
 * and bound (bnb.c) as the core solves it: a fresh workspace per solve, set up with every
 * binary declared and then updated with the event's linear term, bounds and senses; a failed
 * solve retried with the core's settings (HY_RETRIES), then, with at most
 * HY_ENUMERATE_MAX_FREE free binaries, every assignment solved as a QP. The first input is
 * applied, projected onto the mode; an infeasible MIQP applies the previous plan's next input.
 *
 * The control model (zero-order-hold matrices, PWA resistance fitted to the Davis curve) is
 * computed by the core at build time for the declared default sample time and fit speed
 * (ato_hybrid_model.h); the big-M rows, the condensing, the bounds and the linear term are
 * computed here from it in the core's formulas. The matrix products sum in index order, where
 * numpy's BLAS may use another order and fused multiply-adds, and DAQP here is compiled
 * without the Python wheel's reassociation: forces agree within the bound
 * tests/test_native_hybrid.py derives, mode decisions exactly.
 */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "api.h"   /* DAQP */
#include "utils.h" /* DAQP: daqp_update_ldp */
#include "hybrid.h"
#include "ato_hybrid_model.h"
#include "law_common.h"
#include "profile.h"
#include "vars.h"
#include "ato_model.h"

#define UNITS ATO_OPTION_units
#define NX (2 * UNITS)
#define KB 2                      /* breakpoints of the PWA resistance */
#define NW (UNITS + 1 + 2 * KB)   /* per-stage decision [u, delta, b, z] */
#define NMLD (UNITS + 7 * KB)     /* mixed-integer rows per stage */
#define NST (2 * UNITS - 1)       /* state rows per stage: couplers, speeds */
#define KN 1e3
#define BIG 1e30                  /* DAQP's infinity (miqp.py _INF) */
#define SENSE_BINARY 16
#define MAX_N 40                  /* the declared maximum of N */
#define FREE_MODE (-1)            /* delta of a stage left to the optimiser */

/* HybridMiqp of one blocking: the condensed matrices, fixed per blocking */
typedef struct {
    int N, nb, nV, n_rows, n_bin;
    int blocks[MAX_N], stage_block[MAX_N];
    double *P;    /* N x NW x nV: w_s = P_s V */
    double *Phi;  /* (N+1) x NX x NX */
    double *Gam;  /* (N+1) x NX x nV */
    double *fr;   /* (N+1) x NX */
    double *H;    /* nV x nV (DAQP: 1/2 V'HV + f'V) */
    double *Gq;   /* (N+1) x nV x NX: 2 Gam_s' Q */
    double *A;    /* n_rows x nV */
    int *bin_idx, *bin_stage, *bin_kind; /* V index, stage, -1 delta or breakpoint k */
} problem;

typedef struct {
    double forces[UNITS], v_ref, s_ref, speed_error;
    double plan[MAX_N][UNITS];
    int plan_len, plan_pos, delta, braking_done, has_failure;
    double qp_solves, qp_infeasible, nodes, qp_rescued, failure_time;
    char failure[48];
} hybrid_state;

struct law_core {
    const hy_model* md;
    double A1[NX * NX], Bw[NX * NW], f1[NX], c[NX], Fst[NST * NX];
    double ex[NMLD * NX], ew[NMLD * NW], mlo[NMLD], mhi[NMLD];
    double v_lo, v_hi, mass, q[NX], r, dr;
    double brake_from, brake_until_speed, sample_time, coupler_max, speed_max;
    int horizon, n_blocks, blocks[MAX_N], timetable, optimise;
    problem** probs; /* [0]: the declared blocking; then the cut ones met so far */
    int n_probs;
    ato_profile profile;
    hybrid_state st;
};

typedef struct {
    int feasible, nodes;
    double cost;
    char status[48];
    double* V;
} solve_result;

/* -- the control model (ChainModel) ------------------------------------------------------- */
static double resistance(const hy_model* md, double v) { /* PwlResistance.__call__ */
    int j = 0;
    while (j < KB && !(v < md->breakpoints[j])) j++;
    return md->alpha[j] + md->beta[j] * v;
}

static void mld_row(law_core* c, int* r, const double* xc, int nz, const int* wi,
                    const double* wv, double lo, double hi) {
    for (int j = 0; j < NX; j++) c->ex[*r * NX + j] = xc ? xc[j] : 0.0;
    for (int j = 0; j < NW; j++) c->ew[*r * NW + j] = 0.0;
    for (int q = 0; q < nz; q++) c->ew[*r * NW + wi[q]] = wv[q];
    c->mlo[*r] = lo;
    c->mhi[*r] = hi;
    (*r)++;
}

static void make_model(law_core* c) {
    const hy_model* md = c->md;
    for (int i = 0; i < NX; i++) {
        for (int j = 0; j < NX; j++) /* A_seg(0) = A0 + beta_0 g c' */
            c->A1[i * NX + j] = md->A0[i * NX + j] + md->beta[0] * (md->g[i] * md->c[j]);
        for (int j = 0; j < NW; j++) c->Bw[i * NW + j] = 0.0;
        for (int j = 0; j < UNITS; j++) c->Bw[i * NW + j] = md->B[i * UNITS + j];
        for (int k = 0; k < KB; k++)
            c->Bw[i * NW + UNITS + 1 + KB + k] = md->g[i] * (md->beta[k + 1] - md->beta[k]);
        c->f1[i] = md->alpha[0] * md->g[i];
        c->c[i] = md->c[i];
    }
    c->mass = 0.0;
    for (int i = 0; i < UNITS; i++) c->mass += md->m[i];
    /* state rows: coupler forces (kN), then speeds */
    memset(c->Fst, 0, sizeof c->Fst);
    for (int j = 0; j < UNITS - 1; j++)
        for (int x = 0; x < NX; x++) c->Fst[j * NX + x] = md->coupler_rows[j * NX + x];
    for (int i = 0; i < UNITS; i++) c->Fst[(UNITS - 1 + i) * NX + i] = 1.0;
    /* mld_rows */
    int r = 0, di = UNITS;
    double U = md->U;
    for (int i = 0; i < UNITS; i++) {
        int wi[2] = {i, di};
        double wv[2] = {1.0, -U};
        mld_row(c, &r, NULL, 2, wi, wv, -U, 0.0);
    }
    double negc[NX];
    for (int j = 0; j < NX; j++) negc[j] = -c->c[j];
    for (int k = 0; k < KB; k++) {
        double vk = md->breakpoints[k], big = c->v_hi - vk, small = c->v_lo - vk;
        int b = UNITS + 1 + k, z = UNITS + 1 + KB + k;
        int zb[2] = {z, b};
        double w1[2] = {1.0, -big}, w2[2] = {1.0, -small};
        mld_row(c, &r, NULL, 2, zb, w1, -INFINITY, 0.0);
        mld_row(c, &r, NULL, 2, zb, w2, 0.0, INFINITY);
        mld_row(c, &r, negc, 2, zb, w2, -INFINITY, -vk - small);
        mld_row(c, &r, negc, 2, zb, w1, -vk - big, INFINITY);
        double mb[1] = {-big}, ms[1] = {-small}, one[1] = {1.0};
        mld_row(c, &r, c->c, 1, &b, mb, -INFINITY, vk);
        mld_row(c, &r, c->c, 1, &b, ms, vk + small, INFINITY);
        mld_row(c, &r, negc, 1, &z, one, -vk, INFINITY);
    }
}

/* -- the condensed MIQP of one blocking (HybridMiqp.__init__) ------------------------------ */
static void problem_free(problem* pb) {
    if (!pb) return;
    free(pb->P); free(pb->Phi); free(pb->Gam); free(pb->fr); free(pb->H); free(pb->Gq);
    free(pb->A); free(pb->bin_idx); free(pb->bin_stage); free(pb->bin_kind);
    free(pb);
}

static problem* problem_make(const law_core* c, const int* blocks, int nb) {
    int N = c->horizon, n = UNITS;
    problem* pb = calloc(1, sizeof *pb);
    pb->N = N;
    pb->nb = nb;
    for (int j = 0, s = 0; j < nb; j++) {
        pb->blocks[j] = blocks[j];
        for (int q = 0; q < blocks[j]; q++) pb->stage_block[s++] = j;
    }
    int nV = n * nb + N * (1 + 2 * KB);
    pb->nV = nV;
    pb->P = calloc((size_t)N * NW * nV, sizeof(double));
    for (int s = 0; s < N; s++) {
        double* Ps = pb->P + (size_t)s * NW * nV;
        for (int i = 0; i < n; i++) Ps[i * nV + n * pb->stage_block[s] + i] = 1.0;
        int base = n * nb + s * (1 + 2 * KB);
        for (int q = 0; q < 1 + 2 * KB; q++) Ps[(n + q) * nV + base + q] = 1.0;
    }
    pb->Phi = calloc((size_t)(N + 1) * NX * NX, sizeof(double));
    pb->Gam = calloc((size_t)(N + 1) * NX * nV, sizeof(double));
    pb->fr = calloc((size_t)(N + 1) * NX, sizeof(double));
    for (int i = 0; i < NX; i++) pb->Phi[i * NX + i] = 1.0;
    for (int s = 0; s < N; s++) {
        const double *Ph = pb->Phi + (size_t)s * NX * NX, *G = pb->Gam + (size_t)s * NX * nV;
        const double *Ps = pb->P + (size_t)s * NW * nV, *f = pb->fr + (size_t)s * NX;
        double *Ph1 = pb->Phi + (size_t)(s + 1) * NX * NX;
        double *G1 = pb->Gam + (size_t)(s + 1) * NX * nV, *f1 = pb->fr + (size_t)(s + 1) * NX;
        for (int i = 0; i < NX; i++) {
            for (int j = 0; j < NX; j++) {
                double acc = 0.0;
                for (int q = 0; q < NX; q++) acc += c->A1[i * NX + q] * Ph[q * NX + j];
                Ph1[i * NX + j] = acc;
            }
            for (int v = 0; v < nV; v++) {
                double a = 0.0, b = 0.0;
                for (int q = 0; q < NX; q++) a += c->A1[i * NX + q] * G[q * nV + v];
                for (int q = 0; q < NW; q++) b += c->Bw[i * NW + q] * Ps[q * nV + v];
                G1[i * nV + v] = a + b;
            }
            double acc = 0.0;
            for (int q = 0; q < NX; q++) acc += c->A1[i * NX + q] * f[q];
            f1[i] = acc + c->f1[i];
        }
    }
    /* H = 2 (sum_s Gam_s' Q Gam_s + sum_s Pu_s' R Pu_s + D_s' dR D_s) + regularisation */
    double* H = calloc((size_t)nV * nV, sizeof(double));
    pb->Gq = calloc((size_t)(N + 1) * nV * NX, sizeof(double));
    for (int s = 0; s <= N; s++) {
        const double* G = pb->Gam + (size_t)s * NX * nV;
        double* Gq = pb->Gq + (size_t)s * nV * NX;
        for (int v = 0; v < nV; v++)
            for (int x = 0; x < NX; x++) Gq[v * NX + x] = 2.0 * (G[x * nV + v] * c->q[x]);
        if (s == 0) continue;
        for (int a = 0; a < nV; a++)
            for (int b = 0; b < nV; b++) {
                double acc = 0.0;
                for (int x = 0; x < NX; x++) acc += G[x * nV + a] * c->q[x] * G[x * nV + b];
                H[a * nV + b] += acc;
            }
    }
    for (int s = 0; s < N; s++) {
        /* Pu_s selects V[n j + i] (j: the stage's block); D_s = Pu_s - Pu_(s-1) */
        int j = pb->stage_block[s], jp = s > 0 ? pb->stage_block[s - 1] : -1;
        for (int i = 0; i < n; i++) {
            int a = n * j + i;
            H[a * nV + a] += c->r;
            if (jp == j) continue; /* D_s = 0 inside a block */
            H[a * nV + a] += c->dr;
            if (jp >= 0) {
                int b = n * jp + i;
                H[b * nV + b] += c->dr;
                H[a * nV + b] -= c->dr;
                H[b * nV + a] -= c->dr;
            }
        }
    }
    for (int q = 0; q < nV * nV; q++) H[q] *= 2.0;
    pb->bin_idx = malloc(sizeof(int) * N * (1 + KB));
    pb->bin_stage = malloc(sizeof(int) * N * (1 + KB));
    pb->bin_kind = malloc(sizeof(int) * N * (1 + KB));
    int nbin = 0;
    for (int s = 0; s < N; s++) {
        int base = n * nb + s * (1 + 2 * KB);
        pb->bin_idx[nbin] = base, pb->bin_stage[nbin] = s, pb->bin_kind[nbin++] = -1;
        for (int k = 0; k < KB; k++) {
            pb->bin_idx[nbin] = base + 1 + k, pb->bin_stage[nbin] = s;
            pb->bin_kind[nbin++] = k;
            int z = base + 1 + KB + k;
            H[z * nV + z] += 2.0 * HY_EPS_REG;
        }
    }
    pb->n_bin = nbin;
    for (int q = 0; q < nbin; q++) H[pb->bin_idx[q] * nV + pb->bin_idx[q]] += 2.0 * HY_EPS_REG;
    pb->H = malloc(sizeof(double) * nV * nV);
    for (int a = 0; a < nV; a++)
        for (int b = 0; b < nV; b++) pb->H[a * nV + b] = 0.5 * (H[a * nV + b] + H[b * nV + a]);
    free(H);
    /* rows: the MLD rows of stages 0..N-1, the state rows of stages 1..N */
    pb->n_rows = N * NMLD + N * NST;
    pb->A = calloc((size_t)pb->n_rows * nV, sizeof(double));
    for (int s = 0; s < N; s++) {
        const double *G = pb->Gam + (size_t)s * NX * nV, *Ps = pb->P + (size_t)s * NW * nV;
        for (int r = 0; r < NMLD; r++)
            for (int v = 0; v < nV; v++) {
                double a = 0.0, b = 0.0;
                for (int x = 0; x < NX; x++) a += c->ex[r * NX + x] * G[x * nV + v];
                for (int w = 0; w < NW; w++) b += c->ew[r * NW + w] * Ps[w * nV + v];
                pb->A[(size_t)(s * NMLD + r) * nV + v] = a + b;
            }
    }
    for (int s = 1; s <= N; s++) {
        const double* G = pb->Gam + (size_t)s * NX * nV;
        for (int r = 0; r < NST; r++)
            for (int v = 0; v < nV; v++) {
                double a = 0.0;
                for (int x = 0; x < NX; x++) a += c->Fst[r * NX + x] * G[x * nV + v];
                pb->A[(size_t)(N * NMLD + (s - 1) * NST + r) * nV + v] = a;
            }
    }
    return pb;
}

/* split_blocks: the declared blocks cut wherever the fixed mode changes inside one */
static int split_blocks(const law_core* c, const int* delta, int* out) {
    int k = 0, s = 0;
    for (int q = 0; q < c->n_blocks; q++) {
        int start = s;
        for (int t = s + 1; t < s + c->blocks[q]; t++) {
            int a = delta[t - 1], b = delta[t];
            if (a != FREE_MODE && b != FREE_MODE && a != b) {
                out[k++] = t - start;
                start = t;
            }
        }
        s += c->blocks[q];
        out[k++] = s - start;
    }
    return k;
}

static problem* for_modes(law_core* c, const int* delta) {
    int blocks[MAX_N];
    int nb = split_blocks(c, delta, blocks);
    for (int q = 0; q < c->n_probs; q++) {
        problem* pb = c->probs[q];
        if (pb->nb == nb && memcmp(pb->blocks, blocks, sizeof(int) * nb) == 0) return pb;
    }
    c->probs = realloc(c->probs, sizeof(problem*) * (c->n_probs + 1));
    c->probs[c->n_probs] = problem_make(c, blocks, nb);
    return c->probs[c->n_probs++];
}

/* -- one event (HybridMiqp.bounds, linear_term, _solve, _enumerate) ------------------------ */
typedef struct { double traction[UNITS], brake[UNITS], coupler, speed; } limits;

static void free_response(const problem* pb, const double* x0, double* fx) {
    for (int s = 0; s <= pb->N; s++)
        for (int i = 0; i < NX; i++) {
            double acc = 0.0;
            for (int j = 0; j < NX; j++) acc += pb->Phi[((size_t)s * NX + i) * NX + j] * x0[j];
            fx[s * NX + i] = acc + pb->fr[s * NX + i];
        }
}

static int bounds(const law_core* c, const problem* pb, const double* x0, const double* fx,
                  const limits* lim, const int* delta, double* lo, double* hi, int* sense) {
    const hy_model* md = c->md;
    int n = UNITS, N = pb->N, nV = pb->nV, nb = pb->nb;
    double wlo[NW], whi[NW];
    for (int i = 0; i < n; i++) {
        wlo[i] = -lim->brake[i];
        whi[i] = md->motored[i] != 0.0 ? lim->traction[i] : 0.0;
    }
    wlo[n] = 0.0, whi[n] = 1.0;
    for (int k = 0; k < KB; k++) {
        wlo[n + 1 + k] = 0.0, whi[n + 1 + k] = 1.0;
        wlo[n + 1 + KB + k] = 0.0;
        whi[n + 1 + KB + k] = ato_max(0.0, c->v_hi - md->breakpoints[k]);
    }
    for (int q = 0; q < nV + pb->n_rows; q++) sense[q] = 0;
    double ulo[MAX_N][UNITS], uhi[MAX_N][UNITS];
    for (int j = 0; j < nb; j++)
        for (int i = 0; i < n; i++) ulo[j][i] = wlo[i], uhi[j][i] = whi[i];
    for (int s = 0; s < N; s++) {
        int j = pb->stage_block[s];
        for (int i = 0; i < n; i++) {
            if (delta[s] == 1) ulo[j][i] = ato_max(ulo[j][i], 0.0);
            else if (delta[s] == 0) uhi[j][i] = ato_min(uhi[j][i], 0.0);
        }
    }
    for (int j = 0; j < nb; j++)
        for (int i = 0; i < n; i++) {
            lo[n * j + i] = ulo[j][i];
            hi[n * j + i] = ato_max(uhi[j][i], ulo[j][i]); /* np.maximum */
        }
    double v0 = 0.0;
    for (int j = 0; j < NX; j++) v0 += c->c[j] * x0[j];
    double w_min = ato_min(resistance(md, c->v_lo), resistance(md, 0.0));
    double w_max = resistance(md, c->v_hi);
    double trac = 0.0, brake = 0.0;
    for (int i = 0; i < n; i++) {
        trac += md->motored[i] != 0.0 ? lim->traction[i] : 0.0;
        brake += lim->brake[i];
    }
    double a_up = c->sample_time * (1e3 * trac / c->mass - w_min);
    double a_dn = c->sample_time * (1e3 * brake / c->mass + w_max);
    int n_free = 0;
    signed char fixed_b[MAX_N][KB];
    for (int s = 0; s < N; s++) {
        int base = n * nb + s * (1 + 2 * KB);
        for (int q = 1; q < 1 + 2 * KB; q++) lo[base + q] = wlo[n + q], hi[base + q] = whi[n + q];
        sense[base] = SENSE_BINARY;
        if (delta[s] == FREE_MODE) {
            lo[base] = 0.0, hi[base] = 1.0;
            n_free++;
        } else {
            lo[base] = hi[base] = (double)delta[s];
        }
        double vmin = v0 - s * a_dn, vmax = v0 + s * a_up;
        for (int k = 0; k < KB; k++) {
            double vk = md->breakpoints[k];
            int ib = base + 1 + k, iz = base + 1 + KB + k;
            sense[ib] = SENSE_BINARY;
            fixed_b[s][k] = -1;
            if (s == 0 || vmax < vk || vmin >= vk) {
                double b = (s == 0 ? v0 >= vk : vmin >= vk) ? 1.0 : 0.0;
                fixed_b[s][k] = (signed char)b;
                lo[ib] = hi[ib] = b;
                if (s == 0) lo[iz] = hi[iz] = b * (v0 - vk);
                else if (b == 0.0) lo[iz] = hi[iz] = 0.0;
                else lo[iz] = -BIG, hi[iz] = BIG; /* z = v - vk by one equality row */
            } else {
                lo[ib] = 0.0, hi[ib] = 1.0;
                n_free++;
            }
        }
    }
    int row = nV;
    for (int s = 0; s < N; s++) {
        double rlo[NMLD], rhi[NMLD];
        for (int r = 0; r < NMLD; r++) {
            double off = 0.0;
            for (int j = 0; j < NX; j++) off += c->ex[r * NX + j] * fx[s * NX + j];
            rlo[r] = c->mlo[r] - off;
            rhi[r] = c->mhi[r] - off;
        }
        if (delta[s] != FREE_MODE) /* the delta rows come first */
            for (int r = 0; r < n; r++) rlo[r] = -INFINITY, rhi[r] = INFINITY;
        for (int k = 0; k < KB; k++) {
            if (fixed_b[s][k] < 0) continue;
            int r0 = n + 7 * k;
            double keep_hi = rhi[r0 + 2];
            for (int r = r0; r < r0 + 7; r++) rlo[r] = -INFINITY, rhi[r] = INFINITY;
            if (fixed_b[s][k] == 1 && s > 0) rlo[r0 + 2] = rhi[r0 + 2] = keep_hi;
        }
        for (int r = 0; r < NMLD; r++) {
            lo[row + r] = ato_max(rlo[r], -BIG);
            hi[row + r] = ato_min(rhi[r], BIG);
        }
        row += NMLD;
    }
    for (int s = 1; s <= N; s++) {
        for (int r = 0; r < NST; r++) {
            double off = 0.0;
            for (int j = 0; j < NX; j++) off += c->Fst[r * NX + j] * fx[s * NX + j];
            double flo = r < n - 1 ? -lim->coupler : -INFINITY;
            double fhi = r < n - 1 ? lim->coupler : lim->speed;
            lo[row + r] = ato_max(flo - off, -BIG);
            hi[row + r] = ato_min(fhi - off, BIG);
        }
        row += NST;
    }
    /* presolve: a row side no point of the variable box can violate is dropped */
    for (int r = 0; r < pb->n_rows; r++) {
        const double* a = pb->A + (size_t)r * nV;
        double pmax = 0.0, nmax = 0.0, pmin = 0.0, nmin = 0.0;
        for (int v = 0; v < nV; v++) {
            double ap = ato_max(a[v], 0.0), an = ato_min(a[v], 0.0);
            pmax += ap * hi[v];
            nmax += an * lo[v];
            pmin += ap * lo[v];
            nmin += an * hi[v];
        }
        if (pmin + nmin >= lo[nV + r]) lo[nV + r] = -BIG;
        if (pmax + nmax <= hi[nV + r]) hi[nV + r] = BIG;
    }
    return n_free;
}

static void linear_term(const law_core* c, const problem* pb, const double* fx,
                        const double* ref, const double* u_prev, double* f) {
    int nV = pb->nV;
    for (int v = 0; v < nV; v++) {
        double acc = 0.0;
        for (int s = 1; s <= pb->N; s++)
            for (int x = 0; x < NX; x++)
                acc += pb->Gq[((size_t)s * nV + v) * NX + x] * (fx[s * NX + x] - ref[s * NX + x]);
        f[v] = acc;
    }
    for (int i = 0; i < UNITS; i++) f[i] -= 2.0 * c->dr * u_prev[i];
    for (int q = 0; q < pb->n_bin; q++) {
        int s = pb->bin_stage[q], k = pb->bin_kind[q];
        double guess = 1.0;
        if (k >= 0) {
            double v = 0.0;
            for (int j = 0; j < NX; j++) v += c->c[j] * ref[s * NX + j];
            guess = v >= c->md->breakpoints[k] ? 1.0 : 0.0;
        }
        f[pb->bin_idx[q]] -= 2.0 * HY_EPS_REG * guess;
    }
}

/* one DAQP solve as the core's: fresh workspace set up with every binary declared, the
 * retry's settings, then updated with the event's f, bounds and senses */
static int daqp_once(const problem* pb, const double* f, double* lo, double* hi,
                     const int* sense, const hy_retry* retry, double* V, int* nodes) {
    int nV = pb->nV, m = nV + pb->n_rows;
    double* zeros = calloc(nV, sizeof(double));
    double* lo0 = malloc(sizeof(double) * m);
    double* hi0 = malloc(sizeof(double) * m);
    int* sense0 = calloc(m, sizeof(int));
    int* sense1 = malloc(sizeof(int) * m);
    double* lam = calloc(m, sizeof(double));
    double* fc = malloc(sizeof(double) * nV);
    memcpy(fc, f, sizeof(double) * nV);
    memcpy(sense1, sense, sizeof(int) * m);
    for (int q = 0; q < m; q++) lo0[q] = -BIG, hi0[q] = BIG;
    for (int q = 0; q < pb->n_bin; q++) {
        int i = pb->bin_idx[q];
        sense0[i] = SENSE_BINARY;
        lo0[i] = 0.0, hi0[i] = 1.0;
    }
    DAQPWorkspace* work = calloc(1, sizeof *work);
    allocate_daqp_settings(work);
    DAQPProblem qp = {nV, m, nV, pb->H, zeros, pb->A, hi0, lo0, sense0, NULL, 0, 0};
    c_float setup_time = 0.0;
    int flag = setup_daqp_main(&qp, work, &setup_time, 0);
    if (flag >= 0) {
        if (retry->cycle_tol >= 0) work->settings->cycle_tol = retry->cycle_tol;
        if (retry->pivot_tol >= 0) work->settings->pivot_tol = retry->pivot_tol;
        if (retry->primal_tol >= 0) work->settings->primal_tol = retry->primal_tol;
        DAQPProblem upd = qp;
        upd.f = fc, upd.bupper = hi, upd.blower = lo, upd.sense = sense1;
        daqp_update_ldp(DAQP_UPDATE_v | DAQP_UPDATE_d | DAQP_UPDATE_sense, work, &upd);
        DAQPResult res;
        memset(&res, 0, sizeof res);
        res.x = V;
        res.lam = lam;
        daqp_solve(&res, work);
        flag = res.exitflag;
        *nodes += res.nodes;
        free_daqp_workspace(work);
        free_daqp_ldp(work);
    }
    free(work);
    free(zeros); free(lo0); free(hi0); free(sense0); free(sense1); free(lam); free(fc);
    return flag;
}

static void solve_qp(const problem* pb, const double* f, const double* lo_in,
                     const double* hi_in, const int* sense, solve_result* out) {
    int nV = pb->nV, m = nV + pb->n_rows;
    out->feasible = 0, out->nodes = 0, out->cost = INFINITY;
    for (int q = 0; q < m; q++)
        if (lo_in[q] > hi_in[q] + 1e-9) {
            snprintf(out->status, sizeof out->status, "empty constraint set");
            return;
        }
    double* lo = malloc(sizeof(double) * m);
    double* hi = malloc(sizeof(double) * m);
    int flag = 0;
    for (int attempt = 0; attempt < HY_N_RETRIES; attempt++) {
        for (int q = 0; q < m; q++) lo[q] = lo_in[q], hi[q] = ato_max(hi_in[q], lo_in[q]);
        flag = daqp_once(pb, f, lo, hi, sense, &HY_RETRIES[attempt], out->V, &out->nodes);
        int finite = 1;
        for (int v = 0; v < nV; v++) finite &= isfinite(out->V[v]) != 0;
        if (flag == 1 && finite) {
            out->feasible = 1;
            if (attempt == 0) snprintf(out->status, sizeof out->status, "solved");
            else snprintf(out->status, sizeof out->status, "solved (retry %d)", attempt);
            break;
        }
    }
    free(lo);
    free(hi);
    if (!out->feasible) {
        snprintf(out->status, sizeof out->status, "exitflag %d", flag);
        return;
    }
    double cost = 0.0;
    for (int a = 0; a < nV; a++) {
        double hv = 0.0;
        for (int b = 0; b < nV; b++) hv += pb->H[(size_t)a * nV + b] * out->V[b];
        cost += 0.5 * out->V[a] * hv + f[a] * out->V[a];
    }
    out->cost = cost;
}

static void enumerate(const problem* pb, const double* f, const double* lo,
                      const double* hi, const int* sense, solve_result* best) {
    int nV = pb->nV, m = nV + pb->n_rows, idx[MAX_N * (1 + KB)], count = 0;
    for (int q = 0; q < pb->n_bin; q++)
        if (lo[pb->bin_idx[q]] < hi[pb->bin_idx[q]]) idx[count++] = pb->bin_idx[q];
    best->feasible = 0, best->nodes = 0, best->cost = INFINITY;
    snprintf(best->status, sizeof best->status, "infeasible");
    double* lo2 = malloc(sizeof(double) * m);
    double* hi2 = malloc(sizeof(double) * m);
    solve_result trial = {0, 0, 0.0, "", malloc(sizeof(double) * nV)};
    for (long bits = 0; bits < (1L << count); bits++) { /* itertools.product order */
        memcpy(lo2, lo, sizeof(double) * m);
        memcpy(hi2, hi, sizeof(double) * m);
        for (int j = 0; j < count; j++)
            lo2[idx[j]] = hi2[idx[j]] = (double)((bits >> (count - 1 - j)) & 1);
        solve_qp(pb, f, lo2, hi2, sense, &trial);
        if (trial.feasible && trial.cost < best->cost) { /* keep it: swap the buffers */
            double* spare = best->V;
            *best = trial;
            trial.V = spare;
        }
    }
    free(trial.V);
    free(lo2);
    free(hi2);
    size_t len = strlen(best->status);
    snprintf(best->status + len, sizeof best->status - len, " (enumerated)");
}

/* -- construction ------------------------------------------------------------------------- */
void law_free(law_core* c) {
    for (int q = 0; q < c->n_probs; q++) problem_free(c->probs[q]);
    free(c->probs);
    ato_profile_free(&c->profile);
    free(c);
}

static law_core* fail(law_core* c) {
    law_free(c);
    return NULL;
}

law_core* law_make(const ato_values* p, double t0, char* err, size_t n) {
    (void)t0;
    const double* v = p->v;
    char* const* s = p->s;
    law_core* c = calloc(1, sizeof(law_core));
    static const hybrid_vrs vrs = HYBRID_VRS;
    if (!hybrid_check(p, &vrs, &c->profile, err, n)) return fail(c);
    const char* config = s[ATO_VR_configuration];
    for (int q = 0; q < HY_N_MODELS; q++)
        if (strcmp(HY_MODELS[q].name, config) == 0) c->md = &HY_MODELS[q];
    if (!c->md) { /* the declared choices, then emu_config's number of cars */
        int cars = -1;
        char known[256] = "";
        for (int q = 0; q < HY_N_CONFIGS; q++) {
            if (strcmp(HY_CONFIGS[q].name, config) == 0) cars = HY_CONFIGS[q].cars;
            size_t len = strlen(known);
            snprintf(known + len, sizeof known - len, "%s'%s'", q ? ", " : "",
                     HY_CONFIGS[q].name);
        }
        if (cars >= 0)
            snprintf(err, n, "configuration = '%s' has %d cars, this controller has %d",
                     config, cars, UNITS);
        else
            snprintf(err, n, "configuration = '%s': must be one of %s", config, known);
        return fail(c);
    }
    const char* fixed[] = {"sample_time", "fit_speed_max"};
    const int fixed_vr[] = {ATO_VR_sample_time, ATO_VR_fit_speed_max};
    const double built[] = {HY_SAMPLE_TIME, HY_FIT_SPEED_MAX};
    for (int i = 0; i < 2; i++)
        if (v[fixed_vr[i]] != built[i]) {
            char a[40], b[40];
            snprintf(err, n, "%s = %s: the native FMU's control model is built for %s = %s "
                     "(zero-order hold and PWA fit at build time); another needs the Python "
                     "FMU", fixed[i], ato_repr(v[fixed_vr[i]], a), fixed[i],
                     ato_repr(built[i], b));
            return fail(c);
        }
    c->horizon = (int)v[ATO_VR_N];
    hybrid_blocks(s[ATO_VR_move_blocks], c->horizon, c->blocks, &c->n_blocks, err, n);
    c->sample_time = v[ATO_VR_sample_time];
    c->brake_from = v[ATO_VR_brake_from];
    c->brake_until_speed = v[ATO_VR_brake_until_speed];
    c->coupler_max = v[ATO_VR_coupler_force_max] / KN;
    c->speed_max = v[ATO_VR_speed_max];
    c->timetable = strcmp(s[ATO_VR_position_reference], "timetable") == 0;
    c->optimise = strcmp(s[ATO_VR_delta_mode], "optimise") == 0;
    c->v_lo = -10.0; /* chain_model's speed range */
    c->v_hi = ato_max(ato_max(100.0, v[ATO_VR_fit_speed_max]), v[ATO_VR_speed_max]) + 5.0;
    for (int i = 0; i < UNITS; i++) {
        c->q[i] = v[ATO_VR_q_speed];
        c->q[UNITS + i] = v[ATO_VR_q_position];
    }
    c->r = v[ATO_VR_R];
    c->dr = v[ATO_VR_dR];
    make_model(c);
    c->probs = malloc(sizeof(problem*));
    c->probs[0] = problem_make(c, c->blocks, c->n_blocks);
    c->n_probs = 1;
    c->st.delta = 1;
    return c;
}

ATO_LAW_PLAIN_STATE(st)

/* -- event -------------------------------------------------------------------------------- */
void law_outputs(const law_core* c, double* out) {
    const hybrid_state* st = &c->st;
    double total = 0.0;
    for (int i = 0; i < UNITS; i++) {
        out[ATO_VR_force_1 + i] = st->forces[i];
        total += st->forces[i];
    }
    out[ATO_VR_force_demand] = total;
    out[ATO_VR_delta] = (double)st->delta;
    out[ATO_VR_v_ref] = st->v_ref;
    out[ATO_VR_s_ref] = st->s_ref;
    out[ATO_VR_speed_error] = st->speed_error;
    out[ATO_VR_qp_solves] = st->qp_solves;
    out[ATO_VR_qp_infeasible] = st->qp_infeasible;
    out[ATO_VR_qp_rescued] = st->qp_rescued;
    out[ATO_VR_bnb_nodes] = st->nodes;
}

/* HybridMpc.schedule: delta per stage */
static void schedule(law_core* c, double t, double v_mean, int* delta) {
    if (c->optimise) {
        for (int s = 0; s < c->horizon; s++) delta[s] = FREE_MODE;
        return;
    }
    if (t >= c->brake_from && v_mean <= c->brake_until_speed) c->st.braking_done = 1;
    for (int s = 0; s < c->horizon; s++) {
        double ts = t + s * c->sample_time;
        int braking = ts >= c->brake_from && !c->st.braking_done &&
                      (s == 0 || ato_profile_speed(&c->profile, ts) > c->brake_until_speed);
        delta[s] = braking ? 0 : 1;
    }
}

int law_compute(law_core* c, double t, const ato_values* p, double* out, char* err, size_t n) {
    (void)err; (void)n;
    hybrid_state* st = &c->st;
    const double* in = p->v;
    const hy_model* md = c->md;
    /* HybridMpc.state_vector */
    double x0[NX] = {0};
    for (int i = 0; i < UNITS; i++) x0[i] = in[ATO_VR_v_1 + i];
    for (int j = 0; j < UNITS - 1; j++) {
        double f = in[ATO_VR_coupler_force_1 + j];
        x0[UNITS + j + 1] = x0[UNITS + j] - (f - md->d * (x0[j] - x0[j + 1])) / md->k;
    }
    limits lim;
    for (int i = 0; i < UNITS; i++) {
        lim.traction[i] = ato_max(in[ATO_VR_traction_limit_1 + i], 0.0) / KN;
        lim.brake[i] = ato_max(in[ATO_VR_brake_limit_1 + i], 0.0) / KN;
    }
    lim.coupler = c->coupler_max;
    lim.speed = c->speed_max;
    double v_mean = 0.0;
    for (int j = 0; j < NX; j++) v_mean += c->c[j] * x0[j];
    int delta[MAX_N];
    schedule(c, t, v_mean, delta);
    /* HybridMpc.references */
    int N = c->horizon;
    double* ref = malloc(sizeof(double) * (N + 1) * NX);
    double origin = c->timetable ? in[ATO_VR_s] : ato_profile_position(&c->profile, t);
    for (int s = 0; s <= N; s++) {
        double ts = t + s * c->sample_time;
        double vs = ato_profile_speed(&c->profile, ts);
        double xs = ato_profile_position(&c->profile, ts) - origin;
        for (int i = 0; i < UNITS; i++) ref[s * NX + i] = vs, ref[s * NX + UNITS + i] = xs;
    }
    /* HybridMiqp.solve */
    problem* pb = for_modes(c, delta);
    int nV = pb->nV, m = nV + pb->n_rows;
    double* fx = malloc(sizeof(double) * (N + 1) * NX);
    double* f = malloc(sizeof(double) * nV);
    double* lo = malloc(sizeof(double) * m);
    double* hi = malloc(sizeof(double) * m);
    int* sense = malloc(sizeof(int) * m);
    double u_prev[UNITS];
    for (int i = 0; i < UNITS; i++) u_prev[i] = st->forces[i] / KN;
    free_response(pb, x0, fx);
    linear_term(c, pb, fx, ref, u_prev, f);
    int n_free = bounds(c, pb, x0, fx, &lim, delta, lo, hi, sense);
    solve_result res = {0, 0, 0.0, "", malloc(sizeof(double) * nV)};
    solve_qp(pb, f, lo, hi, sense, &res);
    if (!res.feasible && n_free > 0 && n_free <= HY_ENUMERATE_MAX_FREE)
        enumerate(pb, f, lo, hi, sense, &res);
    /* HybridMpc.compute */
    st->qp_solves += 1.0;
    st->nodes += res.nodes;
    double u[UNITS];
    int d0;
    if (res.feasible) {
        st->qp_rescued += strcmp(res.status, "solved") != 0;
        for (int i = 0; i < UNITS; i++) u[i] = res.V[i]; /* the first stage's block is 0 */
        st->plan_len = N - 1;
        st->plan_pos = 0;
        for (int s = 1; s < N; s++)
            for (int i = 0; i < UNITS; i++)
                st->plan[s - 1][i] = res.V[UNITS * pb->stage_block[s] + i];
        d0 = (int)nearbyint(res.V[UNITS * pb->nb]);
    } else {
        st->qp_infeasible += 1.0;
        st->has_failure = 1;
        st->failure_time = t;
        snprintf(st->failure, sizeof st->failure, "%s", res.status);
        if (st->plan_pos < st->plan_len) {
            for (int i = 0; i < UNITS; i++) u[i] = st->plan[st->plan_pos][i];
            st->plan_pos++;
        } else {
            for (int i = 0; i < UNITS; i++) u[i] = st->forces[i] / KN;
        }
        d0 = delta[0] == FREE_MODE ? 1 : delta[0];
    }
    for (int i = 0; i < UNITS; i++) /* project onto the mode */
        u[i] = d0 == 1 ? (md->motored[i] != 0.0 ? ato_max(u[i], 0.0) : 0.0)
                       : ato_min(u[i], 0.0);
    st->delta = d0;
    for (int i = 0; i < UNITS; i++) st->forces[i] = u[i] * KN;
    st->v_ref = ato_profile_speed(&c->profile, t);
    st->s_ref = ato_profile_position(&c->profile, t);
    double vm = 0.0;
    for (int i = 0; i < UNITS; i++) vm += c->c[i] * in[ATO_VR_v_1 + i];
    st->speed_error = vm - st->v_ref;
    free(ref); free(fx); free(f); free(lo); free(hi); free(sense); free(res.V);
    law_outputs(c, out);
    return 1;
}
