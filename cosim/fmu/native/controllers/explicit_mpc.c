/*
 * explicit_mpc.c: online law of Empc3, the C twin of controllers/hybrid/explicit_mpc.py
 * (seed 004, eq. 18): per sample the parameter
 *
 *   theta = [vm - v_ref, 1e3 (v1 - v2), 1e3 (v2 - v3), F12 / 1e3, F23 / 1e3, v_ref,
 *            least-squares slope of v_ref over the horizon, envelope limit of the mode]
 *
 * (controllers/hybrid/explicit.py), the mode delta of the schedule (braking from brake_from
 * until the mean speed is down), the PWA segment of the mean speed vm = c'v, theta clipped
 * into the parameter box of (mode, segment), the region found by descending the bounding-box
 * tree and testing the leaf's regions (E theta <= e + tol; else the least violated), and
 * u = F_i theta + f_i on the cars that act in the mode, projected onto the mode.
 *
 * The region data, the tree built from them and the design constants (c, breakpoints, motored
 * cars, limit ratios) are computed from the bundled region files by the core at build time
 * (ExplicitMpc.native_data, controllers/hybrid/explicit_mpc.py) into
 * resources/regions/<name>.empc. Scalar operations are the core's in its order;
 * the dot products (c'v, the slope's numerator, E theta, F theta) are summed in index order,
 * where numpy's BLAS may use another order and fused multiply-adds: see
 * tests/test_native_controllers.py for the bound that follows.
 */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "hybrid.h"
#include "law_common.h"
#include "profile.h"
#include "vars.h"
#include "ato_model.h"

#define UNITS ATO_OPTION_units
#define NTHETA 8
#define KN 1e3
#define NSEG 3

typedef struct {
    int count, na, nodes;
    double box[2 * NTHETA]; /* lo, hi per parameter */
    double tol;
    double *E, *e, *F, *f, *thr;
    int *rows, *dim, *left, *right, *start, *stop, *items;
} region_set;

typedef struct {
    double forces[UNITS], v_ref, s_ref, speed_error, failure_time;
    double delta, qp_solves, qp_infeasible, nodes, qp_rescued, outside, region;
    int braking_done, has_failure;
} empc_state;

struct law_core {
    double brake_from, brake_until_speed, sample_time;
    int horizon;
    double c[UNITS], breakpoints[NSEG - 1], motored[UNITS], ratio[2][UNITS];
    region_set sets[2][NSEG];
    ato_profile profile;
    empc_state st;
};

/* -- the generated region file: "key count values..." lines, "meta key value" lines -------- */
typedef struct { char key[64]; int n; double* x; } array;
typedef struct { int n, cap; array* a; char meta[16][2][128]; int n_meta; } table;

static void table_free(table* t) {
    for (int i = 0; i < t->n; i++) free(t->a[i].x);
    free(t->a);
}

static int table_load(table* t, const char* path, char* err, size_t n_err) {
    memset(t, 0, sizeof *t);
    FILE* f = fopen(path, "r");
    if (!f) {
        snprintf(err, n_err, "region data %s not found", path);
        return 0;
    }
    char key[64];
    while (fscanf(f, "%63s", key) == 1) {
        if (key[0] == '#') {
            int ch;
            while ((ch = fgetc(f)) != EOF && ch != '\n') {}
            continue;
        }
        if (strcmp(key, "meta") == 0) {
            if (t->n_meta < 16 &&
                fscanf(f, "%127s %127s", t->meta[t->n_meta][0], t->meta[t->n_meta][1]) == 2)
                t->n_meta++;
            continue;
        }
        int n = 0;
        if (fscanf(f, "%d", &n) != 1 || n < 0) break;
        if (t->n == t->cap) {
            t->cap = t->cap ? 2 * t->cap : 64;
            t->a = realloc(t->a, t->cap * sizeof(array));
        }
        array* a = &t->a[t->n++];
        snprintf(a->key, sizeof a->key, "%s", key);
        a->n = n;
        a->x = malloc((n ? n : 1) * sizeof(double));
        for (int i = 0; i < n; i++)
            if (fscanf(f, "%lf", &a->x[i]) != 1) {
                fclose(f);
                snprintf(err, n_err, "%s: array %s is truncated", path, key);
                return 0;
            }
    }
    fclose(f);
    return 1;
}

