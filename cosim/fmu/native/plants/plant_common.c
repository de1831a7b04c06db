/* plant_common.c: route profiles of the native plants (see plant_common.h). */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "plant_common.h"

#include "bundled.h"

static double from_bits(const char* hex, char** end) {
    unsigned long long bits = strtoull(hex, end, 16);
    double d;
    memcpy(&d, &bits, sizeof d);
    return d;
}

void ato_profile_free(ato_profile* p) {
    free(p->starts);
    free(p->values);
    p->starts = p->values = NULL;
    p->n = 0;
}

void ato_route_free(ato_route* r) {
    ato_profile_free(&r->grade);
    ato_profile_free(&r->curve_resistance);
    ato_profile_free(&r->tunnel_resistance);
    ato_profile_free(&r->speed_limit);
    ato_profile_free(&r->neutral);
}

int ato_route_load(ato_inst* m, const char* route, ato_route* out) {
    memset(out, 0, sizeof *out);
    char err[512];
    FILE* f = ato_open_bundled(m->resources, "routes", route, "profiles", "route", err,
                               sizeof err);
    if (!f) {
        ATO_ERROR(m, "bad parameter: %s", err);
        return 0;
    }
    struct { const char* name; ato_profile* p; } fields[] = {
        {"grade", &out->grade}, {"curve_resistance", &out->curve_resistance},
        {"tunnel_resistance", &out->tunnel_resistance}, {"speed_limit", &out->speed_limit},
        {"neutral", &out->neutral}};
    char line[512];
    ato_profile* cur = NULL;
    int filled = 0, ok = 1;
    while (ok && fgets(line, sizeof line, f)) {
        if (line[0] == '#' || line[0] == '\n') continue;
        if (strncmp(line, "profile ", 8) == 0) {
            char name[64];
            int count = 0;
            cur = NULL;
            if (sscanf(line + 8, "%63s %d", name, &count) == 2 && count > 0)
                for (size_t i = 0; i < sizeof fields / sizeof fields[0]; i++)
                    if (strcmp(name, fields[i].name) == 0) cur = fields[i].p;
            if (cur) {
                cur->starts = malloc((size_t)count * sizeof(double));
                cur->values = malloc((size_t)count * sizeof(double));
                cur->n = 0;
                filled++;
                /* read the rows */
                for (int k = 0; k < count; k++) {
                    char* end;
                    if (!fgets(line, sizeof line, f)) { ok = 0; break; }
                    cur->starts[k] = from_bits(line, &end);
                    cur->values[k] = from_bits(end, &end);
                    cur->n = k + 1;
                }
            }
        }
    }
    fclose(f);
    if (!ok || filled != (int)(sizeof fields / sizeof fields[0])) {
        ATO_ERROR(m, "bad parameter: route = '%s': its bundled file is not a complete route "
                  "profile file", route);
        ato_route_free(out);
        return 0;
    }
    return 1;
}

int ato_profile_index(const ato_profile* p, double s) {
    int lo = 0, hi = p->n;
    while (lo < hi) {
        int mid = (lo + hi) / 2;
        if (s < p->starts[mid]) hi = mid; else lo = mid + 1;
    }
    return lo - 1;
}

double ato_profile_at(const ato_profile* p, double s) {
    return p->values[ato_profile_index(p, s)];
}

static int cmp_double(const void* a, const void* b) {
    double x = *(const double*)a, y = *(const double*)b;
    return x < y ? -1 : x > y;
}

void ato_profile_sum(const ato_profile* const* ps, int k, ato_profile* out) {
    int total = 0;
    for (int i = 0; i < k; i++) total += ps[i]->n - 1;
    double* finite = malloc((size_t)(total + 1) * sizeof(double));
    int n = 0;
    for (int i = 0; i < k; i++)
        for (int j = 1; j < ps[i]->n; j++) finite[n++] = ps[i]->starts[j];
    qsort(finite, (size_t)n, sizeof(double), cmp_double);
    out->starts = malloc((size_t)(n + 1) * sizeof(double));
    out->values = malloc((size_t)(n + 1) * sizeof(double));
    out->starts[0] = -INFINITY;
    int u = 1;
    for (int j = 0; j < n; j++) /* np.unique */
        if (u == 1 || finite[j] != out->starts[u - 1]) out->starts[u++] = finite[j];
    out->n = u;
    free(finite);
    for (int j = 0; j < u; j++) { /* values = zeros; values += p.at_array(starts) per p */
        double acc = 0.0;
        for (int i = 0; i < k; i++) acc += ato_profile_at(ps[i], out->starts[j]);
        out->values[j] = acc;
    }
}

void ato_cumulative_of(const ato_profile* p, ato_cumulative* out) {
    int nf = p->n - 1;
    if (nf == 0) {
        out->n = 2;
        out->xs = malloc(2 * sizeof(double));
        out->cum = malloc(2 * sizeof(double));
        out->xs[0] = -1e9;
        out->xs[1] = 1e9;
        out->cum[0] = out->xs[0] * p->values[0];
        out->cum[1] = out->xs[1] * p->values[0];
        return;
    }
    int n = nf + 2;
    out->n = n;
    out->xs = malloc((size_t)n * sizeof(double));
    out->cum = malloc((size_t)n * sizeof(double));
    out->xs[0] = p->starts[1] - 1e7;
    for (int j = 0; j < nf; j++) out->xs[j + 1] = p->starts[j + 1];
    out->xs[n - 1] = p->starts[nf] + 1e7;
    out->cum[0] = 0.0;
    for (int j = 0; j < n - 1; j++) /* cumsum of diff(xs) * values, left to right */
        out->cum[j + 1] = j == 0 ? (out->xs[1] - out->xs[0]) * p->values[0]
                                 : out->cum[j] + (out->xs[j + 1] - out->xs[j]) * p->values[j];
}

void ato_cumulative_free(ato_cumulative* c) {
    free(c->xs);
    free(c->cum);
    c->xs = c->cum = NULL;
}

double ato_interp(const ato_cumulative* c, double x) {
    const double* xs = c->xs;
    const double* ys = c->cum;
    int n = c->n;
    if (x < xs[0]) return ys[0];
    if (x >= xs[n - 1]) return ys[n - 1];
    int lo = 0, hi = n; /* bisect_right(xs, x) - 1 */
    while (lo < hi) {
        int mid = (lo + hi) / 2;
        if (x < xs[mid]) hi = mid; else lo = mid + 1;
    }
    int j = lo - 1;
    if (xs[j] == x) return ys[j];
    return (ys[j + 1] - ys[j]) / (xs[j + 1] - xs[j]) * (x - xs[j]) + ys[j];
}

double ato_mean_over(const ato_cumulative* c, double front, double length) {
    return (ato_interp(c, front) - ato_interp(c, front - length)) / length;
}
