/*
 * FMI 2.0 co-simulation shim in front of pythonfmu 0.7's binary (linux64).
 *
 * `cosim build` compiles this file once (gcc, fmpy's FMI 2 headers) and ships it in every FMU
 * as binaries/linux64/<modelIdentifier>.so; pythonfmu's own binary sits next to it as
 * binaries/linux64/<modelIdentifier>_pythonfmu.so. The shim
 *
 * 1. loads libpython itself when the host process has no Python (a plain C/C++ tool): without
 *    it pythonfmu's binary fails to load ("undefined symbol: _Py_NoneStruct") unless the host
 *    was started with LD_PRELOAD=libpython. It tries the absolute path recorded at build time,
 *    then the soname, with RTLD_GLOBAL (pythonfmu's binary does not link libpython and
 *    resolves the Python C API from the global scope);
 * 2. loads pythonfmu's binary (found next to this file with dladdr) and forwards every FMI 2.0
 *    function to it; the model-exchange functions, which pythonfmu does not export, and any
 *    other missing function return fmi2Error with a log message;
 * 3. reports fmi2Fatal from pythonfmu as fmi2Error, in return values and in log messages.
 *    pythonfmu 0.7 turns *every* Python exception raised by the slave into fmi2Fatal. Our
 *    slaves (cosim/fmu/slave.py) raise only to reject a call (wrong state, NaN/inf input,
 *    out-of-range parameter, bad step size), log the reason, and keep the instance valid (they
 *    restore the references pythonfmu drops on an exception), so the FMI 2.0 status for these
 *    rejections is fmi2Error: this instance's call failed; the instance can still be reset or
 *    freed and other instances are unaffected (fmi2Fatal would mean all instances are lost).
 * 4. keeps pythonfmu's binary loaded until the process exits and then tears it down from an
 *    exit handler, avoiding pythonfmu 0.7's heap corruption at exit (see load()).
 * 5. delivers warnings and errors whatever the host's logging flag (pythonfmu 0.7 passes its
 *    messages to the logger only with logging on, so it is instantiated with logging on and
 *    the shim drops the fmi2OK messages while the host's loggingOn / fmi2SetDebugLogging is
 *    off), as the Reference FMUs do: with fmpy's default (logging off) the user sees why a
 *    call failed.
 *
 * Instances are wrapped: the shim passes pythonfmu its own callback structure (pythonfmu keeps
 * a pointer to it) whose logger maps the status and calls the host's logger with the host's
 * componentEnvironment. pythonfmu 0.7 always passes the complete message as the format string
 * without arguments, '%' not escaped, so the logger forwards it with every '%' doubled: a host
 * that formats the message (FMI 2.0.4 sec. 2.1.5) prints it unchanged.
 *
 * Compile-time settings (cosim/build/python.py): SHIM_LIBPYTHON_SONAME, SHIM_LIBPYTHON_PATH (strings,
 * may be empty).
 */
#define _GNU_SOURCE
#include <dlfcn.h>
#include <pthread.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fmi2Functions.h"
#include "front/instance_registry.h"

#ifndef SHIM_LIBPYTHON_SONAME
#define SHIM_LIBPYTHON_SONAME ""
#endif
#ifndef SHIM_LIBPYTHON_PATH
#define SHIM_LIBPYTHON_PATH ""
#endif
#define SHIM_SUFFIX "_pythonfmu.so"

