/*
 * A minimal FMI 3.0 co-simulation host in C, standing in for any non-Python tool.
 *
 *   fmu3_host UNZIPDIR MODEL_IDENTIFIER TOKEN STEP N_STEPS EVENT_MODE [in:VR=VALUE ...]
 *             [out:VR ...]
 *
 * Loads UNZIPDIR/binaries/x86_64-linux/MODEL_IDENTIFIER.so (built with mingw-w64 for Windows:
 * UNZIPDIR\binaries\x86_64-windows\MODEL_IDENTIFIER.dll), instantiates it (eventModeUsed =
 * EVENT_MODE, 0 or 1), sets the constant Float64 inputs, runs N_STEPS fmi3DoStep calls of STEP
 * seconds and prints "t,out1,out2,...,next" after every step (%.17g; next is the nextEventTime
 * of the last fmi3UpdateDiscreteStates, or nan). With Event Mode it enters Event Mode after
 * initialisation and whenever fmi3DoStep says eventHandlingNeeded. Any non-OK status ends the
 * run with exit status 3. Leaves main() normally (the exit handlers run).
 */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#ifdef _WIN32
#include <windows.h>
#define PLATFORM_BINARY "%s\\binaries\\x86_64-windows\\%s.dll"
#define RESOURCES "%s\\resources\\"
typedef HMODULE library;
static library open_library(const char* path) { return LoadLibraryA(path); }
static void* symbol(library lib, const char* name) { return (void*)GetProcAddress(lib, name); }
static const char* load_error(void) { return "LoadLibrary failed"; }
#else
#include <dlfcn.h>
#define PLATFORM_BINARY "%s/binaries/x86_64-linux/%s.so"
#define RESOURCES "%s/resources/"
typedef void* library;
static library open_library(const char* path) { return dlopen(path, RTLD_NOW | RTLD_LOCAL); }
static void* symbol(library lib, const char* name) { return dlsym(lib, name); }
static const char* load_error(void) { return dlerror(); }
#endif

#include "fmi3Functions.h"

static void logger(fmi3InstanceEnvironment env, fmi3Status status, fmi3String category,
                   fmi3String message)
{
    (void)env;
    fprintf(stderr, "status %d %s: %s\n", (int)status, category ? category : "",
            message ? message : "");
}

#define LOAD(name)                                                                        \
    name##TYPE* name = (name##TYPE*)symbol(lib, #name);                                   \
    if (!name) { fprintf(stderr, "missing symbol %s\n", #name); return 2; }

#define CHECK(call)                                                                       \
    if ((call) != fmi3OK) { fprintf(stderr, "%s failed\n", #call); return 3; }

int main(int argc, char** argv)
{
    if (argc < 7) {
        fprintf(stderr, "usage: %s UNZIPDIR MODEL_IDENTIFIER TOKEN STEP N_STEPS EVENT_MODE "
                        "[in:VR=VALUE ...] [out:VR ...]\n", argv[0]);
        return 1;
    }
    char path[4096], resources[4096];
    snprintf(path, sizeof path, PLATFORM_BINARY, argv[1], argv[2]);
    snprintf(resources, sizeof resources, RESOURCES, argv[1]);
    double step = atof(argv[4]), next = NAN;
    int n_steps = atoi(argv[5]), event_mode = atoi(argv[6]);

    fmi3ValueReference in_vr[64], out_vr[64];
    fmi3Float64 in_value[64], out_value[64];
    size_t n_in = 0, n_out = 0;
    for (int i = 7; i < argc; ++i) {
        if (strncmp(argv[i], "in:", 3) == 0 && n_in < 64) {
            char* eq = strchr(argv[i], '=');
            if (!eq) return 1;
            in_vr[n_in] = (fmi3ValueReference)strtoul(argv[i] + 3, NULL, 10);
            in_value[n_in++] = atof(eq + 1);
        } else if (strncmp(argv[i], "out:", 4) == 0 && n_out < 64) {
            out_vr[n_out++] = (fmi3ValueReference)strtoul(argv[i] + 4, NULL, 10);
        }
    }
    library lib = open_library(path);
    if (!lib) {
        fprintf(stderr, "cannot load %s: %s\n", path, load_error());
        return 2;
    }
    LOAD(fmi3InstantiateCoSimulation) LOAD(fmi3EnterInitializationMode)
    LOAD(fmi3ExitInitializationMode) LOAD(fmi3SetFloat64) LOAD(fmi3GetFloat64)
    LOAD(fmi3DoStep) LOAD(fmi3EnterEventMode) LOAD(fmi3EnterStepMode)
    LOAD(fmi3UpdateDiscreteStates) LOAD(fmi3Terminate) LOAD(fmi3FreeInstance)

    fmi3Instance c = fmi3InstantiateCoSimulation("c_host", argv[3], resources, fmi3False,
                                                 fmi3False, event_mode ? fmi3True : fmi3False,
                                                 fmi3False, NULL, 0, NULL, logger, NULL);
    if (!c) {
        fprintf(stderr, "fmi3InstantiateCoSimulation failed\n");
        return 3;
    }
    fmi3Boolean need, term, nominals, values, defined, event, early;
    fmi3Float64 last;
    CHECK(fmi3EnterInitializationMode(c, fmi3False, 0.0, 0.0, fmi3False, 0.0))
    if (n_in) CHECK(fmi3SetFloat64(c, in_vr, n_in, in_value, n_in))
    CHECK(fmi3ExitInitializationMode(c))
    if (event_mode) {
        CHECK(fmi3UpdateDiscreteStates(c, &need, &term, &nominals, &values, &defined, &next))
        CHECK(fmi3EnterStepMode(c))
    }
    for (int k = 0; k < n_steps; ++k) {
        CHECK(fmi3DoStep(c, k * step, step, fmi3True, &event, &term, &early, &last))
        if (event_mode && event) {
            CHECK(fmi3EnterEventMode(c))
            CHECK(fmi3UpdateDiscreteStates(c, &need, &term, &nominals, &values, &defined,
                                           &next))
            CHECK(fmi3EnterStepMode(c))
        }
        if (n_out) CHECK(fmi3GetFloat64(c, out_vr, n_out, out_value, n_out))
        printf("%.17g", (k + 1) * step);
        for (size_t j = 0; j < n_out; ++j) printf(",%.17g", out_value[j]);
        printf(",%.17g\n", next);
    }
    CHECK(fmi3Terminate(c))
    fmi3FreeInstance(c);
    fprintf(stderr, "freed\n");
    fflush(NULL);
    return 0;
}
