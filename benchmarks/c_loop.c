/* The bare C co-simulation loop a master is measured against (benchmarks/bench_c_limit.py).
 *
 * Loads FMI 2.0 co-simulation FMUs' shared libraries with dlopen, instantiates and initialises
 * them with the start values it is given, and runs the closed loop on one communication step:
 * per step, for each connection group (one source FMU, one destination FMU) one fmi2GetReal of
 * the source's outputs and one fmi2SetReal of the destination's inputs, then fmi2DoStep of
 * every FMU. No recording, no scheduling: the floor of what any master costs on these FMUs.
 *
 * The plan comes on stdin, one item per line (written by bench_c_limit.plan_text):
 *   fmu LIBRARY MODEL_IDENTIFIER GUID RESOURCE_URI INSTANCE_NAME
 *   set r|i|b|s FMU VR VALUE          start value (s: the rest of the line), before exitInit
 *   link SRC DST N SRC_VR... DST_VR...
 *   run START STEP STEPS
 *   final FMU VR                      the Real printed after the loop
 * Prints one JSON line: {"final": %.17g, "loop_wall_s": ..., "loop_cpu_s": ...} (wall:
 * CLOCK_MONOTONIC, CPU: CLOCK_PROCESS_CPUTIME_ID, the loop alone).
 */
#define _POSIX_C_SOURCE 200809L
#include <dlfcn.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "fmi2Functions.h"

#define MAX_FMUS 8
#define MAX_LINKS 32
#define MAX_REFS 64
#define LINE 4096

typedef struct {
    void *lib;
    fmi2Component c;
    fmi2InstantiateTYPE *instantiate;
    fmi2SetupExperimentTYPE *setup_experiment;
    fmi2EnterInitializationModeTYPE *enter_init;
    fmi2ExitInitializationModeTYPE *exit_init;
    fmi2SetRealTYPE *set_real;
    fmi2SetIntegerTYPE *set_integer;
    fmi2SetBooleanTYPE *set_boolean;
    fmi2SetStringTYPE *set_string;
    fmi2GetRealTYPE *get_real;
    fmi2DoStepTYPE *do_step;
    fmi2TerminateTYPE *terminate;
    fmi2FreeInstanceTYPE *free_instance;
} Fmu;

typedef struct {
    int src, dst, n;
    fmi2ValueReference src_vr[MAX_REFS], dst_vr[MAX_REFS];
} Link;

static void die(const char *fmt, ...) {
    va_list ap;
    va_start(ap, fmt);
    fprintf(stderr, "c_loop: ");
    vfprintf(stderr, fmt, ap);
    fprintf(stderr, "\n");
    va_end(ap);
    exit(1);
}

static void check(fmi2Status status, const char *call, int fmu) {
    if (status > fmi2Warning) die("%s of FMU %d returned status %d", call, fmu, (int)status);
}

static void logger(fmi2ComponentEnvironment env, fmi2String instance, fmi2Status status,
                   fmi2String category, fmi2String message, ...) {
    (void)env;
    if (status <= fmi2Warning) return;
    va_list ap;
    va_start(ap, message);
    fprintf(stderr, "%s [%s]: ", instance, category);
    vfprintf(stderr, message, ap);
    fprintf(stderr, "\n");
    va_end(ap);
}

static void *symbol(void *lib, const char *name) {
    void *f = dlsym(lib, name);
    if (f == NULL) die("symbol %s: %s", name, dlerror());
    return f;
}

static double seconds(clockid_t clock) {
    struct timespec ts;
    clock_gettime(clock, &ts);
    return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}

