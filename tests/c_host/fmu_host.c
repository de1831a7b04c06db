/*
 * A minimal FMI 2.0 co-simulation host in C, standing in for any non-Python tool.
 *
 *   fmu_host UNZIPDIR MODEL_IDENTIFIER GUID STEP N_STEPS [in:VR=VALUE ...] [out:VR ...]
 *
 * Loads UNZIPDIR/binaries/linux64/MODEL_IDENTIFIER.so, instantiates it, sets the constant
 * Real inputs, runs N_STEPS doStep calls of STEP seconds and prints "t,out1,out2,..." after
 * every step (%.17g). Any non-OK status ends the run with exit status 3. It leaves with
 * _exit() unless FMU_HOST_PLAIN_EXIT is set (see the end of main).
 * Our FMUs' binary is a shim that loads the libpython the FMU was built with; pythonfmu's
 * plain binary (third-party FMUs, or ours built without gcc) needs libpython's symbols in the
 * global scope: start this program with LD_PRELOAD=<libpython3.X.so> (see
 * docs/other_tools.md). Either way the FMU's Python packages must be importable (same
 * interpreter installation, else PYTHONPATH).
 */
#include <dlfcn.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "fmi2Functions.h"

static void logger(fmi2ComponentEnvironment env, fmi2String instance, fmi2Status status,
                   fmi2String category, fmi2String message, ...)
{
    (void)env;
    fprintf(stderr, "[%s] status %d %s: %s\n", instance, (int)status,
            category ? category : "", message ? message : "");
}

#define LOAD(name)                                                                        \
    name##TYPE* name = (name##TYPE*)dlsym(lib, #name);                                    \
    if (!name) { fprintf(stderr, "missing symbol %s\n", #name); return 2; }

#define CHECK(call)                                                                       \
    if ((call) != fmi2OK) { fprintf(stderr, "%s failed\n", #call); return 3; }

int main(int argc, char** argv)
{
    if (argc < 6) {
        fprintf(stderr, "usage: %s UNZIPDIR MODEL_IDENTIFIER GUID STEP N_STEPS "
                        "[in:VR=VALUE ...] [out:VR ...]\n", argv[0]);
        return 1;
    }
    const char* dir = argv[1];
    char path[4096], resources[4096];
    snprintf(path, sizeof path, "%s/binaries/linux64/%s.so", dir, argv[2]);
    snprintf(resources, sizeof resources, "file://%s/resources", dir);
    double step = atof(argv[4]);
    int n_steps = atoi(argv[5]);

    fmi2ValueReference in_vr[64], out_vr[64];
    fmi2Real in_value[64], out_value[64];
    size_t n_in = 0, n_out = 0;
    for (int i = 6; i < argc; ++i) {
        if (strncmp(argv[i], "in:", 3) == 0 && n_in < 64) {
            char* eq = strchr(argv[i], '=');
            if (!eq) return 1;
            in_vr[n_in] = (fmi2ValueReference)strtoul(argv[i] + 3, NULL, 10);
            in_value[n_in++] = atof(eq + 1);
        } else if (strncmp(argv[i], "out:", 4) == 0 && n_out < 64) {
            out_vr[n_out++] = (fmi2ValueReference)strtoul(argv[i] + 4, NULL, 10);
        }
    }

    void* lib = dlopen(path, RTLD_NOW | RTLD_LOCAL);
    if (!lib) {
        fprintf(stderr, "dlopen failed: %s\n", dlerror());
        return 2;
    }
    LOAD(fmi2Instantiate) LOAD(fmi2SetupExperiment) LOAD(fmi2EnterInitializationMode)
    LOAD(fmi2ExitInitializationMode) LOAD(fmi2SetReal) LOAD(fmi2GetReal) LOAD(fmi2DoStep)
    LOAD(fmi2Terminate) LOAD(fmi2FreeInstance)

    fmi2CallbackFunctions callbacks = {logger, calloc, free, NULL, NULL};
    fmi2Component c = fmi2Instantiate("c_host", fmi2CoSimulation, argv[3], resources,
                                      &callbacks, fmi2False, fmi2False);
    if (!c) {
        fprintf(stderr, "fmi2Instantiate failed\n");
        return 3;
    }
    CHECK(fmi2SetupExperiment(c, fmi2False, 0.0, 0.0, fmi2False, 0.0))
    CHECK(fmi2EnterInitializationMode(c))
    if (n_in) CHECK(fmi2SetReal(c, in_vr, n_in, in_value))
    CHECK(fmi2ExitInitializationMode(c))
    for (int k = 0; k < n_steps; ++k) {
        CHECK(fmi2DoStep(c, k * step, step, fmi2True))
        if (n_out) CHECK(fmi2GetReal(c, out_vr, n_out, out_value))
        printf("%.17g", (k + 1) * step);
        for (size_t j = 0; j < n_out; ++j) printf(",%.17g", out_value[j]);
        printf("\n");
    }
    CHECK(fmi2Terminate(c))
    fmi2FreeInstance(c);
    fprintf(stderr, "freed\n");
    /* pythonfmu 0.7's library destructor (finalizePythonInterpreter) writes to a static
     * already destroyed by the exit handlers and corrupts the heap; leave without running
     * them once every instance is freed (nothing is lost: output is flushed here). */
    fflush(NULL);
    if (getenv("FMU_HOST_PLAIN_EXIT"))
        return 0; /* run the exit handlers: fine with our FMUs' shim (see the test) */
    _exit(0);
}
