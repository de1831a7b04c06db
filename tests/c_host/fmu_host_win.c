/*
 * fmu_host_win.c: the Windows twin of fmu_host.c (LoadLibrary instead of dlopen), built with
 * mingw-w64 and run under Wine to step an FMU's binaries/win64/<id>.dll.
 *
 * usage: fmu_host_win UNZIPDIR MODEL_IDENTIFIER GUID STEP N_STEPS [in:VR=VALUE ...] [out:VR ...]
 * prints one line per step: time,out1,out2,... (%.17g); errors on stderr.
 */
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <windows.h>

#include "fmi2Functions.h"

static void logger(fmi2ComponentEnvironment env, fmi2String instance, fmi2Status status,
                   fmi2String category, fmi2String message, ...) {
    (void)env;
    fprintf(stderr, "[%s] status %d %s: %s\n", instance, (int)status,
            category ? category : "", message);
}

#define LOAD(T, name)                                                                  \
    T* name = (T*)(void*)GetProcAddress(lib, #name);                                  \
    if (!name) { fprintf(stderr, "missing symbol %s\n", #name); return 2; }
#define CHECK(call)                                                                    \
    if ((call) != fmi2OK) { fprintf(stderr, "%s failed\n", #call); return 3; }

int main(int argc, char** argv) {
    if (argc < 6) {
        fprintf(stderr, "usage: %s UNZIPDIR MODEL_IDENTIFIER GUID STEP N_STEPS "
                        "[in:VR=VALUE ...] [out:VR ...]\n", argv[0]);
        return 1;
    }
    char path[4096], resources[4200];
    snprintf(path, sizeof path, "%s\\binaries\\win64\\%s.dll", argv[1], argv[2]);
    snprintf(resources, sizeof resources, "file:///%s/resources", argv[1]);
    for (char* p = resources; *p; p++)
        if (*p == '\\') *p = '/';
    double step = atof(argv[4]);
    int n_steps = atoi(argv[5]);
    fmi2ValueReference in_vr[64], out_vr[64];
    double in_value[64], out_value[64];
    size_t n_in = 0, n_out = 0;
    for (int i = 6; i < argc; i++) {
        if (strncmp(argv[i], "in:", 3) == 0 && n_in < 64) {
            char* eq = strchr(argv[i], '=');
            if (!eq) return 1;
            in_vr[n_in] = (fmi2ValueReference)strtoul(argv[i] + 3, NULL, 10);
            in_value[n_in++] = atof(eq + 1);
        } else if (strncmp(argv[i], "out:", 4) == 0 && n_out < 64) {
            out_vr[n_out++] = (fmi2ValueReference)strtoul(argv[i] + 4, NULL, 10);
        }
    }
    HMODULE lib = LoadLibraryA(path);
    if (!lib) {
        fprintf(stderr, "LoadLibrary %s failed: %lu\n", path, (unsigned long)GetLastError());
        return 2;
    }
    LOAD(fmi2InstantiateTYPE, fmi2Instantiate)
    LOAD(fmi2SetupExperimentTYPE, fmi2SetupExperiment)
    LOAD(fmi2EnterInitializationModeTYPE, fmi2EnterInitializationMode)
    LOAD(fmi2ExitInitializationModeTYPE, fmi2ExitInitializationMode)
    LOAD(fmi2SetRealTYPE, fmi2SetReal)
    LOAD(fmi2GetRealTYPE, fmi2GetReal)
    LOAD(fmi2DoStepTYPE, fmi2DoStep)
    LOAD(fmi2TerminateTYPE, fmi2Terminate)
    LOAD(fmi2FreeInstanceTYPE, fmi2FreeInstance)
    fmi2CallbackFunctions cb = {logger, calloc, free, NULL, NULL};
    fmi2Component c = fmi2Instantiate("win_host", fmi2CoSimulation, argv[3], resources, &cb,
                                      fmi2False, fmi2False);
    if (!c) {
        fprintf(stderr, "fmi2Instantiate failed\n");
        return 3;
    }
    CHECK(fmi2SetupExperiment(c, fmi2False, 0.0, 0.0, fmi2False, 0.0))
    CHECK(fmi2EnterInitializationMode(c))
    CHECK(fmi2ExitInitializationMode(c))
    for (int k = 0; k < n_steps; k++) {
        CHECK(fmi2SetReal(c, in_vr, n_in, in_value))
        CHECK(fmi2DoStep(c, k * step, step, fmi2True))
        CHECK(fmi2GetReal(c, out_vr, n_out, out_value))
        printf("%.17g", (k + 1) * step);
        for (size_t j = 0; j < n_out; j++) printf(",%.17g", out_value[j]);
        printf("\n");
    }
    CHECK(fmi2Terminate(c))
    fmi2FreeInstance(c);
    FreeLibrary(lib);
    return 0;
}