static const array* table_get(const table* t, const char* key) {
    for (int i = 0; i < t->n; i++)
        if (strcmp(t->a[i].key, key) == 0) return &t->a[i];
    return NULL;
}

static const char* table_meta(const table* t, const char* key) {
    for (int i = 0; i < t->n_meta; i++)
        if (strcmp(t->meta[i][0], key) == 0) return t->meta[i][1];
    return NULL;
}

static double* take_doubles(const table* t, const char* key, int want, int* n, char* err,
                            size_t n_err) {
    const array* a = table_get(t, key);
    if (!a || (want >= 0 && a->n != want)) {
        snprintf(err, n_err, "region data: array %s missing or of the wrong size", key);
        return NULL;
    }
    double* x = malloc((a->n ? a->n : 1) * sizeof(double));
    memcpy(x, a->x, a->n * sizeof(double));
    if (n) *n = a->n;
    return x;
}

static int* take_ints(const table* t, const char* key, int* n, char* err, size_t n_err) {
    const array* a = table_get(t, key);
    if (!a) {
        snprintf(err, n_err, "region data: array %s missing", key);
        return NULL;
    }
    int* x = malloc((a->n ? a->n : 1) * sizeof(int));
    for (int i = 0; i < a->n; i++) x[i] = (int)a->x[i];
    if (n) *n = a->n;
    return x;
}

static void set_free(region_set* s) {
    free(s->E); free(s->e); free(s->F); free(s->f); free(s->thr);
    free(s->rows); free(s->dim); free(s->left); free(s->right); free(s->start);
    free(s->stop); free(s->items);
    memset(s, 0, sizeof *s);
}

static int load_set(region_set* s, const table* t, int mode, int seg, char* err, size_t n) {
    char k[64];
    int count = 0, nodes = 0;
#define KEY(name) (snprintf(k, sizeof k, "m%ds%d_%s", mode, seg, name), k)
    double* box = take_doubles(t, KEY("box"), 2 * NTHETA, NULL, err, n);
    double* na = take_doubles(t, KEY("na"), 1, NULL, err, n);
    double* tol = take_doubles(t, KEY("tol"), 1, NULL, err, n);
    if (!box || !na || !tol) { free(box); free(na); free(tol); return 0; }
    memcpy(s->box, box, sizeof s->box);
    s->na = (int)na[0];
    s->tol = tol[0];
    free(box); free(na); free(tol);
    s->rows = take_ints(t, KEY("rows"), &count, err, n);
    s->count = count - 1;
    s->E = take_doubles(t, KEY("E"), -1, NULL, err, n);
    s->e = take_doubles(t, KEY("e"), -1, NULL, err, n);
    s->F = take_doubles(t, KEY("F"), s->count * s->na * NTHETA, NULL, err, n);
    s->f = take_doubles(t, KEY("f"), s->count * s->na, NULL, err, n);
    s->dim = take_ints(t, KEY("dim"), &nodes, err, n);
    s->thr = take_doubles(t, KEY("thr"), nodes, NULL, err, n);
    s->left = take_ints(t, KEY("left"), NULL, err, n);
    s->right = take_ints(t, KEY("right"), NULL, err, n);
    s->start = take_ints(t, KEY("start"), NULL, err, n);
    s->stop = take_ints(t, KEY("stop"), NULL, err, n);
    s->items = take_ints(t, KEY("items"), NULL, err, n);
#undef KEY
    s->nodes = nodes;
    return s->rows && s->E && s->e && s->F && s->f && s->dim && s->thr && s->left &&
           s->right && s->start && s->stop && s->items;
}

/* -- construction ------------------------------------------------------------------------- */
static int isclose(double a, double b) {
    return a == b || fabs(a - b) <= 1e-9 * ato_max(fabs(a), fabs(b));
}

void law_free(law_core* c) {
    for (int m = 0; m < 2; m++)
        for (int s = 0; s < NSEG; s++) set_free(&c->sets[m][s]);
    ato_profile_free(&c->profile);
    free(c);
}

