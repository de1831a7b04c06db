/*
 * ffdl_ismpc.c: online law of EmuIsmpc3, the C twin of controllers/datadriven/laws.py Ismpc
 * behind emu_control.py EmuIsmpc (seed-001 FFDL-ISMPC, eqs. 52-75): the sliding surface and
 * equivalent control of sliding.h, and the first move of the N-step MPC on s:
 *
 *   S = Lambda s(t) + Theta U -/+ Psi P_hat,   min ||S||^2 + theta ||U||^2
 *   subject to lo - base <= sum_{j<=k} U_j <= hi - base,  base = u(t-1) + du_eq
 *
 * The unconstrained minimiser (eq. 72) is taken when it keeps the box: in the eigenvectors Q
 * of tril'tril (N x N, fixed; ato_sym_eigen) and the kept right singular vectors V of Phi_2
 * (ato_truncated_svd), X = -Q ((Q' G V) / (lambda_tt sv^2 + theta)) V', G the stages' gradient
 * Theta'(Lambda s - Psi P). Otherwise the QP in the cumulated moves z (simple bounds):
 *
 *   min 1/2 z'Hz + q'z,  H = 2 (I_N (x) Phi_2'Phi_2) + 2 theta (D'D (x) I_n),
 *   q = 2 vec(offset Phi_2),  offset_k = s -/+ k p_hat
 *
 * is solved by DAQP (daqp_quadprog, default settings, its active set started from the signs
 * of the previous plan's duals shifted by one stage: controllers/common/qp.py DenseQP), built
 * from the sources of its registry distribution at build time (cosim/build/solvers.py).
 * theta is rescaled to the units of y and u (x (gy / gu)^2).
 *
 * State: the drive's (datadriven.h), the sliding law's (sliding.h: estimator, u, E, F,
 * s), then warm_dual (N n), qp_solves, qp_failures: Ismpc.state_fields in order.
 */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "api.h"
#include "linalg.h"
#include "sliding.h"

#define NU DD_N

struct law_core {
    dd_drive drive;
    sliding law;
    double theta, p_hat_sign;
    int hz, nz, clip, count;
    double* st;
    double *warm_dual, *qp_solves, *qp_failures;
    /* fixed by the parameters: eigen-decomposition of tril'tril (eig, vec: columns), the
     * move weight 2 theta (D'D (x) I_n) */
    double *tt_eig, *tt_vec, *move_weight;
    /* work arrays of one sample */
    double *offset, *tails, *grad, *a1, *a2, *X, *H, *q, *lo, *hi, *z, *lam;
    int* sense;
};

static law_core* fail(law_core* c) {
    law_free(c);
    return NULL;
}

law_core* law_make(const ato_values* p, double t0, char* err, size_t n) {
    (void)t0;
    const double* v = p->v;
    const char* constraints = p->s[ATO_VR_constraints];
    const char* prediction = p->s[ATO_VR_error_prediction];
    /* IsmpcParams.check: the declared choices */
    if (strcmp(constraints, "qp") != 0 && strcmp(constraints, "clip") != 0) {
        snprintf(err, n, "constraints = '%s': must be one of 'qp', 'clip'", constraints);
        return NULL;
    }
    double sign = strcmp(prediction, "eq78") == 0 ? -1.0 : strcmp(prediction, "eq72") == 0 ? 1.0
                  : strcmp(prediction, "off") == 0 ? 0.0 : NAN; /* laws.py P_HAT_SIGN */
    if (isnan(sign)) {
        snprintf(err, n, "error_prediction = '%s': must be one of 'eq78', 'eq72', 'off'",
                 prediction);
        return NULL;
    }
    law_core* c = calloc(1, sizeof *c);
    if (!dd_drive_make(&c->drive, p, err, n)) {
        free(c);
        return NULL;
    }
    sliding_read(&c->law, v);
    double g = (v[ATO_VR_output_scale] / DD_KMH_PER_MPS) / v[ATO_VR_input_scale]; /* rescaled */
    c->theta = (v[ATO_VR_theta] * g) * g;
    c->p_hat_sign = sign;
    c->clip = strcmp(constraints, "clip") == 0;
    int hz = c->hz = (int)v[ATO_VR_N], nz = c->nz = hz * NU;
    c->count = DD_DRIVE_STATE + sliding_state_count(&c->law) + nz + 2;
    c->st = calloc(c->count, sizeof(double));
    sliding_bind(&c->law, c->st + DD_DRIVE_STATE);
    c->warm_dual = c->st + DD_DRIVE_STATE + sliding_state_count(&c->law);
    c->qp_solves = c->warm_dual + nz;
    c->qp_failures = c->qp_solves + 1;
    c->tt_eig = malloc(sizeof(double) * hz);
    c->tt_vec = malloc(sizeof(double) * hz * hz);
    c->move_weight = malloc(sizeof(double) * nz * nz);
    double** work[] = {&c->offset, &c->tails, &c->grad, &c->a1, &c->a2, &c->X, &c->q, &c->lo,
                       &c->hi, &c->z, &c->lam};
    for (size_t i = 0; i < sizeof work / sizeof *work; i++) *work[i] = malloc(sizeof(double) * nz);
    c->H = malloc(sizeof(double) * nz * nz);
    c->sense = malloc(sizeof(int) * nz);
    /* tril'tril: (k, l) -> N - max(k, l) (exact); D = tril^-1 the first differences, D'D
     * tridiagonal (2, ..., 2, 1 on the diagonal, -1 beside it) */
    double* tt = malloc(sizeof(double) * hz * hz);
    for (int k = 0; k < hz; k++)
        for (int l = 0; l < hz; l++) tt[k * hz + l] = hz - (k > l ? k : l);
    int sweeps = ato_sym_eigen(tt, hz, c->tt_eig, c->tt_vec);
    free(tt);
    if (sweeps < 0) {
        snprintf(err, n, "N = %d: the eigen-decomposition of tril'tril did not converge", hz);
        return fail(c);
    }
    double w2 = 2.0 * c->theta;
    for (int a = 0; a < hz; a++)
        for (int i = 0; i < NU; i++)
            for (int b = 0; b < hz; b++)
                for (int j = 0; j < NU; j++) {
                    double dtd = a == b ? (a == hz - 1 ? 1.0 : 2.0)
                                 : (a - b == 1 || b - a == 1) ? -1.0 : 0.0;
                    c->move_weight[(a * NU + i) * nz + b * NU + j] = w2 * (dtd * (i == j));
                }
    return c;
}

