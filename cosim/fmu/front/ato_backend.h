/*
 * ato_backend.h: the interface between the FMI 3.0 co-simulation front (fmi3_front.c) and a
 * model BACKEND that has FMI 2.0-shaped functions.
 *
 * The front implements the whole FMI 3.0 co-simulation API (fmi3Functions.h): the calling-
 * sequence state machine (FMI 3.0 sec. 2.3 and 4.2), Event Mode (hasEventMode), early return
 * from fmi3DoStep, the FMI 3 type and argument conversions and logging (errors reach the host's
 * logMessage even when logging is off). It forwards every model call to one backend, a table
 * of functions with the FMI 2.0 co-simulation signatures (fmi2FunctionTypes.h), so that
 *
 *  - a Python FMU's backend is pythonfmu's FMI 2 binary behind our shim
 *    (ato_backend_fmi2dl.c loads <modelIdentifier>_fmi2.so next to the front with dlopen);
 *  - a native C model is a second backend, linked statically into the same front: it defines
 *    ato_backend_get() returning its own table.
 *
 * Exactly one backend is linked with the front. It provides:
 *
 *     const ato_backend* ato_backend_get(char* error, size_t error_size);
 *
 * called once per process (from the first fmi3Instantiate*; never concurrently with itself).
 * It returns the table, or NULL after writing a NUL-terminated reason into `error` (which the
 * front reports through the host's logMessage).
 *
 * Contract of the table (FMI 2.0.4 sec. 2.1 and 4.2 semantics, co-simulation only):
 *
 *  - instantiate is called as fmi2Instantiate(instanceName, fmi2CoSimulation, instantiationToken,
 *    resourceURI, functions, visible, loggingOn): the GUID argument is the FMI 3
 *    instantiationToken unchanged (modelDescription.xml carries the same string in both builds);
 *    resourceURI is the FMI 3 resourcePath as a file:// URI (percent-encoded, no trailing slash
 *    added or removed); functions->componentEnvironment is the front's instance and
 *    functions->logger the front's logger (it maps fmi2 statuses to fmi3 ones and forwards to
 *    the host); allocateMemory/freeMemory are calloc/free; stepFinished is NULL (the front never
 *    asks for asynchronous steps).
 *  - Value references are the FMI 3 ones unchanged: Float64 <-> Real, Int32 <-> Integer,
 *    Boolean <-> Boolean (the front converts fmi3Boolean bool <-> fmi2Boolean int),
 *    String <-> String. The front rejects every other FMI 3 type itself.
 *  - setup_experiment, enter/exit_initialization_mode: the front calls setup_experiment then
 *    enter_initialization_mode from fmi3EnterInitializationMode, exit from fmi3ExitInitializationMode.
 *  - do_step(c, t, h, noSetFMUStatePriorToCurrentPoint) advances from t to t + h; the front
 *    never calls it with h <= 0. For a backend with event_time_vr >= 0 the front shortens a
 *    step that would pass over the announced event when the importer allowed early return.
 *  - FMU state: get/set/free/serialized_size/serialize/deserialize as in FMI 2; the front does
 *    not add anything to the state (it keeps no model data of its own).
 *  - Any entry may be NULL: the front then answers that FMI 3 call with fmi3Error and a log
 *    message naming the missing function (terminate, reset, instantiate and free_instance must
 *    not be NULL).
 *
 * Model facts the FMI 3 front needs and FMI 2 has no call for:
 *
 *  - event_time_vr: value reference of the Real (Float64) output that holds the time in seconds
 *    of the model's next event (our `next_event_time`, cosim/fmu/slave.py), or -1 for a model
 *    without events (a plant). With event_time_vr >= 0 the front's fmi3UpdateDiscreteStates
 *    returns nextEventTimeDefined = true and nextEventTime = that output, fmi3DoStep returns
 *    eventHandlingNeeded = true when the step ends at that time, and (earlyReturnAllowed) a
 *    step that would pass it stops there with earlyReturn = true. Its value must be read after
 *    the inputs of the current instant are set (it may depend on them) and be > the current
 *    time after an event.
 *  - literal_messages: 1 when the backend's logger calls pass the complete message as the
 *    format string without printf arguments (pythonfmu and our shim do; "%%" stands for "%"),
 *    0 for a standard FMI 2 backend whose message is a printf format with arguments.
 */
#ifndef ATO_BACKEND_H
#define ATO_BACKEND_H

#include <stddef.h>

#include "fmi2FunctionTypes.h"

#ifdef __cplusplus
extern "C" {
#endif

/* Value reference of the FMI 3 independent variable `time` (Float64, s; FMI 3.0 sec. 2.4
 * requires exactly one independent variable): the front answers fmi3GetFloat64 of it with the
 * instance's current time itself, so a backend must not use this value reference. */
#define ATO_TIME_VR 2147483647u

typedef struct ato_backend {
    const char* name; /* for messages, e.g. "pythonfmu (FMI 2) via the shim" */
    long event_time_vr;   /* see above; -1: no events */
    int literal_messages; /* see above */

    fmi2InstantiateTYPE* instantiate;
    fmi2FreeInstanceTYPE* free_instance;
    fmi2SetDebugLoggingTYPE* set_debug_logging;

    fmi2SetupExperimentTYPE* setup_experiment;
    fmi2EnterInitializationModeTYPE* enter_initialization_mode;
    fmi2ExitInitializationModeTYPE* exit_initialization_mode;
    fmi2TerminateTYPE* terminate;
    fmi2ResetTYPE* reset;

    fmi2GetRealTYPE* get_real;
    fmi2GetIntegerTYPE* get_integer;
    fmi2GetBooleanTYPE* get_boolean;
    fmi2GetStringTYPE* get_string;
    fmi2SetRealTYPE* set_real;
    fmi2SetIntegerTYPE* set_integer;
    fmi2SetBooleanTYPE* set_boolean;
    fmi2SetStringTYPE* set_string;

    fmi2DoStepTYPE* do_step;

    fmi2GetFMUstateTYPE* get_fmu_state;
    fmi2SetFMUstateTYPE* set_fmu_state;
    fmi2FreeFMUstateTYPE* free_fmu_state;
    fmi2SerializedFMUstateSizeTYPE* serialized_fmu_state_size;
    fmi2SerializeFMUstateTYPE* serialize_fmu_state;
    fmi2DeSerializeFMUstateTYPE* deserialize_fmu_state;
} ato_backend;

/* The linked backend's table, or NULL with a reason in error (see above). */
const ato_backend* ato_backend_get(char* error, size_t error_size);

#ifdef __cplusplus
}
#endif

#endif /* ATO_BACKEND_H */