static law_core* fail(law_core* c, table* t) {
    if (t) table_free(t);
    law_free(c);
    return NULL;
}

law_core* law_make(const ato_values* p, double t0, char* err, size_t n) {
    (void)t0;
    const double* v = p->v;
    char* const* s = p->s;
    law_core* c = calloc(1, sizeof(law_core));
    c->brake_from = v[ATO_VR_brake_from];
    c->brake_until_speed = v[ATO_VR_brake_until_speed];
    c->sample_time = v[ATO_VR_sample_time];
    c->horizon = (int)v[ATO_VR_N];
    /* HybridMpcParams.check and the profile, in their order */
    static const hybrid_vrs vrs = HYBRID_VRS;
    if (!hybrid_check(p, &vrs, &c->profile, err, n)) return fail(c, NULL);
    const char* posref = s[ATO_VR_position_reference];
    const char* dmode = s[ATO_VR_delta_mode];
    double r_increment = v[ATO_VR_dR];
    /* ExplicitMpc.__init__, in its order: the evaluation, eq. 11's weight, the mode */
    const char* evaluation = s[ATO_VR_evaluation];
    if (strcmp(evaluation, "explicit") != 0 && strcmp(evaluation, "online") != 0) {
        snprintf(err, n, "evaluation = '%s' must be one of ('explicit', 'online')", evaluation);
        return fail(c, NULL);
    }
    if (strcmp(evaluation, "explicit") != 0) {
        snprintf(err, n, "evaluation = '%s': the native FMU evaluates the region lookup only; "
                 "the online twin needs the Python FMU", evaluation);
        return fail(c, NULL);
    }
    if (r_increment != 0.0) {
        char a[40];
        snprintf(err, n, "dR = %s: the EMPC's reduced problem has no force-increment term "
                 "(eq. 11); its regions are built for dR = 0", ato_repr(r_increment, a));
        return fail(c, NULL);
    }
    if (strcmp(dmode, "schedule") != 0) {
        snprintf(err, n, "delta_mode = '%s': EMPC needs the scheduled mode (its regions are "
                 "per mode)", dmode);
        return fail(c, NULL);
    }
    /* the region data: a bundled name */
    const char* name = s[ATO_VR_regions];
    for (const char* q = name; *q; q++)
        if (*q == '/' || *q == '\\' || *q == '.') {
            snprintf(err, n, "regions = '%s': the native FMU reads bundled region data only "
                     "(resources/regions/*.empc); a file path needs the Python FMU", name);
            return fail(c, NULL);
        }
    size_t len = strlen(p->resources) + strlen(name) + 32;
    char* path = malloc(len);
    snprintf(path, len, "%s/regions/%s.empc", p->resources, name);
    table t;
    int ok = table_load(&t, path, err, n);
    free(path);
    if (!ok) return fail(c, &t);
    /* ExplicitMpc.design_meta against the data's */
    char blocks[64];
    if (s[ATO_VR_move_blocks][0]) {
        snprintf(blocks, sizeof blocks, "%s", s[ATO_VR_move_blocks]);
    } else {
        int k = 0;
        for (; k < c->horizon && k + 1 < (int)sizeof blocks; k++) blocks[k] = '1';
        blocks[k] = 0;
    }
    const char* fkeys[] = {"N", "q_speed", "q_position", "R", "sample_time", "fit_speed_max"};
    const double fvals[] = {(double)c->horizon, v[ATO_VR_q_speed], v[ATO_VR_q_position],
                            v[ATO_VR_R], v[ATO_VR_sample_time], v[ATO_VR_fit_speed_max]};
    for (int i = 0; i < 6; i++) {
        const char* have = table_meta(&t, fkeys[i]);
        if (!have || !isclose(strtod(have, NULL), fvals[i])) {
            char a[40];
            snprintf(err, n, "regions = '%s.npz' were built for %s = %s, this controller has "
                     "%s: regenerate them with papers/seed004/make_empc_regions.py", name,
                     fkeys[i], have ? have : "None", ato_repr(fvals[i], a));
            return fail(c, &t);
        }
    }
    const char* skeys[] = {"move_blocks", "configuration", "position_reference"};
    const char* svals[] = {blocks, s[ATO_VR_configuration], posref};
    for (int i = 0; i < 3; i++) {
        const char* have = table_meta(&t, skeys[i]);
        if (!have || strcmp(have, svals[i]) != 0) {
            snprintf(err, n, "regions = '%s.npz' were built for %s = %s, this controller has "
                     "'%s': regenerate them with papers/seed004/make_empc_regions.py", name, skeys[i],
                     have ? have : "None", svals[i]);
            return fail(c, &t);
        }
    }
    double* cw = take_doubles(&t, "c", UNITS, NULL, err, n);
    double* bp = take_doubles(&t, "breakpoints", NSEG - 1, NULL, err, n);
    double* mot = take_doubles(&t, "motored", UNITS, NULL, err, n);
    double* r0 = take_doubles(&t, "ratio0", UNITS, NULL, err, n);
    double* r1 = take_doubles(&t, "ratio1", UNITS, NULL, err, n);
    ok = cw && bp && mot && r0 && r1;
    if (ok) {
        memcpy(c->c, cw, sizeof c->c);
        memcpy(c->breakpoints, bp, sizeof c->breakpoints);
        memcpy(c->motored, mot, sizeof c->motored);
        memcpy(c->ratio[0], r0, sizeof c->ratio[0]);
        memcpy(c->ratio[1], r1, sizeof c->ratio[1]);
    }
    free(cw); free(bp); free(mot); free(r0); free(r1);
    for (int m = 0; m < 2 && ok; m++)
        for (int sg = 0; sg < NSEG && ok; sg++) ok = load_set(&c->sets[m][sg], &t, m, sg, err, n);
    if (!ok) return fail(c, &t);
    table_free(&t);
    c->st.delta = 1.0;
    c->st.region = -1.0;
    return c;
}

