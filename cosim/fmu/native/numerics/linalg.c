/* linalg.c: see linalg.h. */
#include <float.h>
#include <math.h>
#include <string.h>

#include "linalg.h"

void ato_matvec(const double* a, int rows, int cols, const double* x, double* y) {
    for (int i = 0; i < rows; i++) {
        double s = 0.0;
        for (int j = 0; j < cols; j++) s += a[i * cols + j] * x[j];
        y[i] = s;
    }
}

int ato_sym_eigen(double* a, int n, double* w, double* v) {
    for (int i = 0; i < n; i++)
        for (int j = 0; j < n; j++) v[i * n + j] = i == j ? 1.0 : 0.0;
    int sweeps = 0, rotated = 1;
    while (rotated) {
        if (sweeps == 100) return -1;
        sweeps++;
        rotated = 0;
        for (int p = 0; p < n - 1; p++)
            for (int q = p + 1; q < n; q++) {
                double apq = a[p * n + q];
                double app = a[p * n + p], aqq = a[q * n + q];
                if (fabs(apq) <= 0.5 * DBL_EPSILON * sqrt(fabs(app * aqq))) {
                    a[p * n + q] = a[q * n + p] = 0.0; /* below the diagonal's rounding */
                    continue;
                }
                if (!isfinite(apq)) return -1;
                rotated = 1;
                /* the rotation J = [c s; -s c] on (p, q) with (J'AJ)_pq = 0 (Golub, Van
                 * Loan, Matrix Computations, sym.schur2): the smaller angle */
                double theta = (aqq - app) / (2.0 * apq);
                double t = (theta >= 0.0 ? 1.0 : -1.0) / (fabs(theta) + hypot(1.0, theta));
                double c = 1.0 / sqrt(1.0 + t * t), s = t * c;
                for (int k = 0; k < n; k++) { /* A J */
                    double akp = a[k * n + p], akq = a[k * n + q];
                    a[k * n + p] = c * akp - s * akq;
                    a[k * n + q] = s * akp + c * akq;
                }
                for (int k = 0; k < n; k++) { /* J' (A J) */
                    double apk = a[p * n + k], aqk = a[q * n + k];
                    a[p * n + k] = c * apk - s * aqk;
                    a[q * n + k] = s * apk + c * aqk;
                }
                a[p * n + q] = a[q * n + p] = 0.0;
                for (int k = 0; k < n; k++) { /* V J */
                    double vkp = v[k * n + p], vkq = v[k * n + q];
                    v[k * n + p] = c * vkp - s * vkq;
                    v[k * n + q] = s * vkp + c * vkq;
                }
            }
    }
    for (int i = 0; i < n; i++) w[i] = a[i * n + i];
    for (int i = 0; i < n - 1; i++) { /* largest first (selection sort, columns with them) */
        int best = i;
        for (int j = i + 1; j < n; j++)
            if (w[j] > w[best]) best = j;
        if (best == i) continue;
        double tw = w[i];
        w[i] = w[best];
        w[best] = tw;
        for (int k = 0; k < n; k++) {
            double tv = v[k * n + i];
            v[k * n + i] = v[k * n + best];
            v[k * n + best] = tv;
        }
    }
    return sweeps;
}

double ato_npclip(double x, double lo, double hi) {
    double a = isnan(x) || isnan(lo) ? x + lo : (lo > x ? lo : x);
    return isnan(a) || isnan(hi) ? a + hi : (hi < a ? hi : a);
}

void ato_truncated_gain(const double* m, int n, double eps, double cutoff, double* m_r,
                        double* k, int* kept) {
    double sv[ATO_LINALG_MAX], vt[ATO_LINALG_MAX * ATO_LINALG_MAX];
    ato_truncated_svd(m, n, eps, cutoff, m_r, k, sv, vt, kept);
}

void ato_truncated_svd(const double* m, int n, double eps, double cutoff, double* m_r,
                       double* k, double* kept_sv, double* vt, int* kept) {
    double a[ATO_LINALG_MAX * ATO_LINALG_MAX], v[ATO_LINALG_MAX * ATO_LINALG_MAX];
    double w[ATO_LINALG_MAX], sv[ATO_LINALG_MAX], col[ATO_LINALG_MAX], mv[ATO_LINALG_MAX];
    for (int i = 0; i < n; i++) /* M'M */
        for (int j = 0; j < n; j++) {
            double s = 0.0;
            for (int r = 0; r < n; r++) s += m[r * n + i] * m[r * n + j];
            a[i * n + j] = s;
        }
    if (ato_sym_eigen(a, n, w, v) < 0) { /* non-finite Phi_2: numpy's SVD gives NaN too */
        for (int i = 0; i < n * n; i++) m_r[i] = k[i] = NAN;
        *kept = 0;
        return;
    }
    for (int j = 0; j < n; j++) sv[j] = sqrt(w[j] > 0.0 ? w[j] : 0.0);
    memset(m_r, 0, sizeof(double) * n * n);
    memset(k, 0, sizeof(double) * n * n);
    *kept = 0;
    for (int j = 0; j < n; j++) {
        if (!(sv[j] >= cutoff * sv[0])) continue;
        kept_sv[*kept] = sv[j];
        for (int r = 0; r < n; r++) vt[*kept * n + r] = col[r] = v[r * n + j];
        ++*kept;
        ato_matvec(m, n, n, col, mv); /* M v_j = sigma_j u_j */
        double lam = w[j] > 0.0 ? w[j] : 0.0;
        double g = 1.0 / (lam + eps);
        for (int r = 0; r < n; r++)
            for (int c = 0; c < n; c++) {
                m_r[r * n + c] += mv[r] * col[c];
                k[r * n + c] += col[r] * (mv[c] * g);
            }
    }
}

int ato_solve(double* a, double* b, int n, double* x) {
    for (int col = 0; col < n; col++) {
        int piv = col;
        for (int r = col + 1; r < n; r++)
            if (fabs(a[r * n + col]) > fabs(a[piv * n + col])) piv = r;
        if (a[piv * n + col] == 0.0) return 0;
        if (piv != col) {
            for (int c = 0; c < n; c++) {
                double t = a[col * n + c];
                a[col * n + c] = a[piv * n + c];
                a[piv * n + c] = t;
            }
            double t = b[col];
            b[col] = b[piv];
            b[piv] = t;
        }
        for (int r = col + 1; r < n; r++) {
            double f = a[r * n + col] / a[col * n + col];
            for (int c = col + 1; c < n; c++) a[r * n + c] -= f * a[col * n + c];
            b[r] -= f * b[col];
        }
    }
    for (int r = n - 1; r >= 0; r--) {
        double s = b[r];
        for (int c = r + 1; c < n; c++) s -= a[r * n + c] * x[c];
        x[r] = s / a[r * n + r];
    }
    return 1;
}

void ato_null_space_share(const double* u, const double* m, const double* k, int n,
                          double gain, double* out) {
    double dev[ATO_LINALG_MAX], md[ATO_LINALG_MAX], kmd[ATO_LINALG_MAX], sum = 0.0;
    for (int i = 0; i < n; i++) sum += u[i];
    for (int i = 0; i < n; i++) dev[i] = u[i] - sum / n;
    ato_matvec(m, n, n, dev, md);
    ato_matvec(k, n, n, md, kmd);
    for (int i = 0; i < n; i++) out[i] = gain * (dev[i] - kmd[i]);
}
