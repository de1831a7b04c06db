/*
 * linalg.h: the small dense linear algebra of the data-driven controllers (ffdl_mfac.c,
 * ffdl_ismc.c, ffdl_ismpc.c, emu_gpc.c), row-major n x n matrices, sums in index order.
 *
 * ato_truncated_gain is controllers/common/ffdl.py truncated_gain without forming U: with
 * M'M = V diag(lambda) V' (cyclic Jacobi, ato_sym_eigen) and sigma_j = sqrt(lambda_j), the
 * kept directions (sigma_j >= cutoff sigma_1) give
 *
 *   M_r = sum_j (M v_j) v_j',   K = sum_j v_j (M v_j)' / (lambda_j + eps)
 *
 * which equal U_r diag(sigma) V_r' and V_r diag(sigma / (sigma^2 + eps)) U_r' (sigma_j u_j =
 * M v_j) and need no division by a small sigma. Both depend on the kept subspace only, not on
 * the basis chosen inside a repeated singular value.
 */
#ifndef ATO_LINALG_H
#define ATO_LINALG_H

#define ATO_LINALG_MAX 64 /* largest n of ato_sym_eigen / ato_truncated_gain */

/* Eigen-decomposition of the symmetric n x n matrix a (destroyed): eigenvalues in w (largest
 * first), eigenvectors in the columns of v (row-major n x n); cyclic Jacobi rotations until a
 * sweep finds every off-diagonal entry below DBL_EPSILON / 2 sqrt(|a_pp a_qq|). Returns the
 * number of sweeps, or -1 when 100 sweeps did not converge (a non-finite entry). */
int ato_sym_eigen(double* a, int n, double* w, double* v);

/* M_r and K (n x n) of the n x n matrix m: see above; kept: the number of kept directions. */
void ato_truncated_gain(const double* m, int n, double eps, double cutoff, double* m_r,
                        double* k, int* kept);
/* the same, and truncated_gain's sv (the kept singular values, largest first) and Vt (the
 * kept right singular vectors as rows, kept x n, row-major) */
void ato_truncated_svd(const double* m, int n, double eps, double cutoff, double* m_r,
                       double* k, double* sv, double* vt, int* kept);

/* x = A^-1 b by Gaussian elimination with partial pivoting (LAPACK dgesv's pivot choice: the
 * first largest |entry|); a (n x n) and b are destroyed, x may be b. Returns 0 when a pivot is
 * exactly zero (numpy.linalg.solve: "Singular matrix"). */
int ato_solve(double* a, double* b, int n, double* x);

/* out = gain (dev - K (M dev)), dev = u - mean(u): controllers/datadriven/laws.py
 * null_space_share (the move that moves only the force split between the units). */
void ato_null_space_share(const double* u, const double* m, const double* k, int n,
                          double gain, double* out);

/* numpy.clip(x, lo, hi) of one value: max(x, lo), then min(., hi), a NaN propagated */
double ato_npclip(double x, double lo, double hi);

/* y = A x (A: rows x cols, row-major) */
void ato_matvec(const double* a, int rows, int cols, const double* x, double* y);

#endif