/* every function pythonfmu may export (it exports the co-simulation ones) */
#define SHIM_FUNCTIONS(X)                                                                   \
    X(fmi2GetTypesPlatform) X(fmi2GetVersion) X(fmi2SetDebugLogging) X(fmi2Instantiate)     \
    X(fmi2FreeInstance) X(fmi2SetupExperiment) X(fmi2EnterInitializationMode)               \
    X(fmi2ExitInitializationMode) X(fmi2Terminate) X(fmi2Reset) X(fmi2GetReal)              \
    X(fmi2GetInteger) X(fmi2GetBoolean) X(fmi2GetString) X(fmi2SetReal) X(fmi2SetInteger)   \
    X(fmi2SetBoolean) X(fmi2SetString) X(fmi2GetFMUstate) X(fmi2SetFMUstate)                \
    X(fmi2FreeFMUstate) X(fmi2SerializedFMUstateSize) X(fmi2SerializeFMUstate)              \
    X(fmi2DeSerializeFMUstate) X(fmi2GetDirectionalDerivative) X(fmi2EnterEventMode)        \
    X(fmi2NewDiscreteStates) X(fmi2EnterContinuousTimeMode) X(fmi2CompletedIntegratorStep)  \
    X(fmi2SetTime) X(fmi2SetContinuousStates) X(fmi2GetDerivatives)                         \
    X(fmi2GetEventIndicators) X(fmi2GetContinuousStates)                                    \
    X(fmi2GetNominalsOfContinuousStates) X(fmi2SetRealInputDerivatives)                     \
    X(fmi2GetRealOutputDerivatives) X(fmi2DoStep) X(fmi2CancelStep) X(fmi2GetStatus)        \
    X(fmi2GetRealStatus) X(fmi2GetIntegerStatus) X(fmi2GetBooleanStatus)                    \
    X(fmi2GetStringStatus)

static struct {
#define X(name) name##TYPE* name;
    SHIM_FUNCTIONS(X)
#undef X
} inner;

static pthread_once_t load_once = PTHREAD_ONCE_INIT;
static void* inner_lib = NULL;
static void (*inner_finalize)(void) = NULL; /* pythonfmu's finalizePythonInterpreter */
static char load_error[8192] = "";

/* one wrapped instance */
typedef struct {
    fmi2Component inner;
    fmi2CallbackFunctions host;   /* the host's callbacks */
    fmi2CallbackFunctions mine;   /* given to pythonfmu: our logger, this struct as env */
    char name[256];               /* instance name, for the shim's own messages */
    fmi2Boolean logging_on;       /* the host's loggingOn / fmi2SetDebugLogging */
} Shim;

static fmi2Status mapped(fmi2Status status)
{
    /* see the header: a Python exception in our slave is a rejected call, not a lost FMU */
    return status == fmi2Fatal ? fmi2Error : status;
}

/* ``message`` as a printf format without arguments ('%' doubled, cut to ``size``): the FMI 2
 * logger's message is a format (FMI 2.0.4 sec. 2.1.5), a host formats it with vsnprintf */
static void as_format(const char* message, char* out, size_t size)
{
    size_t j = 0;
    for (size_t i = 0; message[i] && j + 2 < size; ++i) {
        if (message[i] == '%')
            out[j++] = '%';
        out[j++] = message[i];
    }
    out[j] = '\0';
}

static void shim_logger(fmi2ComponentEnvironment env, fmi2String instanceName,
                        fmi2Status status, fmi2String category, fmi2String message, ...)
{
    static const char prefix[] = "Fatal py exception encountered: ";
    Shim* s = (Shim*)env;
    if (!s || !s->host.logger)
        return;
    if (status == fmi2OK && !s->logging_on)
        return; /* pythonfmu runs with logging on (see 5.); ok messages only when asked */
    if (status == fmi2Fatal && message && strncmp(message, prefix, sizeof prefix - 1) == 0) {
        /* pythonfmu's wording for any Python exception; the call was rejected, see above */
        char text[8192], format[16400];
        snprintf(text, sizeof text, "Python exception, call rejected with fmi2Error: %s",
                 message + sizeof prefix - 1);
        as_format(text, format, sizeof format);
        s->host.logger(s->host.componentEnvironment, instanceName, fmi2Error, category, format);
        return;
    }
    char format[16400];
    as_format(message ? message : "", format, sizeof format);
    s->host.logger(s->host.componentEnvironment, instanceName, mapped(status), category,
                   format);
}