ATO_LAW_PLAIN_STATE(st)

/* -- event ------------------------------------------------------------------------------- */
static double violation(const region_set* s, int i, const double* theta) {
    double worst = -INFINITY;
    for (int r = s->rows[i]; r < s->rows[i + 1]; r++) {
        double dot = 0.0;
        for (int j = 0; j < NTHETA; j++) dot += s->E[r * NTHETA + j] * theta[j];
        double x = dot - s->e[r];
        if (r == s->rows[i] || x > worst) worst = x;
    }
    return worst;
}

/* RegionSet.locate: the first leaf candidate holding theta, else the least violated */
static int locate(const region_set* s, const double* theta, double* viol) {
    int k = 0;
    while (s->dim[k] >= 0) k = theta[s->dim[k]] <= s->thr[k] ? s->left[k] : s->right[k];
    int best = -1;
    double best_v = INFINITY;
    for (int q = s->start[k]; q < s->stop[k]; q++) {
        int i = s->items[q];
        double x = violation(s, i, theta);
        if (x <= s->tol) {
            *viol = x;
            return i;
        }
        if (x < best_v) {
            best = i;
            best_v = x;
        }
    }
    *viol = best_v;
    return best;
}

static int segment(const law_core* c, double v) { /* searchsorted(breakpoints, v, "right") */
    int j = 0;
    while (j < NSEG - 1 && !(v < c->breakpoints[j])) j++;
    return j;
}

void law_outputs(const law_core* c, double* out) {
    const empc_state* st = &c->st;
    double total = 0.0;
    for (int i = 0; i < UNITS; i++) {
        out[ATO_VR_force_1 + i] = st->forces[i];
        total += st->forces[i];
    }
    out[ATO_VR_force_demand] = total;
    out[ATO_VR_delta] = st->delta;
    out[ATO_VR_v_ref] = st->v_ref;
    out[ATO_VR_s_ref] = st->s_ref;
    out[ATO_VR_speed_error] = st->speed_error;
    out[ATO_VR_qp_solves] = st->qp_solves;
    out[ATO_VR_qp_infeasible] = st->qp_infeasible;
    out[ATO_VR_qp_rescued] = st->qp_rescued;
    out[ATO_VR_bnb_nodes] = st->nodes;
    out[ATO_VR_empc_outside] = st->outside;
    out[ATO_VR_empc_region] = st->region;
}