void law_free(law_core* c) {
    if (!c) return;
    dd_drive_free(&c->drive);
    free(c->st); free(c->tt_eig); free(c->tt_vec); free(c->move_weight);
    free(c->offset); free(c->tails); free(c->grad); free(c->a1); free(c->a2); free(c->X);
    free(c->q); free(c->lo); free(c->hi); free(c->z); free(c->lam); free(c->H); free(c->sense);
    free(c);
}

DD_LAW_STATE_IMAGE

void law_outputs(const law_core* c, double* out) {
    dd_outputs(c->st, out);
    out[ATO_VR_qp_solves] = *c->qp_solves;
    out[ATO_VR_qp_infeasible] = *c->qp_failures;
}

/* DenseQP.solve (simple bounds only): z and the duals into c->z, c->lam; 0 when DAQP did not
 * solve it (exitflag < 1) or z is not finite */
static int dense_qp(law_core* c) {
    int nz = c->nz;
    for (int i = 0; i < nz; i++) {
        c->sense[i] = 0;
        double hi = c->hi[i], lo = c->lo[i]; /* numpy.maximum(hi, lo) */
        c->hi[i] = isnan(hi) || isnan(lo) ? hi + lo : (lo > hi ? lo : hi);
    }
    DAQPProblem qp = {0};
    qp.n = nz;
    qp.m = qp.ms = nz;
    qp.H = c->H;
    qp.f = c->q;
    qp.A = NULL;
    qp.bupper = c->hi;
    qp.blower = c->lo;
    qp.sense = c->sense;
    DAQPSettings settings;
    daqp_default_settings(&settings);
    DAQPResult res = {0};
    res.x = c->z;
    res.lam = c->lam;
    daqp_dual_init_active(&qp, c->warm_dual);
    daqp_quadprog(&res, &qp, &settings);
    if (res.exitflag < 1) return 0;
    for (int i = 0; i < nz; i++)
        if (!isfinite(c->z[i])) return 0;
    return 1;
}