/* a message of the shim itself, passed as a format without arguments like pythonfmu's */
static void log_message(const fmi2CallbackFunctions* f, fmi2String instanceName,
                        const char* message)
{
    char text[16400];
    if (!f || !f->logger)
        return;
    as_format(message, text, sizeof text);
    f->logger(f->componentEnvironment, instanceName ? instanceName : "", fmi2Error,
              "logStatusError", text);
}

static int load_libpython(void)
{
    if (dlsym(RTLD_DEFAULT, "Py_IsInitialized") != NULL)
        return 1; /* a Python host (or a preloaded/linked libpython): nothing to do */
    /* the absolute path first: the soname alone can find another installation of the same
     * Python version (e.g. the distribution's /lib/x86_64-linux-gnu/libpython3.11.so.1.0
     * for a pyenv build), whose interpreter lacks the FMU's packages; the soname is the
     * fallback for an FMU copied to a machine where that Python lives elsewhere */
    const char* candidates[] = {SHIM_LIBPYTHON_PATH, SHIM_LIBPYTHON_SONAME};
    char tried[2048] = "";
    for (size_t i = 0; i < sizeof candidates / sizeof *candidates; ++i) {
        if (!candidates[i][0])
            continue;
        if (dlopen(candidates[i], RTLD_NOW | RTLD_GLOBAL))
            return 1;
        const char* err = dlerror();
        size_t used = strlen(tried);
        snprintf(tried + used, sizeof tried - used, "%s%s", used ? "; " : "",
                 err ? err : candidates[i]);
    }
    snprintf(load_error, sizeof load_error,
             "cannot load the Python library this FMU was built with (%s); start the host "
             "with LD_PRELOAD=<libpython3.X.so> or install that Python",
             tried[0] ? tried : "no shared libpython recorded at build time");
    return 0;
}

static void finalize_at_exit(void)
{
    inner_finalize();
}

static void load(void)
{
    if (!load_libpython())
        return;
    Dl_info info;
    if (!dladdr((void*)&mapped, &info) || !info.dli_fname) {
        snprintf(load_error, sizeof load_error, "cannot locate the FMU binary (dladdr)");
        return;
    }
    char path[4096];
    size_t n = strlen(info.dli_fname);
    if (n < 3 || strcmp(info.dli_fname + n - 3, ".so") != 0 ||
        n - 3 + sizeof SHIM_SUFFIX > sizeof path) {
        snprintf(load_error, sizeof load_error, "unexpected FMU binary name %s",
                 info.dli_fname);
        return;
    }
    memcpy(path, info.dli_fname, n - 3);
    memcpy(path + n - 3, SHIM_SUFFIX, sizeof SHIM_SUFFIX);
    inner_lib = dlopen(path, RTLD_NOW | RTLD_LOCAL);
    if (!inner_lib) {
        const char* err = dlerror();
        snprintf(load_error, sizeof load_error, "cannot load pythonfmu's binary: %s",
                 err ? err : path);
        return;
    }
#define X(name) *(void**)(&inner.name) = dlsym(inner_lib, #name);
    SHIM_FUNCTIONS(X)
#undef X
    if (!inner.fmi2Instantiate || !inner.fmi2FreeInstance) {
        snprintf(load_error, sizeof load_error, "%s does not export fmi2Instantiate", path);
        inner_lib = NULL;
        return;
    }
    /* pythonfmu's teardown is safe only before the exit handlers run: its library destructor
     * resets a static std::shared_ptr that the C++ exit handlers (registered when the library
     * was loaded) have already destroyed, which corrupts the heap at exit ("corrupted
     * double-linked list"), in any host that has not unloaded the library by then. So this
     * shim, and with it pythonfmu's binary, stays loaded until exit (RTLD_NODELETE: this also
     * makes unloading and reloading the FMU safe), and an exit handler registered now, after
     * pythonfmu's, runs before them and tears pythonfmu down in the order it expects. */
    dlopen(info.dli_fname, RTLD_NOW | RTLD_NOLOAD | RTLD_NODELETE);
    *(void**)(&inner_finalize) = dlsym(inner_lib, "finalizePythonInterpreter");
    if (inner_finalize)
        atexit(finalize_at_exit);
}