int main(void) {
    static Fmu fmus[MAX_FMUS];
    static Link links[MAX_LINKS];
    static const fmi2CallbackFunctions callbacks = {logger, calloc, free, NULL, NULL};
    int n_fmus = 0, n_links = 0, initialised = 0, final_fmu = -1;
    fmi2ValueReference final_vr = 0;
    double start = 0.0, step = 0.0;
    long steps = 0;
    char line[LINE];

    while (fgets(line, sizeof line, stdin) != NULL) {
        line[strcspn(line, "\n")] = '\0';
        char kind[16];
        int used = 0;
        if (sscanf(line, "%15s %n", kind, &used) < 1) continue;
        char *rest = line + used;
        if (strcmp(kind, "fmu") == 0) {
            char path[LINE], id[256], guid[256], uri[LINE], name[256];
            if (n_fmus == MAX_FMUS) die("more than %d FMUs", MAX_FMUS);
            if (sscanf(rest, "%s %255s %255s %s %255s", path, id, guid, uri, name) != 5)
                die("bad line: %s", line);
            Fmu *f = &fmus[n_fmus];
            f->lib = dlopen(path, RTLD_NOW | RTLD_LOCAL);
            if (f->lib == NULL) die("dlopen %s: %s", path, dlerror());
            f->instantiate = (fmi2InstantiateTYPE *)symbol(f->lib, "fmi2Instantiate");
            f->setup_experiment = (fmi2SetupExperimentTYPE *)symbol(f->lib,
                                                                    "fmi2SetupExperiment");
            f->enter_init = (fmi2EnterInitializationModeTYPE *)symbol(
                f->lib, "fmi2EnterInitializationMode");
            f->exit_init = (fmi2ExitInitializationModeTYPE *)symbol(
                f->lib, "fmi2ExitInitializationMode");
            f->set_real = (fmi2SetRealTYPE *)symbol(f->lib, "fmi2SetReal");
            f->set_integer = (fmi2SetIntegerTYPE *)symbol(f->lib, "fmi2SetInteger");
            f->set_boolean = (fmi2SetBooleanTYPE *)symbol(f->lib, "fmi2SetBoolean");
            f->set_string = (fmi2SetStringTYPE *)symbol(f->lib, "fmi2SetString");
            f->get_real = (fmi2GetRealTYPE *)symbol(f->lib, "fmi2GetReal");
            f->do_step = (fmi2DoStepTYPE *)symbol(f->lib, "fmi2DoStep");
            f->terminate = (fmi2TerminateTYPE *)symbol(f->lib, "fmi2Terminate");
            f->free_instance = (fmi2FreeInstanceTYPE *)symbol(f->lib, "fmi2FreeInstance");
            f->c = f->instantiate(name, fmi2CoSimulation, guid, uri, &callbacks, fmi2False,
                                  fmi2False);
            if (f->c == NULL) die("fmi2Instantiate of %s failed", path);
            n_fmus++;
        } else if (strcmp(kind, "set") == 0) {
            char type;
            int i, at = 0;
            unsigned vr;
            if (sscanf(rest, " %c %d %u %n", &type, &i, &vr, &at) < 3 || i < 0 || i >= n_fmus)
                die("bad line: %s", line);
            Fmu *f = &fmus[i];
            if (!initialised) {  /* every FMU in initialisation mode before its start values */
                for (int k = 0; k < n_fmus; k++) {
                    check(fmus[k].setup_experiment(fmus[k].c, fmi2False, 0.0, start, fmi2False,
                                                   0.0), "fmi2SetupExperiment", k);
                    check(fmus[k].enter_init(fmus[k].c), "fmi2EnterInitializationMode", k);
                }
                initialised = 1;
            }
            fmi2ValueReference ref = vr;
            const char *value = rest + at;
            if (type == 'r') {
                fmi2Real x = strtod(value, NULL);
                check(f->set_real(f->c, &ref, 1, &x), "fmi2SetReal", i);
            } else if (type == 'i') {
                fmi2Integer x = (fmi2Integer)strtol(value, NULL, 10);
                check(f->set_integer(f->c, &ref, 1, &x), "fmi2SetInteger", i);
            } else if (type == 'b') {
                fmi2Boolean x = strtol(value, NULL, 10) != 0;
                check(f->set_boolean(f->c, &ref, 1, &x), "fmi2SetBoolean", i);
            } else if (type == 's') {
                fmi2String x = value;
                check(f->set_string(f->c, &ref, 1, &x), "fmi2SetString", i);
            } else {
                die("bad type in: %s", line);
            }
        } else if (strcmp(kind, "link") == 0) {
            Link *l = &links[n_links];
            int at = 0, more = 0;
            if (n_links == MAX_LINKS) die("more than %d connection groups", MAX_LINKS);
            if (sscanf(rest, "%d %d %d %n", &l->src, &l->dst, &l->n, &at) < 3 || l->n < 1
                || l->n > MAX_REFS || l->src < 0 || l->src >= n_fmus || l->dst < 0
                || l->dst >= n_fmus)
                die("bad line: %s", line);
            for (int k = 0; k < 2 * l->n; k++) {
                unsigned vr;
                if (sscanf(rest + at, "%u %n", &vr, &more) < 1) die("bad line: %s", line);
                at += more;
                if (k < l->n) l->src_vr[k] = vr;
                else l->dst_vr[k - l->n] = vr;
            }
            n_links++;
        } else if (strcmp(kind, "run") == 0) {
            if (sscanf(rest, "%lf %lf %ld", &start, &step, &steps) != 3) die("bad line: %s", line);
        } else if (strcmp(kind, "final") == 0) {
            unsigned vr;
            if (sscanf(rest, "%d %u", &final_fmu, &vr) != 2) die("bad line: %s", line);
            final_vr = vr;
        } else {
            die("unknown line: %s", line);
        }
    }
    if (n_fmus == 0 || steps < 1 || final_fmu < 0 || final_fmu >= n_fmus)
        die("the plan needs fmu, run and final lines");
    for (int k = 0; k < n_fmus; k++) {
        if (!initialised) {
            check(fmus[k].setup_experiment(fmus[k].c, fmi2False, 0.0, start, fmi2False, 0.0),
                  "fmi2SetupExperiment", k);
            check(fmus[k].enter_init(fmus[k].c), "fmi2EnterInitializationMode", k);
        }
        check(fmus[k].exit_init(fmus[k].c), "fmi2ExitInitializationMode", k);
    }

    fmi2Real values[MAX_REFS];
    double wall0 = seconds(CLOCK_MONOTONIC), cpu0 = seconds(CLOCK_PROCESS_CPUTIME_ID);
    for (long s = 0; s < steps; s++) {
        double t = start + (double)s * step;
        for (int k = 0; k < n_links; k++) {
            const Link *l = &links[k];
            check(fmus[l->src].get_real(fmus[l->src].c, l->src_vr, l->n, values),
                  "fmi2GetReal", l->src);
            check(fmus[l->dst].set_real(fmus[l->dst].c, l->dst_vr, l->n, values),
                  "fmi2SetReal", l->dst);
        }
        for (int k = 0; k < n_fmus; k++)
            check(fmus[k].do_step(fmus[k].c, t, step, fmi2True), "fmi2DoStep", k);
    }
    double wall = seconds(CLOCK_MONOTONIC) - wall0, cpu = seconds(CLOCK_PROCESS_CPUTIME_ID) - cpu0;

    fmi2Real final;
    check(fmus[final_fmu].get_real(fmus[final_fmu].c, &final_vr, 1, &final), "fmi2GetReal",
          final_fmu);
    for (int k = 0; k < n_fmus; k++) {
        fmus[k].terminate(fmus[k].c);
        fmus[k].free_instance(fmus[k].c);
    }
    printf("{\"final\": %.17g, \"loop_wall_s\": %.9g, \"loop_cpu_s\": %.9g}\n", final, wall,
           cpu);
    return 0;
}