/* Ismpc.mpc_moves: the first move U_0 into u0 (the plan's later moves are not used) */
static void mpc_moves(law_core* c, const double* lo_cum, const double* hi_cum, double* u0) {
    sliding* law = &c->law;
    int hz = c->hz, nz = c->nz, kept = law->kept;
    const double* M = law->M;
    double p_hat[NU];
    for (int i = 0; i < NU; i++)
        p_hat[i] = c->p_hat_sign * (law->est.dd_hat[i] - law->est.dd_hat_prev[i]);
    for (int k = 0; k < hz; k++)
        for (int i = 0; i < NU; i++)
            c->offset[k * NU + i] = law->s[i] + (k + 1.0) * p_hat[i];
    for (int k = hz - 1; k >= 0; k--) /* sum_{k' >= k} offset_k' */
        for (int i = 0; i < NU; i++)
            c->tails[k * NU + i] = k == hz - 1 ? c->offset[k * NU + i]
                                   : c->tails[(k + 1) * NU + i] + c->offset[k * NU + i];
    for (int k = 0; k < hz; k++) /* grad = tails Phi_2 */
        for (int j = 0; j < NU; j++) {
            double s = 0.0;
            for (int i = 0; i < NU; i++) s += c->tails[k * NU + i] * M[i * NU + j];
            c->grad[k * NU + j] = s;
        }
    /* X = -(Q (((Q' grad) V) * inv) V') */
    const double *Q = c->tt_vec, *vt = law->vt;
    for (int a = 0; a < hz; a++)
        for (int j = 0; j < NU; j++) {
            double s = 0.0;
            for (int k = 0; k < hz; k++) s += Q[k * hz + a] * c->grad[k * NU + j];
            c->a1[a * NU + j] = s;
        }
    for (int a = 0; a < hz; a++)
        for (int l = 0; l < kept; l++) {
            double s = 0.0;
            for (int j = 0; j < NU; j++) s += c->a1[a * NU + j] * vt[l * NU + j];
            double den = c->tt_eig[a] * (law->sv[l] * law->sv[l]) + c->theta;
            c->a2[a * NU + l] = s * (den > 1e-12 ? 1.0 / den : 0.0);
        }
    for (int k = 0; k < hz; k++) {
        double row[NU];
        for (int l = 0; l < kept; l++) {
            double s = 0.0;
            for (int a = 0; a < hz; a++) s += Q[k * hz + a] * c->a2[a * NU + l];
            row[l] = s;
        }
        for (int j = 0; j < NU; j++) {
            double s = 0.0;
            for (int l = 0; l < kept; l++) s += row[l] * vt[l * NU + j];
            c->X[k * NU + j] = -s;
        }
    }
    int inside = 1;
    double cum[NU] = {0};
    for (int k = 0; k < hz && inside; k++)
        for (int i = 0; i < NU; i++) {
            cum[i] = k == 0 ? c->X[i] : cum[i] + c->X[k * NU + i];
            inside &= cum[i] >= lo_cum[i] && cum[i] <= hi_cum[i];
        }
    if (c->clip || inside) {
        for (int i = 0; i < NU; i++) u0[i] = c->X[i];
        memset(c->warm_dual, 0, sizeof(double) * nz); /* the zero duals shifted */
        return;
    }
    /* J = sum_k ||offset_k + Phi_2 z_k||^2 + theta ||D z||^2, lo_cum <= z_k <= hi_cum */
    double PtP[NU * NU];
    for (int i = 0; i < NU; i++)
        for (int j = 0; j < NU; j++) {
            double s = 0.0;
            for (int r = 0; r < NU; r++) s += M[r * NU + i] * M[r * NU + j];
            PtP[i * NU + j] = s;
        }
    for (int a = 0; a < hz; a++)
        for (int i = 0; i < NU; i++)
            for (int b = 0; b < hz; b++)
                for (int j = 0; j < NU; j++) {
                    int at = (a * NU + i) * nz + b * NU + j;
                    c->H[at] = 2.0 * ((a == b ? 1.0 : 0.0) * PtP[i * NU + j])
                               + c->move_weight[at];
                }
    for (int k = 0; k < hz; k++)
        for (int j = 0; j < NU; j++) {
            double s = 0.0;
            for (int i = 0; i < NU; i++) s += c->offset[k * NU + i] * M[i * NU + j];
            c->q[k * NU + j] = 2.0 * s;
            c->lo[k * NU + j] = lo_cum[j];
            c->hi[k * NU + j] = hi_cum[j];
        }
    int solved = dense_qp(c);
    *c->qp_solves += 1.0;
    if (!solved) {
        *c->qp_failures += 1.0;
        memset(c->warm_dual, 0, sizeof(double) * nz);
        for (int i = 0; i < NU; i++) u0[i] = 0.0;
        return;
    }
    for (int i = 0; i < NU; i++) u0[i] = c->z[i];
    /* warm start of the next solve: the plan's active constraints shifted by one stage */
    memcpy(c->warm_dual, c->lam + NU, sizeof(double) * (nz - NU));
    memset(c->warm_dual + nz - NU, 0, sizeof(double) * NU);
}

int law_compute(law_core* c, double t, const ato_values* p, double* out, char* err, size_t n) {
    (void)err; (void)n;
    dd_sample smp;
    sliding* law = &c->law;
    double du[NU];
    if (sliding_sample(law, &c->drive, t, p->v, &smp, du)) {
        double base[NU], lo_cum[NU], hi_cum[NU], u0[NU], want[NU];
        for (int i = 0; i < NU; i++) {
            base[i] = law->u[i] + du[i];
            lo_cum[i] = smp.lo[i] - base[i];
            hi_cum[i] = smp.hi[i] - base[i];
        }
        mpc_moves(c, lo_cum, hi_cum, u0);
        for (int i = 0; i < NU; i++) want[i] = base[i] + u0[i];
        sliding_finish(law, want, &smp);
    }
    dd_commit(&smp, law->u, c->st);
    law_outputs(c, out);
    return 1;
}
