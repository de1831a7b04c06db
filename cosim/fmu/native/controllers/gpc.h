/*
 * gpc.h: the GPC of controllers/common/gpc.py Gpc in C (emu_gpc.c for seed 001's EMU,
 * crh3_gpc.c for seed 003's CRH3): RLS with forgetting f on the incremental ARX model
 *
 *   dy(t) = sum_i A_i dy(t-i) + sum_j B_j du(t-j)          (n outputs, m inputs)
 *
 * (one covariance P, symmetrised, its trace capped at p_max; no update while |x| <=
 * excitation), and per sample the unclipped input u(t) = u(t-1) + du(t), du(t) the first
 * move of dU = (G'G + w I)^-1 G'(R - f) (free response f and step-response matrix G over Ny
 * samples and Nu moves, by simulating the model as Gpc._simulate). The core's scalar
 * operations in its order; products summed in index order and the solve by Gaussian
 * elimination (linalg.h), where numpy calls BLAS and LAPACK.
 *
 * State: Gpc.state_fields as doubles in the caller's array, gpc_state_count of them:
 * theta (n x n_reg, row-major), P (n_reg x n_reg), y_prev (n), dy_hist (na x n), du_hist
 * (nb x m), u_prev (m), started, updates.
 */
#ifndef ATO_GPC_H
#define ATO_GPC_H

#include <stddef.h>

/* GpcParams and the model's dimensions */
typedef struct gpc_params {
    int n, m, Ny, Nu, na, nb;
    double forgetting, weight, a_init, b_init, p0, p_max, excitation;
} gpc_params;

typedef struct gpc_core {
    gpc_params p;
    int nreg;
    double *theta, *P, *y_prev, *dy_hist, *du_hist, *u_prev, *started, *updates; /* state */
    /* scratch */
    double *G, *H, *f, *g, *refs, *sim_dy, *sim_du, *moves, *Px, *Pn, *x, *k, *dy, *tx, *y;
} gpc_core;

/* the gpc_params of the parameter values v of a law whose generated header declares
 * GpcParams' fields, for n outputs and m inputs */
#define GPC_PARAMS(v, n_out, m_in)                                                       \
    ((gpc_params){(n_out), (m_in), (int)(v)[ATO_VR_Ny], (int)(v)[ATO_VR_Nu],               \
                      (int)(v)[ATO_VR_na], (int)(v)[ATO_VR_nb], (v)[ATO_VR_forgetting],          \
                      (v)[ATO_VR_control_weight], (v)[ATO_VR_a_init], (v)[ATO_VR_b_init],          \
                      (v)[ATO_VR_p0], (v)[ATO_VR_p_max], (v)[ATO_VR_excitation]})

/* GpcParams.check_relations (Nu <= Ny); 0 after writing the core's message into err */
int gpc_check(const gpc_params* p, char* err, size_t err_size);

/* the number of state doubles of a GPC with these parameters */
int gpc_state_count(const gpc_params* p);
/* the GPC over the state array st (gpc_state_count doubles), set to Gpc's start */
void gpc_make(gpc_core* g, const gpc_params* p, double* st);
void gpc_free(gpc_core* g);
/* Gpc.observe: the measurement y(t) (n), one RLS step when adapt */
void gpc_observe(gpc_core* g, const double* y, int adapt);
/* Gpc.plan: the unclipped input u (m) for the references refs (Ny x n, row-major) of
 * y(t+1..t+Ny); 0 when G'G + w I is singular (numpy: "Singular matrix") */
int gpc_plan(gpc_core* g, const double* refs, double* u);
/* Gpc.applied: record the input u(t) (m) actually applied */
void gpc_applied(gpc_core* g, const double* u);

#endif
