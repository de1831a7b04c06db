/*
 * The backend of our Python FMUs for the FMI 3 front (ato_backend.h): an FMI 2.0 co-simulation
 * binary loaded with dlopen, namely our shim (cosim/fmu/pythonfmu_shim.c) in front of
 * pythonfmu's binary, shipped next to the front as <modelIdentifier>_fmi2.so (the shim then
 * finds pythonfmu's binary as <modelIdentifier>_fmi2_pythonfmu.so).
 *
 * Compile-time setting (cosim/build/python.py): ATO_EVENT_TIME_VR, the value reference of the
 * model's `next_event_time` output, or -1 (a plant: no events).
 */
#define _GNU_SOURCE
#include <dlfcn.h>
#include <stdio.h>
#include <string.h>

#include "ato_backend.h"

#ifndef ATO_EVENT_TIME_VR
#define ATO_EVENT_TIME_VR -1
#endif
#define ATO_FMI2_SUFFIX "_fmi2.so"

static ato_backend table;

const ato_backend* ato_backend_get(char* error, size_t error_size)
{
    Dl_info info;
    char path[4096];
    if (!dladdr((void*)&ato_backend_get, &info) || !info.dli_fname) {
        snprintf(error, error_size, "cannot locate the FMU binary (dladdr)");
        return NULL;
    }
    size_t n = strlen(info.dli_fname);
    if (n < 3 || strcmp(info.dli_fname + n - 3, ".so") != 0 ||
        n - 3 + sizeof ATO_FMI2_SUFFIX > sizeof path) {
        snprintf(error, error_size, "unexpected FMU binary name %s", info.dli_fname);
        return NULL;
    }
    memcpy(path, info.dli_fname, n - 3);
    memcpy(path + n - 3, ATO_FMI2_SUFFIX, sizeof ATO_FMI2_SUFFIX);
    /* loaded for the life of the process: the shim keeps pythonfmu's binary loaded until
     * exit for the same reason (see its header) */
    void* lib = dlopen(path, RTLD_NOW | RTLD_LOCAL | RTLD_NODELETE);
    if (!lib) {
        const char* err = dlerror();
        snprintf(error, error_size, "cannot load the model's FMI 2 binary: %s",
                 err ? err : path);
        return NULL;
    }
    table.name = "pythonfmu (FMI 2) behind the shim";
    table.event_time_vr = ATO_EVENT_TIME_VR;
    table.literal_messages = 1; /* pythonfmu and the shim pass complete messages */
#define LOAD(field, symbol) *(void**)(&table.field) = dlsym(lib, #symbol);
    LOAD(instantiate, fmi2Instantiate)
    LOAD(free_instance, fmi2FreeInstance)
    LOAD(set_debug_logging, fmi2SetDebugLogging)
    LOAD(setup_experiment, fmi2SetupExperiment)
    LOAD(enter_initialization_mode, fmi2EnterInitializationMode)
    LOAD(exit_initialization_mode, fmi2ExitInitializationMode)
    LOAD(terminate, fmi2Terminate)
    LOAD(reset, fmi2Reset)
    LOAD(get_real, fmi2GetReal)
    LOAD(get_integer, fmi2GetInteger)
    LOAD(get_boolean, fmi2GetBoolean)
    LOAD(get_string, fmi2GetString)
    LOAD(set_real, fmi2SetReal)
    LOAD(set_integer, fmi2SetInteger)
    LOAD(set_boolean, fmi2SetBoolean)
    LOAD(set_string, fmi2SetString)
    LOAD(do_step, fmi2DoStep)
    LOAD(get_fmu_state, fmi2GetFMUstate)
    LOAD(set_fmu_state, fmi2SetFMUstate)
    LOAD(free_fmu_state, fmi2FreeFMUstate)
    LOAD(serialized_fmu_state_size, fmi2SerializedFMUstateSize)
    LOAD(serialize_fmu_state, fmi2SerializeFMUstate)
    LOAD(deserialize_fmu_state, fmi2DeSerializeFMUstate)
#undef LOAD
    if (!table.instantiate || !table.free_instance || !table.terminate || !table.reset) {
        snprintf(error, error_size, "%s lacks fmi2Instantiate, fmi2FreeInstance, "
                 "fmi2Terminate or fmi2Reset", path);
        return NULL;
    }
    return &table;
}
