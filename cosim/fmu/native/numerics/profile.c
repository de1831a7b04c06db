/* profile.c: reference profiles of the native controllers (see profile.h). */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "profile.h"

#include "bundled.h"

int ato_bisect_right(const double* xs, int n, double s) {
    int lo = 0, hi = n;
    while (lo < hi) {
        int mid = (lo + hi) / 2;
        if (s < xs[mid]) hi = mid; else lo = mid + 1;
    }
    return lo;
}

double ato_interp(double x, const double* xp, const double* fp, int n) {
    if (isnan(x)) return x;
    if (x < xp[0]) return fp[0];
    if (x > xp[n - 1]) return fp[n - 1];
    int j = ato_bisect_right(xp, n, x) - 1;
    if (j == n - 1 || xp[j] == x) return fp[j];
    double slope = (fp[j + 1] - fp[j]) / (xp[j + 1] - xp[j]);
    double r = slope * (x - xp[j]) + fp[j];
    if (isnan(r)) {
        r = slope * (x - xp[j + 1]) + fp[j + 1];
        if (isnan(r) && fp[j] == fp[j + 1]) r = fp[j];
    }
    return r;
}

double ato_profile_speed(const ato_profile* p, double x) {
    double f = ato_interp(x, p->x, p->f, p->n);
    if (p->distance) return sqrt(0.0 > f ? 0.0 : f); /* sqrt(max(f, 0.0)) */
    return f;
}

double ato_profile_accel(const ato_profile* p, double x) {
    if (x < p->x[0] || x >= p->x[p->n - 1]) return 0.0;
    return p->accel[ato_bisect_right(p->x, p->n, x) - 1];
}

double ato_profile_position(const ato_profile* p, double t) {
    const double *x = p->x, *v = p->v;
    int n = p->n;
    if (t <= x[0]) return v[0] * (t - x[0]);
    if (t >= x[n - 1]) return p->cum[n - 1] + v[n - 1] * (t - x[n - 1]);
    int i = ato_bisect_right(x, n, t) - 1;
    double dt = t - x[i];
    double a = (v[i + 1] - v[i]) / (x[i + 1] - x[i]);
    return p->cum[i] + v[i] * dt + 0.5 * a * dt * dt;
}

void ato_profile_free(ato_profile* p) {
    free(p->cum);
    free(p->x);
    free(p->v);
    free(p->f);
    free(p->accel);
    memset(p, 0, sizeof *p);
}

int ato_profile_load(ato_profile* p, const char* resources, const char* name, char* err,
                     size_t n_err) {
    memset(p, 0, sizeof *p);
    FILE* f = ato_open_bundled(resources, "references", name, "ref", "reference", err,
                               n_err);
    if (!f) return 0;
    int cap = 64, k = 0, kind = -1;
    p->x = malloc(cap * sizeof(double));
    p->v = malloc(cap * sizeof(double));
    char line[256], word[32];
    while (fgets(line, sizeof line, f)) {
        double a, b;
        if (line[0] == '#') continue;
        if (sscanf(line, "kind %31s", word) == 1) {
            kind = strcmp(word, "distance") == 0 ? 1 : strcmp(word, "time") == 0 ? 0 : -1;
            continue;
        }
        if (sscanf(line, "%lf %lf", &a, &b) != 2) continue;
        if (k == cap) {
            cap *= 2;
            p->x = realloc(p->x, cap * sizeof(double));
            p->v = realloc(p->v, cap * sizeof(double));
        }
        p->x[k] = a;
        p->v[k] = b;
        k++;
    }
    fclose(f);
    if (kind < 0 || k < 2) {
        snprintf(err, n_err, "reference = '%s': its bundled file has no kind line or fewer "
                 "than two points", name);
        ato_profile_free(p);
        return 0;
    }
    p->distance = kind;
    p->n = k;
    p->f = malloc(k * sizeof(double));
    p->accel = malloc((k - 1) * sizeof(double));
    p->cum = malloc(k * sizeof(double));
    p->cum[0] = 0.0; /* cumsum of (dx 0.5) (v_i + v_i+1), in order */
    for (int i = 0; i + 1 < k; i++)
        p->cum[i + 1] = p->cum[i] + (p->x[i + 1] - p->x[i]) * 0.5 * (p->v[i] + p->v[i + 1]);
    for (int i = 0; i < k; i++) p->f[i] = kind ? p->v[i] * p->v[i] : p->v[i];
    for (int i = 0; i + 1 < k; i++) {
        double dx = p->x[i + 1] - p->x[i];
        p->accel[i] = kind ? (p->f[i + 1] - p->f[i]) / (2.0 * dx) : (p->v[i + 1] - p->v[i]) / dx;
    }
    return 1;
}