int law_compute(law_core* c, double t, const ato_values* p, double* out, char* err, size_t n) {
    (void)err; (void)n;
    empc_state* st = &c->st;
    const double* in = p->v;
    double v[UNITS];
    for (int i = 0; i < UNITS; i++) v[i] = in[ATO_VR_v_1 + i];
    double vm = 0.0;
    for (int i = 0; i < UNITS; i++) vm += c->c[i] * v[i];
    /* HybridMpc.schedule, stage 0 */
    if (t >= c->brake_from && vm <= c->brake_until_speed) st->braking_done = 1;
    int mode = (t >= c->brake_from && !st->braking_done) ? 0 : 1;
    int seg = segment(c, vm);
    /* ExplicitMpc.theta */
    double vd = ato_profile_speed(&c->profile, t);
    double num = 0.0, den = 0.0;
    for (int k = 1; k <= c->horizon; k++) {
        double sk = (double)k * c->sample_time;
        num += sk * (ato_profile_speed(&c->profile, t + sk) - vd);
    }
    for (int k = 1; k <= c->horizon; k++) {
        double sk = (double)k * c->sample_time;
        den += sk * sk;
    }
    double slope = num / den;
    const double* ratio = c->ratio[mode];
    double lim = 0.0;
    int first = 1;
    for (int i = 0; i < UNITS; i++) {
        if (mode == 1 && !(ratio[i] > 0)) continue;
        double limit = mode == 1 ? in[ATO_VR_traction_limit_1 + i]
                                 : in[ATO_VR_brake_limit_1 + i];
        double x = limit / KN / ratio[i];
        if (first || x < lim) lim = x;
        first = 0;
    }
    double theta[NTHETA] = {vm - vd, 1e3 * (v[0] - v[1]), 1e3 * (v[1] - v[2]),
                            in[ATO_VR_coupler_force_1] / KN, in[ATO_VR_coupler_force_2] / KN,
                            vd, slope, ato_max(lim, 0.0)};
    const region_set* rs = &c->sets[mode][seg];
    double clipped[NTHETA];
    int changed = 0;
    for (int j = 0; j < NTHETA; j++) { /* np.clip: minimum(maximum(theta, lo), hi) */
        double x = theta[j] >= rs->box[2 * j] ? theta[j] : rs->box[2 * j];
        clipped[j] = x <= rs->box[2 * j + 1] ? x : rs->box[2 * j + 1];
        changed |= clipped[j] != theta[j];
    }
    double viol;
    int i = locate(rs, clipped, &viol);
    st->outside += (changed || viol > rs->tol) ? 1.0 : 0.0;
    double u[UNITS] = {0};
    if (i >= 0) {
        int q = 0;
        for (int car = 0; car < UNITS; car++) {
            if (mode == 1 && !(ratio[car] > 0)) continue;
            double dot = 0.0;
            const double* F = rs->F + ((size_t)i * rs->na + q) * NTHETA;
            for (int j = 0; j < NTHETA; j++) dot += F[j] * clipped[j];
            u[car] = dot + rs->f[i * rs->na + q];
            q++;
        }
    } else {
        st->qp_infeasible += 1.0;
        st->has_failure = 1;
        st->failure_time = t;
        for (int car = 0; car < UNITS; car++) u[car] = st->forces[car] / KN;
    }
    for (int car = 0; car < UNITS; car++) /* project onto the mode */
        u[car] = mode == 1 ? (c->motored[car] != 0.0 ? (u[car] >= 0.0 ? u[car] : 0.0) : 0.0)
                           : (u[car] <= 0.0 ? u[car] : 0.0);
    st->region = (double)i;
    st->delta = (double)mode;
    for (int car = 0; car < UNITS; car++) st->forces[car] = u[car] * KN;
    st->qp_solves += 1.0;
    st->v_ref = ato_profile_speed(&c->profile, t);
    st->s_ref = ato_profile_position(&c->profile, t);
    st->speed_error = vm - st->v_ref;
    law_outputs(c, out);
    return 1;
}