static int loaded(void)
{
    pthread_once(&load_once, load);
    return inner_lib != NULL;
}

static fmi2Status unsupported(fmi2Component c, const char* function)
{
    Shim* s = (Shim*)c;
    char text[256];
    snprintf(text, sizeof text, "%s is not supported by this FMU (co-simulation only)",
             function);
    if (s)
        log_message(&s->host, s->name, text);
    return fmi2Error;
}

/* forward a status function: NAME(c, ...) -> inner NAME(inner c, ...), fatal -> error */
#define FORWARD(name, params, args)                                                         \
    fmi2Status name params                                                                  \
    {                                                                                       \
        Shim* s = (Shim*)c;                                                                 \
        if (!s || !s->inner)                                                                \
            return fmi2Error;                                                               \
        if (!inner.name)                                                                    \
            return unsupported(c, #name);                                                   \
        return mapped(inner.name args);                                                     \
    }

/* -- inquire platform and version, logging ------------------------------------------------- */
const char* fmi2GetTypesPlatform(void)
{
    return loaded() && inner.fmi2GetTypesPlatform ? inner.fmi2GetTypesPlatform()
                                                  : fmi2TypesPlatform;
}

const char* fmi2GetVersion(void)
{
    return loaded() && inner.fmi2GetVersion ? inner.fmi2GetVersion() : fmi2Version;
}

fmi2Status fmi2SetDebugLogging(fmi2Component c, fmi2Boolean loggingOn, size_t nCategories,
                               const fmi2String categories[])
{
    /* pythonfmu keeps logging on (see 5.): the shim filters the ok messages itself */
    Shim* s = (Shim*)c;
    if (!s || !s->inner)
        return fmi2Error;
    s->logging_on = loggingOn;
    (void)nCategories;
    (void)categories;
    return fmi2OK;
}

/* -- creation and destruction -------------------------------------------------------------- */
fmi2Component fmi2Instantiate(fmi2String instanceName, fmi2Type fmuType, fmi2String fmuGUID,
                              fmi2String fmuResourceLocation,
                              const fmi2CallbackFunctions* functions, fmi2Boolean visible,
                              fmi2Boolean loggingOn)
{
    if (!functions)
        return NULL;
    if (fmuType != fmi2CoSimulation) {
        log_message(functions, instanceName, "this FMU supports co-simulation only");
        return NULL;
    }
    if (!loaded()) {
        log_message(functions, instanceName, load_error);
        return NULL;
    }
    Shim* s = (Shim*)calloc(1, sizeof *s);
    if (!s)
        return NULL;
    s->host = *functions;
    s->mine = *functions;
    s->mine.logger = shim_logger;
    s->mine.stepFinished = NULL;
    s->mine.componentEnvironment = s;
    snprintf(s->name, sizeof s->name, "%s", instanceName ? instanceName : "");
    s->logging_on = loggingOn;
    s->inner = inner.fmi2Instantiate(instanceName, fmuType, fmuGUID, fmuResourceLocation,
                                     &s->mine, visible, fmi2True);
    if (!s->inner) {
        char text[8192];
        Dl_info info;
        void* py = dlsym(RTLD_DEFAULT, "Py_IsInitialized");
        snprintf(text, sizeof text, "pythonfmu could not instantiate the model (Python "
                 "library %s; are the FMU's packages importable by that Python? set "
                 "PYTHONPATH for a virtual environment; instantiate with loggingOn for "
                 "pythonfmu's message)",
                 py && dladdr(py, &info) && info.dli_fname ? info.dli_fname : "?");
        log_message(functions, instanceName, text);
        free(s);
        return NULL;
    }
    if (!registry_add(s)) {
        log_message(functions, instanceName, "out of memory");
        inner.fmi2FreeInstance(s->inner);
        free(s);
        return NULL;
    }
    return s;
}

/* what a second fmi2FreeInstance needs for its message (front/instance_registry.h) */
typedef struct {
    fmi2CallbackFunctions host;
    char name[256];
} FreedMemo;

void fmi2FreeInstance(fmi2Component c)
{
    Shim* s = (Shim*)c;
    unsigned char buf[REGISTRY_MEMO] = {0};
    FreedMemo memo;
    char text[512];
    if (!s)
        return;
    if (registry_is_live(s)) { /* pythonfmu aborts on a second delete of its slave */
        memset(&memo, 0, sizeof memo);
        memo.host = s->host;
        snprintf(memo.name, sizeof memo.name, "%s", s->name);
        memcpy(buf, &memo, sizeof memo);
        registry_release(s, buf);
        if (s->inner)
            inner.fmi2FreeInstance(s->inner);
        free(s);
        return;
    }
    if (registry_release(s, buf) == -1) {
        memcpy(&memo, buf, sizeof memo);
        snprintf(text, sizeof text, "fmi2FreeInstance: instance '%s' was freed already; call "
                 "refused", memo.name);
        log_message(&memo.host, memo.name, text);
    } else {
        fprintf(stderr, "fmi2FreeInstance: %p is not a live instance of this FMU; call "
                "refused\n", c);
    }
}

/* -- initialisation, termination, reset ---------------------------------------------------- */
FORWARD(fmi2SetupExperiment,
        (fmi2Component c, fmi2Boolean toleranceDefined, fmi2Real tolerance, fmi2Real startTime,
         fmi2Boolean stopTimeDefined, fmi2Real stopTime),
        (s->inner, toleranceDefined, tolerance, startTime, stopTimeDefined, stopTime))
FORWARD(fmi2EnterInitializationMode, (fmi2Component c), (s->inner))
FORWARD(fmi2ExitInitializationMode, (fmi2Component c), (s->inner))
FORWARD(fmi2Terminate, (fmi2Component c), (s->inner))
FORWARD(fmi2Reset, (fmi2Component c), (s->inner))

/* -- getting and setting variable values --------------------------------------------------- */
FORWARD(fmi2GetReal,
        (fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2Real value[]),
        (s->inner, vr, nvr, value))
FORWARD(fmi2GetInteger,
        (fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2Integer value[]),
        (s->inner, vr, nvr, value))
FORWARD(fmi2GetBoolean,
        (fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2Boolean value[]),
        (s->inner, vr, nvr, value))
FORWARD(fmi2GetString,
        (fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2String value[]),
        (s->inner, vr, nvr, value))
FORWARD(fmi2SetReal,
        (fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const fmi2Real value[]),
        (s->inner, vr, nvr, value))
FORWARD(fmi2SetInteger,
        (fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
         const fmi2Integer value[]),
        (s->inner, vr, nvr, value))
FORWARD(fmi2SetBoolean,
        (fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
         const fmi2Boolean value[]),
        (s->inner, vr, nvr, value))
FORWARD(fmi2SetString,
        (fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
         const fmi2String value[]),
        (s->inner, vr, nvr, value))

/* -- FMU state ------------------------------------------------------------------------------ */
FORWARD(fmi2GetFMUstate, (fmi2Component c, fmi2FMUstate* state), (s->inner, state))
FORWARD(fmi2SetFMUstate, (fmi2Component c, fmi2FMUstate state), (s->inner, state))
FORWARD(fmi2FreeFMUstate, (fmi2Component c, fmi2FMUstate* state), (s->inner, state))
FORWARD(fmi2SerializedFMUstateSize, (fmi2Component c, fmi2FMUstate state, size_t* size),
        (s->inner, state, size))
FORWARD(fmi2SerializeFMUstate,
        (fmi2Component c, fmi2FMUstate state, fmi2Byte serializedState[], size_t size),
        (s->inner, state, serializedState, size))
FORWARD(fmi2DeSerializeFMUstate,
        (fmi2Component c, const fmi2Byte serializedState[], size_t size,
         fmi2FMUstate* state),
        (s->inner, serializedState, size, state))

/* -- derivatives ----------------------------------------------------------------------------- */
FORWARD(fmi2GetDirectionalDerivative,
        (fmi2Component c, const fmi2ValueReference vUnknown_ref[], size_t nUnknown,
         const fmi2ValueReference vKnown_ref[], size_t nKnown, const fmi2Real dvKnown[],
         fmi2Real dvUnknown[]),
        (s->inner, vUnknown_ref, nUnknown, vKnown_ref, nKnown, dvKnown, dvUnknown))

/* -- model exchange (pythonfmu does not export these: fmi2Error "not supported") ----------- */
FORWARD(fmi2EnterEventMode, (fmi2Component c), (s->inner))
FORWARD(fmi2NewDiscreteStates, (fmi2Component c, fmi2EventInfo* fmi2eventInfo),
        (s->inner, fmi2eventInfo))
FORWARD(fmi2EnterContinuousTimeMode, (fmi2Component c), (s->inner))
FORWARD(fmi2CompletedIntegratorStep,
        (fmi2Component c, fmi2Boolean noSetFMUStatePriorToCurrentPoint,
         fmi2Boolean* enterEventMode, fmi2Boolean* terminateSimulation),
        (s->inner, noSetFMUStatePriorToCurrentPoint, enterEventMode, terminateSimulation))
FORWARD(fmi2SetTime, (fmi2Component c, fmi2Real time), (s->inner, time))
FORWARD(fmi2SetContinuousStates, (fmi2Component c, const fmi2Real x[], size_t nx),
        (s->inner, x, nx))
FORWARD(fmi2GetDerivatives, (fmi2Component c, fmi2Real derivatives[], size_t nx),
        (s->inner, derivatives, nx))
FORWARD(fmi2GetEventIndicators, (fmi2Component c, fmi2Real eventIndicators[], size_t ni),
        (s->inner, eventIndicators, ni))
FORWARD(fmi2GetContinuousStates, (fmi2Component c, fmi2Real x[], size_t nx),
        (s->inner, x, nx))
FORWARD(fmi2GetNominalsOfContinuousStates, (fmi2Component c, fmi2Real x_nominal[], size_t nx),
        (s->inner, x_nominal, nx))

/* -- co-simulation ----------------------------------------------------------------------------- */
FORWARD(fmi2SetRealInputDerivatives,
        (fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
         const fmi2Integer order[], const fmi2Real value[]),
        (s->inner, vr, nvr, order, value))
FORWARD(fmi2GetRealOutputDerivatives,
        (fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
         const fmi2Integer order[], fmi2Real value[]),
        (s->inner, vr, nvr, order, value))
FORWARD(fmi2DoStep,
        (fmi2Component c, fmi2Real currentCommunicationPoint,
         fmi2Real communicationStepSize, fmi2Boolean noSetFMUStatePriorToCurrentPoint),
        (s->inner, currentCommunicationPoint, communicationStepSize,
         noSetFMUStatePriorToCurrentPoint))
FORWARD(fmi2CancelStep, (fmi2Component c), (s->inner))
FORWARD(fmi2GetStatus, (fmi2Component c, const fmi2StatusKind kind, fmi2Status* value),
        (s->inner, kind, value))
FORWARD(fmi2GetRealStatus, (fmi2Component c, const fmi2StatusKind kind, fmi2Real* value),
        (s->inner, kind, value))
FORWARD(fmi2GetIntegerStatus, (fmi2Component c, const fmi2StatusKind kind, fmi2Integer* value),
        (s->inner, kind, value))
FORWARD(fmi2GetBooleanStatus, (fmi2Component c, const fmi2StatusKind kind, fmi2Boolean* value),
        (s->inner, kind, value))
FORWARD(fmi2GetStringStatus, (fmi2Component c, const fmi2StatusKind kind, fmi2String* value),
        (s->inner, kind, value))
