/* hybrid.c: see hybrid.h */
#include "hybrid.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>

int hybrid_blocks(const char* text, int horizon, int* blocks, int* count, char* err,
                      size_t n) {
    const char* q = text;
    while (*q == ' ' || *q == '\t') q++;
    if (!*q) {
        for (int i = 0; i < horizon; i++) blocks[i] = 1;
        *count = horizon;
        return 1;
    }
    long sum = 0;
    int positive = 1, k = 0;
    const char* p = text;
    for (;;) {
        char* end;
        while (*p == ' ' || *p == '\t') p++;
        long b = strtol(p, &end, 10);
        if (end == p) {
            snprintf(err, n, "move_blocks = '%s': expected lengths like '3:4:3'", text);
            return 0;
        }
        p = end;
        while (*p == ' ' || *p == '\t') p++;
        positive &= b >= 1;
        sum += b;
        if (k < horizon) blocks[k] = (int)b;
        k++;
        if (!*p) break;
        if (*p != ':' && *p != ',') {
            snprintf(err, n, "move_blocks = '%s': expected lengths like '3:4:3'", text);
            return 0;
        }
        p++;
    }
    if (!positive || sum != horizon) {
        snprintf(err, n, "move_blocks = '%s': positive lengths summing to N = %d", text,
                 horizon);
        return 0;
    }
    *count = k;
    return 1;
}

int hybrid_check(const ato_values* p, const hybrid_vrs* vr, ato_profile* profile,
                     char* err, size_t n) {
    const double* v = p->v;
    char* const* s = p->s;
    int horizon = (int)v[vr->N];
    int* blocks = malloc((horizon > 0 ? horizon : 1) * sizeof(int));
    int count = 0;
    int ok = hybrid_blocks(s[vr->move_blocks], horizon, blocks, &count, err, n);
    free(blocks);
    if (!ok) return 0;
    const char* posref = s[vr->position_reference];
    if (strcmp(posref, "horizon") != 0 && strcmp(posref, "timetable") != 0) {
        snprintf(err, n, "position_reference = '%s': must be one of 'horizon', 'timetable'",
                 posref);
        return 0;
    }
    const char* dmode = s[vr->delta_mode];
    if (strcmp(dmode, "schedule") != 0 && strcmp(dmode, "optimise") != 0) {
        snprintf(err, n, "delta_mode = '%s': must be one of 'schedule', 'optimise'", dmode);
        return 0;
    }
    const char* nonneg[] = {"q_speed", "q_position"};
    const int nonneg_vr[] = {vr->q_speed, vr->q_position};
    for (int i = 0; i < 2; i++)
        if (!(v[nonneg_vr[i]] >= 0)) {
            char a[40];
            snprintf(err, n, "%s = %s must be >= 0", nonneg[i], ato_repr(v[nonneg_vr[i]], a));
            return 0;
        }
    const char* pos[] = {"sample_time", "coupler_force_max"};
    const int pos_vr[] = {vr->sample_time, vr->coupler_force_max};
    for (int i = 0; i < 2; i++)
        if (!(v[pos_vr[i]] > 0)) {
            char a[40];
            snprintf(err, n, "%s = %s must be > 0", pos[i], ato_repr(v[pos_vr[i]], a));
            return 0;
        }
    double r_force = v[vr->R], r_increment = v[vr->dR];
    if (!(r_force >= 0 && r_increment >= 0 && r_force + r_increment > 0)) {
        char a[40], b[40];
        snprintf(err, n, "R = %s, dR = %s: both >= 0 and one > 0 (the QP needs a weight on the "
                 "forces or their increments)", ato_repr(r_force, a), ato_repr(r_increment, b));
        return 0;
    }
    if (!ato_profile_load(profile, p->resources, s[vr->reference], err, n)) return 0;
    if (profile->distance) {
        snprintf(err, n, "reference: hybrid MPC tracks a speed-time profile, got a "
                 "'distance' one");
        return 0;
    }
    return 1;
}
