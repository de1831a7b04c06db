/* grade.c: the bundled route grades a controller reads (grade.h) */
#include "grade.h"

#include "bundled.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>

int ato_grade_load(const char* resources, const char* route, ato_grade* out, char* err,
                   size_t n) {
    FILE* f = ato_open_bundled(resources, "routes", route, "grade", "route", err, n);
    if (!f) return 0;
    char line[256];
    int cap = 16;
    out->n = 0;
    out->starts = malloc(sizeof(double) * cap);
    out->values = malloc(sizeof(double) * cap);
    while (fgets(line, sizeof line, f)) {
        if (line[0] == '#') continue;
        double a, v;
        if (sscanf(line, "%lf %lf", &a, &v) != 2) continue;
        if (out->n == cap) {
            cap *= 2;
            out->starts = realloc(out->starts, sizeof(double) * cap);
            out->values = realloc(out->values, sizeof(double) * cap);
        }
        out->starts[out->n] = a;
        out->values[out->n++] = v;
    }
    fclose(f);
    return out->n > 0;
}

void ato_grade_free(ato_grade* g) {
    free(g->starts);
    free(g->values);
    g->starts = g->values = NULL;
    g->n = 0;
}

double ato_grade_at(const ato_grade* g, double s) {
    int lo = 0, hi = g->n;
    while (lo < hi) {
        int mid = (lo + hi) / 2;
        if (s < g->starts[mid]) hi = mid; else lo = mid + 1;
    }
    return g->values[lo - 1 < 0 ? 0 : lo - 1];
}

double ato_grade_accel(const ato_grade* g, double s) {
    return ATO_GRADE_GRAVITY * ato_grade_at(g, s) / 1000.0;
}
