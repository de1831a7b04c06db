/*
 * FMI 3.0 co-simulation front in front of a backend with FMI 2.0-shaped functions
 * (ato_backend.h; the Python FMUs' backend is ato_backend_fmi2dl.c).
 *
 * `cosim build --fmi 3` compiles this file with one backend into every FMI 3 FMU's
 * binaries/x86_64-linux/<modelIdentifier>.so. The front
 *
 * 1. keeps the FMI 3.0 co-simulation state machine (FMI 3.0 sec. 4.2, State Machine for
 *    Co-Simulation): Instantiated -> Initialization Mode -> (Event Mode <-> Step Mode) ->
 *    Terminated, with fmi3Reset back to Instantiated; a call made in a state where the
 *    standard does not allow it is answered with fmi3Error and a message naming the call and
 *    the state, and the backend is not called;
 * 2. implements Event Mode (hasEventMode, FMI 3.0 sec. 2.3.5 and 4.2) for a backend that has
 *    an event-time output (ato_backend.event_time_vr): fmi3UpdateDiscreteStates returns
 *    nextEventTimeDefined = true and nextEventTime = that output; fmi3DoStep sets
 *    eventHandlingNeeded when the step ends at the announced event; and, when the importer
 *    instantiated with earlyReturnAllowed, a step that would pass over the announced event is
 *    stepped only up to it and returns earlyReturn = true with lastSuccessfulTime = the event
 *    time (FMI 3.0 sec. 4.1.3 and 4.2.1, fmi3DoStep "earlyReturn"). Without early return the full step is
 *    forwarded: the FMU then behaves exactly as its FMI 2 twin (which computes or refuses it);
 * 3. converts FMI 3 arguments to FMI 2 ones: Float64 -> Real, Int32 -> Integer, Boolean
 *    (bool) -> Boolean (int), String -> String; the other FMI 3 types (and clocks, binaries,
 *    model exchange, scheduled execution, configuration mode, derivatives) have no variables
 *    in these FMUs and are answered with fmi3Error and a message unless no value is asked for;
 * 4. logs: its own errors always reach the host's logMessage (whatever loggingOn says); the
 *    backend's messages are forwarded with the FMI 3 status of equal meaning.
 *
 * The front keeps no model data; it answers the independent variable `time` (ATO_TIME_VR)
 * itself, and its FMU state is the backend's with that time. It has no Python in it.
 *
 * Clocked builds (`cosim build --fmi 3 --clock periodic|countdown`, cosim/build/fmi3.py) compile
 * it with ATO_CLOCK_VR, the value reference of one input Clock that activates the model's
 * events (FMI 3.0 sec. 2.2.8, 2.3.5), instead of announcing them as nextEventTime:
 *
 *  - ATO_CLOCK_COUNTDOWN = 0: a `fixed` periodic Clock of interval the Real parameter of value
 *    reference ATO_SAMPLE_TIME_VR (fmi3GetIntervalDecimal in Initialization Mode; shift 0:
 *    the first tick at the start time); an event whose next one is not one interval later (a
 *    self-triggered model) is an error;
 *  - ATO_CLOCK_COUNTDOWN = 1: a `countdown` Clock: in Event Mode fmi3GetIntervalDecimal gives
 *    fmi3IntervalChanged and the time from now to the backend's next event once per new next
 *    event, fmi3IntervalUnchanged otherwise.
 *
 * fmi3UpdateDiscreteStates then says nextEventTimeDefined = false and fmi3DoStep neither sets
 * eventHandlingNeeded nor returns early (mightReturnEarlyFromDoStep = false: the importer ticks
 * the Clock, and a step over a tick runs that event with the inputs held, as the FMI 2 twin
 * does); the backend is unchanged, so the events are those of the unclocked build when the
 * Clock ticks at its announced times.
 *
 * Scheduled Execution builds (`--interface se`) are also compiled with ATO_SCHEDULED = 1: the
 * same Clock, now the input Clock of the model's one model partition (FMI 3.0 chap. 5), and
 * fmi3InstantiateScheduledExecution in place of fmi3InstantiateCoSimulation. After
 * fmi3ExitInitializationMode the FMU is in Clock Activation Mode (sec. 5.2.1);
 * fmi3ActivateModelPartition(sample, t) is the event at t:
 *
 *  1. the backend steps from the previous activation to t (fmi2DoStep: it commits the event
 *     of the previous activation with the inputs it had there);
 *  2. the inputs set since the previous activation reach the backend (fmi3Set* in Clock
 *     Activation Mode are held by the front until then: sec. 5.2.1 sets inputs before the
 *     activation that uses them, and the backend, one event behind, still needs the previous
 *     ones to commit it);
 *  3. the event at t is computed from them (the backend's event-time output is read): its
 *     outputs are what fmi3Get* gives until the next activation;
 *  4. countdown: the front calls fmi3ClockUpdateCallback when the backend's next event is a
 *     new one, and fmi3GetIntervalDecimal gives the time to it (fmi3IntervalChanged, sec.
 *     2.2.8.2 and 5.2.2, Clock Update Mode); in Initialization Mode it gives 0 (the model's
 *     first event is at the start time: the first tick, t_0 = t_start + 0).
 *
 * The events, their inputs and their outputs are those of the co-simulation build whose
 * Clock ticks at the same times. FMU state is not offered (its held inputs are not in the
 * backend's state: canGetAndSetFMUState = false).
 */
#define _GNU_SOURCE
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "ato_backend.h"
#include "fmi3Functions.h"
#include "instance_registry.h"

#ifndef ATO_CLOCK_VR
#define ATO_CLOCK_VR -1L /* the input Clock's value reference; -1: no clock (see above) */
#endif
#ifndef ATO_CLOCK_COUNTDOWN
#define ATO_CLOCK_COUNTDOWN 0
#endif
#ifndef ATO_SAMPLE_TIME_VR
#define ATO_SAMPLE_TIME_VR -1L
#endif
#ifndef ATO_SCHEDULED
#define ATO_SCHEDULED 0 /* 1: a Scheduled Execution build (see above) */
#endif
#define CLOCKED (ATO_CLOCK_VR >= 0)
#if ATO_SCHEDULED
#define STATE_MACHINE "FMI 3.0 sec. 5.2, state machine for Scheduled Execution"
#else
#define STATE_MACHINE "FMI 3.0 sec. 4.2, co-simulation state machine"
#endif

typedef enum {
    MODE_INSTANTIATED,
    MODE_INITIALIZATION,
    MODE_EVENT,
    MODE_STEP,
    MODE_TERMINATED,
    MODE_CLOCK_ACTIVATION, /* Scheduled Execution (sec. 5.2.1) */
    MODE_FAILED /* after fmi3Fatal from the backend: only fmi3FreeInstance is allowed */
} Mode;

static const char* const MODE_NAMES[] = {"Instantiated", "Initialization Mode", "Event Mode",
                                         "Step Mode", "Terminated", "Clock Activation Mode",
                                         "failed (fatal error)"};

enum {
    ALLOW_INSTANTIATED = 1 << MODE_INSTANTIATED,
    ALLOW_INITIALIZATION = 1 << MODE_INITIALIZATION,
    ALLOW_EVENT = 1 << MODE_EVENT,
    ALLOW_STEP = 1 << MODE_STEP,
    ALLOW_TERMINATED = 1 << MODE_TERMINATED,
    ALLOW_CLOCK_ACTIVATION = 1 << MODE_CLOCK_ACTIVATION,
};

/* an input set in Clock Activation Mode, held until the next activation (see above) */
typedef struct {
    char kind; /* 'r' Real, 'i' Integer, 'b' Boolean, 's' String */
    fmi2ValueReference vr;
    fmi2Real real;
    fmi2Integer integer; /* Integer and Boolean */
    char* string;
} HeldInput;

typedef struct {
    fmi2Component inner;
    fmi2CallbackFunctions callbacks; /* given to the backend: our logger, this struct as env */
    fmi3InstanceEnvironment environment;
    fmi3LogMessageCallback logMessage;
    fmi3Boolean loggingOn;
    fmi3Boolean eventModeUsed;
    fmi3Boolean earlyReturnAllowed;
    Mode mode;
    double time; /* the independent variable (ATO_TIME_VR), s */
    double clock_next; /* countdown: the tick last given by fmi3GetIntervalDecimal, s */
    int clock_given;   /* countdown: clock_next holds a tick */
    fmi3ClockUpdateCallback clockUpdate; /* Scheduled Execution */
    int activated;     /* Scheduled Execution: a partition ran (at `time`) */
    HeldInput* held;   /* Scheduled Execution: inputs set since the last activation */
    size_t n_held, cap_held;
    char name[256];
} Front;

/* an FMU state: the backend's and the front's time */
typedef struct {
    fmi2FMUstate inner;
    double time;
} FrontState;

static const ato_backend* backend = NULL;
static char backend_error[4096] = "";
static int backend_tried = 0;

static const ato_backend* get_backend(void)
{
    if (!backend_tried) {
        backend_tried = 1;
        backend = ato_backend_get(backend_error, sizeof backend_error);
        if (!backend && !backend_error[0])
            snprintf(backend_error, sizeof backend_error, "the model backend is unavailable");
    }
    return backend;
}

/* -- logging --------------------------------------------------------------------------------- */
static void front_log(const Front* f, fmi3Status status, const char* category, const char* fmt,
                      ...)
{
    char text[8192];
    va_list args;
    if (!f || !f->logMessage)
        return;
    va_start(args, fmt);
    vsnprintf(text, sizeof text, fmt, args);
    va_end(args);
    f->logMessage(f->environment, status, category, text);
}

static fmi3Status status3(fmi2Status status)
{
    switch (status) {
    case fmi2OK: return fmi3OK;
    case fmi2Warning: return fmi3Warning;
    case fmi2Discard: return fmi3Discard;
    case fmi2Fatal: return fmi3Fatal;
    default: return fmi3Error; /* fmi2Error; fmi2Pending (never asked for) */
    }
}

/* the backend's logger: its status in FMI 3 terms, forwarded to the host */
static void backend_logger(fmi2ComponentEnvironment env, fmi2String instanceName,
                           fmi2Status status, fmi2String category, fmi2String message, ...)
{
    Front* f = (Front*)env;
    char text[8192];
    (void)instanceName;
    if (!f || !f->logMessage || !message)
        return;
    if (backend && backend->literal_messages) {
        size_t j = 0;
        for (size_t i = 0; message[i] && j + 1 < sizeof text; ++i) {
            if (message[i] == '%' && message[i + 1] == '%')
                ++i;
            text[j++] = message[i];
        }
        text[j] = '\0';
    } else {
        va_list args;
        va_start(args, message);
        vsnprintf(text, sizeof text, message, args);
        va_end(args);
    }
    f->logMessage(f->environment, status3(status), category ? category : "logAll", text);
}

/* -- state machine --------------------------------------------------------------------------- */
static int allowed(Front* f, const char* call, unsigned modes)
{
    if (!f)
        return 0;
    if (modes & (1u << f->mode))
        return 1;
    front_log(f, fmi3Error, "logStatusError",
              "%s: %s is not allowed in state %s (" STATE_MACHINE ")", f->name, call,
              MODE_NAMES[f->mode]);
    return 0;
}

static fmi3Status missing(Front* f, const char* call)
{
    front_log(f, fmi3Error, "logStatusError", "%s: %s: the model backend (%s) has no such "
              "function", f->name, call, backend ? backend->name : "?");
    return fmi3Error;
}

static fmi3Status forwarded(Front* f, fmi2Status status)
{
    fmi3Status s = status3(status);
    if (s == fmi3Fatal)
        f->mode = MODE_FAILED;
    return s;
}

static fmi3Status unsupported(fmi3Instance instance, const char* call, const char* why)
{
    Front* f = (Front*)instance;
    if (f)
        front_log(f, fmi3Error, "logStatusError", "%s: %s is not supported by this FMU (%s)",
                  f->name, call, why);
    return fmi3Error;
}

/* -- inquire version, logging ------------------------------------------------------------------ */
const char* fmi3GetVersion(void)
{
    return fmi3Version;
}

fmi3Status fmi3SetDebugLogging(fmi3Instance instance, fmi3Boolean loggingOn, size_t nCategories,
                               const fmi3String categories[])
{
    Front* f = (Front*)instance;
    if (!f)
        return fmi3Error;
    f->loggingOn = loggingOn;
    if (!backend->set_debug_logging)
        return fmi3OK; /* the front's own errors are logged regardless */
    return forwarded(f, backend->set_debug_logging(f->inner, loggingOn ? fmi2True : fmi2False,
                                                   nCategories, categories));
}

/* -- creation and destruction ------------------------------------------------------------------ */
/* resourcePath (a directory path, FMI 3.0 sec. 2.3.1) as the file URI FMI 2 expects (FMI 2.0.4
 * sec. 2.1.5 fmuResourceLocation): "file://" + the percent-encoded path, no trailing '/'. On
 * Windows a path "C:\dir\resources\" becomes "file:///C:/dir/resources" (RFC 8089: '\' as '/',
 * the drive letter after a '/', its ':' kept). */
static char* resource_uri(const char* path)
{
    static const char hex[] = "0123456789ABCDEF";
    size_t n = path ? strlen(path) : 0;
    char* uri = (char*)malloc(8 + 3 * n + 1);
    size_t j = 0;
    if (!uri)
        return NULL;
    memcpy(uri, "file://", 7);
    j = 7;
#ifdef _WIN32
    while (n > 1 && (path[n - 1] == '/' || path[n - 1] == '\\'))
        --n;
    int drive = n >= 2 && path[1] == ':' &&
                ((path[0] >= 'A' && path[0] <= 'Z') || (path[0] >= 'a' && path[0] <= 'z'));
    if (drive)
        uri[j++] = '/';
#else
    while (n > 1 && path[n - 1] == '/')
        --n;
#endif
    for (size_t i = 0; i < n; ++i) {
        unsigned char c = (unsigned char)path[i];
#ifdef _WIN32
        if (c == '\\')
            c = '/';
        if (drive && i == 1) {
            uri[j++] = ':';
            continue;
        }
#endif
        if ((c >= 'A' && c <= 'Z') || (c >= 'a' && c <= 'z') || (c >= '0' && c <= '9') ||
            strchr("/-._~", c)) {
            uri[j++] = (char)c;
        } else {
            uri[j++] = '%';
            uri[j++] = hex[c >> 4];
            uri[j++] = hex[c & 15];
        }
    }
    uri[j] = '\0';
    return uri;
}

static void host_error(fmi3InstanceEnvironment env, fmi3LogMessageCallback log,
                       const char* message)
{
    if (log)
        log(env, fmi3Error, "logStatusError", message);
}

/* NULL, with the reason (printf format ``fmt``) sent to the host's logMessage */
static fmi3Instance refused(fmi3InstanceEnvironment env, fmi3LogMessageCallback log,
                            const char* fmt, ...)
{
    char text[8192];
    va_list args;
    va_start(args, fmt);
    vsnprintf(text, sizeof text, fmt, args);
    va_end(args);
    host_error(env, log, text);
    return NULL;
}

/* a front with its backend instance, or NULL (the reason logged) */
static Front* new_front(fmi3String instanceName, fmi3String instantiationToken,
                        fmi3String resourcePath, fmi3Boolean visible, fmi3Boolean loggingOn,
                        fmi3Boolean eventModeUsed, fmi3Boolean earlyReturnAllowed,
                        fmi3InstanceEnvironment instanceEnvironment,
                        fmi3LogMessageCallback logMessage)
{
    Front* f = (Front*)calloc(1, sizeof *f);
    if (!f)
        return NULL;
    f->environment = instanceEnvironment;
    f->logMessage = logMessage;
    f->loggingOn = loggingOn;
    f->eventModeUsed = eventModeUsed;
    f->earlyReturnAllowed = earlyReturnAllowed;
    f->mode = MODE_INSTANTIATED;
    snprintf(f->name, sizeof f->name, "%s", instanceName ? instanceName : "");
    f->callbacks.logger = backend_logger;
    f->callbacks.allocateMemory = calloc;
    f->callbacks.freeMemory = free;
    f->callbacks.stepFinished = NULL;
    f->callbacks.componentEnvironment = f;
    char* uri = resource_uri(resourcePath);
    if (!uri) {
        free(f);
        return NULL;
    }
    f->inner = backend->instantiate(instanceName, fmi2CoSimulation, instantiationToken, uri,
                                    &f->callbacks, visible ? fmi2True : fmi2False,
                                    loggingOn ? fmi2True : fmi2False);
    free(uri);
    if (!f->inner) {
        front_log(f, fmi3Error, "logStatusError", "%s: the model backend (%s) could not "
                  "instantiate the model", f->name, backend->name);
        free(f);
        return NULL;
    }
    if (!registry_add(f)) {
        front_log(f, fmi3Error, "logStatusError", "%s: out of memory", f->name);
        backend->free_instance(f->inner);
        free(f);
        return NULL;
    }
    return f;
}

fmi3Instance fmi3InstantiateCoSimulation(
    fmi3String instanceName, fmi3String instantiationToken, fmi3String resourcePath,
    fmi3Boolean visible, fmi3Boolean loggingOn, fmi3Boolean eventModeUsed,
    fmi3Boolean earlyReturnAllowed, const fmi3ValueReference requiredIntermediateVariables[],
    size_t nRequiredIntermediateVariables, fmi3InstanceEnvironment instanceEnvironment,
    fmi3LogMessageCallback logMessage, fmi3IntermediateUpdateCallback intermediateUpdate)
{
    const char* name = instanceName ? instanceName : "";
    (void)requiredIntermediateVariables;
    (void)intermediateUpdate;
    if (ATO_SCHEDULED)
        return refused(instanceEnvironment, logMessage, "%s: this FMU supports Scheduled "
                       "Execution only (no CoSimulation element in its modelDescription.xml): "
                       "instantiate it with fmi3InstantiateScheduledExecution", name);
    if (!get_backend())
        return refused(instanceEnvironment, logMessage, "%s: %s", name, backend_error);
    if (eventModeUsed && backend->event_time_vr < 0)
        return refused(instanceEnvironment, logMessage, "%s: eventModeUsed = true, but this "
                       "FMU declares hasEventMode = false (FMI 3.0 sec. 2.3.1, "
                       "fmi3InstantiateCoSimulation)", name);
    if (nRequiredIntermediateVariables > 0)
        return refused(instanceEnvironment, logMessage, "%s: this FMU provides no intermediate "
                       "update (providesIntermediateUpdate = false); "
                       "requiredIntermediateVariables must be empty (FMI 3.0 sec. 2.3.1, "
                       "fmi3InstantiateCoSimulation)", name);
    return new_front(instanceName, instantiationToken, resourcePath, visible, loggingOn,
                     eventModeUsed, earlyReturnAllowed, instanceEnvironment, logMessage);
}

fmi3Instance fmi3InstantiateModelExchange(fmi3String instanceName, fmi3String instantiationToken,
                                          fmi3String resourcePath, fmi3Boolean visible,
                                          fmi3Boolean loggingOn,
                                          fmi3InstanceEnvironment instanceEnvironment,
                                          fmi3LogMessageCallback logMessage)
{
    char text[512];
    (void)instantiationToken, (void)resourcePath, (void)visible, (void)loggingOn;
    snprintf(text, sizeof text, "%s: this FMU supports co-simulation only (no ModelExchange "
             "element in its modelDescription.xml)", instanceName ? instanceName : "");
    host_error(instanceEnvironment, logMessage, text);
    return NULL;
}

/* FMI 3.0 sec. 5.2.1: a Scheduled Execution build (ATO_SCHEDULED) only; the preemption
 * callbacks are not needed: the model has one partition, and the backend is called from
 * within fmi3ActivateModelPartition and the get and set functions only */
fmi3Instance fmi3InstantiateScheduledExecution(
    fmi3String instanceName, fmi3String instantiationToken, fmi3String resourcePath,
    fmi3Boolean visible, fmi3Boolean loggingOn, fmi3InstanceEnvironment instanceEnvironment,
    fmi3LogMessageCallback logMessage, fmi3ClockUpdateCallback clockUpdate,
    fmi3LockPreemptionCallback lockPreemption, fmi3UnlockPreemptionCallback unlockPreemption)
{
    const char* name = instanceName ? instanceName : "";
    (void)lockPreemption, (void)unlockPreemption;
    if (!ATO_SCHEDULED)
        return refused(instanceEnvironment, logMessage, "%s: this FMU supports co-simulation "
                       "only (no ScheduledExecution element in its modelDescription.xml)",
                       name);
    if (!get_backend())
        return refused(instanceEnvironment, logMessage, "%s: %s", name, backend_error);
    if (!clockUpdate)
        return refused(instanceEnvironment, logMessage, "%s: fmi3InstantiateScheduledExecution: "
                       "clockUpdate is NULL (FMI 3.0 sec. 5.2.1: the FMU calls it to announce "
                       "its countdown Clock)", name);
    Front* f = new_front(instanceName, instantiationToken, resourcePath, visible, loggingOn,
                         fmi3False, fmi3False, instanceEnvironment, logMessage);
    if (f)
        f->clockUpdate = clockUpdate;
    return f;
}

/* -- inputs held in Clock Activation Mode (Scheduled Execution) ------------------------------- */
static void drop_held(Front* f)
{
    for (size_t i = 0; i < f->n_held; ++i)
        free(f->held[i].string);
    f->n_held = 0;
}

/* true when the front holds this set call's values (Clock Activation Mode) */
static int holding(const Front* f)
{
    return ATO_SCHEDULED && f->mode == MODE_CLOCK_ACTIVATION;
}

/* one held input; 0 when out of memory (logged) */
static int hold(Front* f, HeldInput input)
{
    if (f->n_held == f->cap_held) {
        size_t cap = f->cap_held ? 2 * f->cap_held : 16;
        HeldInput* more = (HeldInput*)realloc(f->held, cap * sizeof *more);
        if (!more) {
            front_log(f, fmi3Error, "logStatusError", "%s: out of memory", f->name);
            free(input.string);
            return 0;
        }
        f->held = more;
        f->cap_held = cap;
    }
    f->held[f->n_held++] = input;
    return 1;
}

/* the held inputs to the backend, in the order they were set */
static fmi3Status release_held(Front* f)
{
    fmi3Status worst = fmi3OK;
    for (size_t i = 0; i < f->n_held && worst <= fmi3Warning; ++i) {
        HeldInput* h = &f->held[i];
        fmi2Status s = fmi2Error;
        if (h->kind == 'r' && backend->set_real)
            s = backend->set_real(f->inner, &h->vr, 1, &h->real);
        else if (h->kind == 'i' && backend->set_integer)
            s = backend->set_integer(f->inner, &h->vr, 1, &h->integer);
        else if (h->kind == 'b' && backend->set_boolean)
            s = backend->set_boolean(f->inner, &h->vr, 1, &h->integer);
        else if (h->kind == 's' && backend->set_string) {
            fmi2String value = h->string;
            s = backend->set_string(f->inner, &h->vr, 1, &value);
        }
        fmi3Status s3 = forwarded(f, s);
        worst = s3 > worst ? s3 : worst;
    }
    drop_held(f);
    return worst;
}

/* what a second fmi3FreeInstance needs for its message (instance_registry.h) */
typedef struct {
    fmi3InstanceEnvironment environment;
    fmi3LogMessageCallback logMessage;
    char name[256];
} FreedMemo;

void fmi3FreeInstance(fmi3Instance instance)
{
    Front* f = (Front*)instance;
    unsigned char buf[REGISTRY_MEMO] = {0};
    FreedMemo memo;
    char text[512];
    if (!f)
        return;
    if (registry_is_live(f)) {
        memset(&memo, 0, sizeof memo);
        memo.environment = f->environment;
        memo.logMessage = f->logMessage;
        snprintf(memo.name, sizeof memo.name, "%s", f->name);
        memcpy(buf, &memo, sizeof memo);
        registry_release(f, buf);
        if (f->inner)
            backend->free_instance(f->inner);
        drop_held(f);
        free(f->held);
        free(f);
        return;
    }
    if (registry_release(f, buf) == -1) {
        memcpy(&memo, buf, sizeof memo);
        snprintf(text, sizeof text, "%s: fmi3FreeInstance: the instance was freed already; "
                 "call refused", memo.name);
        host_error(memo.environment, memo.logMessage, text);
    } else {
        fprintf(stderr, "fmi3FreeInstance: %p is not a live instance of this FMU; call "
                "refused\n", instance);
    }
}

/* -- initialisation, modes, termination, reset --------------------------------------------------- */
fmi3Status fmi3EnterInitializationMode(fmi3Instance instance, fmi3Boolean toleranceDefined,
                                       fmi3Float64 tolerance, fmi3Float64 startTime,
                                       fmi3Boolean stopTimeDefined, fmi3Float64 stopTime)
{
    Front* f = (Front*)instance;
    if (!allowed(f, "fmi3EnterInitializationMode", ALLOW_INSTANTIATED))
        return fmi3Error;
    if (!backend->setup_experiment || !backend->enter_initialization_mode)
        return missing(f, "fmi3EnterInitializationMode");
    fmi3Status s = forwarded(f, backend->setup_experiment(
        f->inner, toleranceDefined ? fmi2True : fmi2False, tolerance, startTime,
        stopTimeDefined ? fmi2True : fmi2False, stopTime));
    if (s > fmi3Warning)
        return s;
    fmi3Status s2 = forwarded(f, backend->enter_initialization_mode(f->inner));
    if (s2 <= fmi3Warning) {
        f->mode = MODE_INITIALIZATION;
        f->time = startTime;
        f->clock_given = 0;
        f->activated = 0;
        drop_held(f);
    }
    return s2 > s ? s2 : s;
}

fmi3Status fmi3ExitInitializationMode(fmi3Instance instance)
{
    Front* f = (Front*)instance;
    if (!allowed(f, "fmi3ExitInitializationMode", ALLOW_INITIALIZATION))
        return fmi3Error;
    if (!backend->exit_initialization_mode)
        return missing(f, "fmi3ExitInitializationMode");
    fmi3Status s = forwarded(f, backend->exit_initialization_mode(f->inner));
    /* FMI 3.0 sec. 4.2: Event Mode if eventModeUsed, else Step Mode; sec. 5.2: Clock
     * Activation Mode */
    if (s <= fmi3Warning)
        f->mode = ATO_SCHEDULED ? MODE_CLOCK_ACTIVATION
                                : f->eventModeUsed ? MODE_EVENT : MODE_STEP;
    return s;
}

fmi3Status fmi3EnterEventMode(fmi3Instance instance)
{
    Front* f = (Front*)instance;
    if (!allowed(f, "fmi3EnterEventMode", ALLOW_STEP))
        return fmi3Error;
    if (!f->eventModeUsed) {
        front_log(f, fmi3Error, "logStatusError", "%s: fmi3EnterEventMode: the FMU was "
                  "instantiated with eventModeUsed = false (FMI 3.0 sec. 4.2.1, fmi3EnterEventMode)", f->name);
        return fmi3Error;
    }
    f->mode = MODE_EVENT;
    return fmi3OK;
}

fmi3Status fmi3EnterStepMode(fmi3Instance instance)
{
    Front* f = (Front*)instance;
    if (!allowed(f, "fmi3EnterStepMode", ALLOW_EVENT))
        return fmi3Error;
    f->mode = MODE_STEP;
    return fmi3OK;
}

static long long ticks(double t);
static int clock_interval(Front* f, double* interval, fmi3IntervalQualifier* qualifier);

/* periodic Clock (ATO_CLOCK_COUNTDOWN = 0): is the model's next event ``t`` (s) at most one
 * interval after now? Else 0, logged: a self-triggered model takes a countdown Clock */
static int on_periodic_clock(Front* f, double t)
{
    double period = 0.0;
    fmi3IntervalQualifier qualifier;
    if (!CLOCKED || ATO_CLOCK_COUNTDOWN)
        return 1;
    if (!clock_interval(f, &period, &qualifier))
        return 0;
    if (ticks(t) <= ticks(f->time) + ticks(period))
        return 1;
    front_log(f, fmi3Error, "logStatusError", "%s: the model's next event at t = %.17g s is "
              "more than one interval (%.17g s) of its periodic Clock after t = %.17g s: a "
              "self-triggered model takes a countdown Clock", f->name, t, period, f->time);
    return 0;
}

/* the backend's announced next event time (s); 0 when it has none, -1 on error */
static int next_event(Front* f, double* t)
{
    fmi2ValueReference vr = (fmi2ValueReference)backend->event_time_vr;
    if (backend->event_time_vr < 0 || !backend->get_real)
        return 0;
    fmi2Status s = backend->get_real(f->inner, &vr, 1, t);
    if (s > fmi2Warning) {
        forwarded(f, s);
        return -1;
    }
    if (!isfinite(*t))
        return 0;
    return 1;
}

fmi3Status fmi3UpdateDiscreteStates(fmi3Instance instance,
                                    fmi3Boolean* discreteStatesNeedUpdate,
                                    fmi3Boolean* terminateSimulation,
                                    fmi3Boolean* nominalsOfContinuousStatesChanged,
                                    fmi3Boolean* valuesOfContinuousStatesChanged,
                                    fmi3Boolean* nextEventTimeDefined,
                                    fmi3Float64* nextEventTime)
{
    Front* f = (Front*)instance;
    double t = 0.0;
    if (!allowed(f, "fmi3UpdateDiscreteStates", ALLOW_EVENT))
        return fmi3Error;
    /* the event of this instant is computed from the inputs set in this Event Mode when its
     * outputs (here: the event time) are read; doStep commits it, as in the FMI 2 twin */
    int found = next_event(f, &t);
    if (found < 0)
        return fmi3Error;
    if (discreteStatesNeedUpdate)
        *discreteStatesNeedUpdate = fmi3False;
    if (terminateSimulation)
        *terminateSimulation = fmi3False;
    if (nominalsOfContinuousStatesChanged)
        *nominalsOfContinuousStatesChanged = fmi3False;
    if (valuesOfContinuousStatesChanged)
        *valuesOfContinuousStatesChanged = fmi3False;
    if (found && !on_periodic_clock(f, t))
        return fmi3Error;
    if (CLOCKED) /* the input Clock activates the events, not nextEventTime */
        found = 0;
    if (nextEventTimeDefined)
        *nextEventTimeDefined = found ? fmi3True : fmi3False;
    if (nextEventTime)
        *nextEventTime = found ? t : 0.0;
    return fmi3OK;
}

/* time in integer nanoseconds, the grid of the models' clocks (cosim/fmu/state.py) */
static long long ticks(double t)
{
    return llround(t * 1e9);
}

fmi3Status fmi3DoStep(fmi3Instance instance, fmi3Float64 currentCommunicationPoint,
                      fmi3Float64 communicationStepSize,
                      fmi3Boolean noSetFMUStatePriorToCurrentCommunicationPoint,
                      fmi3Boolean* eventHandlingNeeded, fmi3Boolean* terminateSimulation,
                      fmi3Boolean* earlyReturn, fmi3Float64* lastSuccessfulTime)
{
    Front* f = (Front*)instance;
    double t = currentCommunicationPoint, h = communicationStepSize, end = t + h, te = 0.0;
    int announced = 0, early = 0, event_at_end = 0;
    if (eventHandlingNeeded)
        *eventHandlingNeeded = fmi3False;
    if (terminateSimulation)
        *terminateSimulation = fmi3False;
    if (earlyReturn)
        *earlyReturn = fmi3False;
    if (lastSuccessfulTime)
        *lastSuccessfulTime = t;
    if (!allowed(f, "fmi3DoStep", ALLOW_STEP))
        return fmi3Error;
    if (!backend->do_step)
        return missing(f, "fmi3DoStep");
    if (!(h > 0.0) || !isfinite(h) || !isfinite(t)) {
        front_log(f, fmi3Error, "logStatusError", "%s: fmi3DoStep(currentCommunicationPoint "
                  "= %.17g, communicationStepSize = %.17g): the step size must be positive and "
                  "finite (FMI 3.0 sec. 4.2.1, fmi3DoStep)", f->name, t, h);
        return fmi3Error;
    }
    if (f->eventModeUsed || f->earlyReturnAllowed) {
        announced = next_event(f, &te);
        if (announced < 0)
            return fmi3Error;
        if (announced && ticks(te) > ticks(t) && ticks(te) < ticks(end) &&
            f->earlyReturnAllowed && !CLOCKED) {
            /* FMI 3.0 sec. 4.2.1, fmi3DoStep: return early at the event the FMU announced */
            h = te - t;
            end = te;
            early = 1;
        }
    }
    fmi3Status s = forwarded(f, backend->do_step(
        f->inner, t, h, noSetFMUStatePriorToCurrentCommunicationPoint ? fmi2True : fmi2False));
    if (s > fmi3Warning)
        return s;
    if (announced && f->eventModeUsed && !CLOCKED) {
        if (ticks(te) == ticks(end)) {
            event_at_end = 1;
        } else if (ticks(te) < ticks(end)) {
            /* the backend ran events inside the step: is another one due at its end? */
            double after = 0.0;
            int again = next_event(f, &after);
            if (again < 0)
                return fmi3Error;
            event_at_end = again && ticks(after) <= ticks(end);
        }
    }
    if (eventHandlingNeeded)
        *eventHandlingNeeded = event_at_end ? fmi3True : fmi3False;
    if (earlyReturn)
        *earlyReturn = early ? fmi3True : fmi3False;
    if (lastSuccessfulTime)
        *lastSuccessfulTime = end;
    f->time = end;
    return s;
}

fmi3Status fmi3Terminate(fmi3Instance instance)
{
    Front* f = (Front*)instance;
    if (!allowed(f, "fmi3Terminate", ALLOW_EVENT | ALLOW_STEP | ALLOW_CLOCK_ACTIVATION))
        return fmi3Error;
    fmi3Status s = forwarded(f, backend->terminate(f->inner));
    if (s <= fmi3Warning)
        f->mode = MODE_TERMINATED;
    return s;
}

fmi3Status fmi3Reset(fmi3Instance instance)
{
    Front* f = (Front*)instance;
    if (!allowed(f, "fmi3Reset", ALLOW_INSTANTIATED | ALLOW_INITIALIZATION | ALLOW_EVENT |
                 ALLOW_STEP | ALLOW_TERMINATED | ALLOW_CLOCK_ACTIVATION))
        return fmi3Error;
    fmi3Status s = forwarded(f, backend->reset(f->inner));
    if (s <= fmi3Warning) {
        f->mode = MODE_INSTANTIATED;
        f->time = 0.0;
        drop_held(f);
    }
    return s;
}

/* -- getting and setting variable values ----------------------------------------------------------- */
#define GET_MODES (ALLOW_INITIALIZATION | ALLOW_EVENT | ALLOW_STEP | ALLOW_TERMINATED |        \
                   ALLOW_CLOCK_ACTIVATION)
#define SET_MODES (ALLOW_INSTANTIATED | ALLOW_INITIALIZATION | ALLOW_EVENT | ALLOW_STEP |        \
                   ALLOW_CLOCK_ACTIVATION)

static int scalars(Front* f, const char* call, size_t nvr, size_t nValues)
{
    if (nvr == nValues)
        return 1;
    front_log(f, fmi3Error, "logStatusError", "%s: %s: nValues = %zu but %zu value references: "
              "this FMU has scalar variables only (FMI 3.0 sec. 2.2.7.2, getting and setting variable values)", f->name, call,
              nValues, nvr);
    return 0;
}

fmi3Status fmi3GetFloat64(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                          fmi3Float64 values[], size_t nValues)
{
    Front* f = (Front*)instance;
    size_t n = 0;
    if (!allowed(f, "fmi3GetFloat64", GET_MODES) || !scalars(f, "fmi3GetFloat64", nvr, nValues))
        return fmi3Error;
    for (size_t i = 0; i < nvr; ++i)
        n += vr[i] != ATO_TIME_VR;
    if (n == nvr) {
        if (nvr == 0)
            return fmi3OK;
        if (!backend->get_real)
            return missing(f, "fmi3GetFloat64");
        return forwarded(f, backend->get_real(f->inner, vr, nvr, values));
    }
    /* the independent variable is the front's; the others the backend's, in one call */
    fmi3Status s = fmi3OK;
    if (n > 0) {
        fmi2ValueReference* refs = (fmi2ValueReference*)calloc(n, sizeof *refs);
        fmi2Real* got = (fmi2Real*)calloc(n, sizeof *got);
        size_t j = 0;
        if (!refs || !got || !backend->get_real) {
            free(refs);
            free(got);
            return refs && got ? missing(f, "fmi3GetFloat64") : fmi3Error;
        }
        for (size_t i = 0; i < nvr; ++i)
            if (vr[i] != ATO_TIME_VR)
                refs[j++] = vr[i];
        s = forwarded(f, backend->get_real(f->inner, refs, n, got));
        for (size_t i = 0, k = 0; i < nvr && s <= fmi3Warning; ++i)
            if (vr[i] != ATO_TIME_VR)
                values[i] = got[k++];
        free(refs);
        free(got);
    }
    for (size_t i = 0; i < nvr && s <= fmi3Warning; ++i)
        if (vr[i] == ATO_TIME_VR)
            values[i] = f->time;
    return s;
}

fmi3Status fmi3SetFloat64(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                          const fmi3Float64 values[], size_t nValues)
{
    Front* f = (Front*)instance;
    if (!allowed(f, "fmi3SetFloat64", SET_MODES) || !scalars(f, "fmi3SetFloat64", nvr, nValues))
        return fmi3Error;
    for (size_t i = 0; i < nvr; ++i)
        if (vr[i] == ATO_TIME_VR) {
            front_log(f, fmi3Error, "logStatusError", "%s: fmi3SetFloat64: `time` is the "
                      "independent variable and cannot be set (FMI 3.0 sec. 2.4.7.4, causality independent)",
                      f->name);
            return fmi3Error;
        }
    if (nvr == 0)
        return fmi3OK;
    if (holding(f)) {
        for (size_t i = 0; i < nvr; ++i)
            if (!hold(f, (HeldInput){'r', vr[i], values[i], 0, NULL}))
                return fmi3Error;
        return fmi3OK;
    }
    if (!backend->set_real)
        return missing(f, "fmi3SetFloat64");
    return forwarded(f, backend->set_real(f->inner, vr, nvr, values));
}

fmi3Status fmi3GetInt32(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                        fmi3Int32 values[], size_t nValues)
{
    Front* f = (Front*)instance;
    if (!allowed(f, "fmi3GetInt32", GET_MODES) || !scalars(f, "fmi3GetInt32", nvr, nValues))
        return fmi3Error;
    if (nvr == 0)
        return fmi3OK;
    if (!backend->get_integer)
        return missing(f, "fmi3GetInt32");
    return forwarded(f, backend->get_integer(f->inner, vr, nvr, values)); /* both int32 */
}

fmi3Status fmi3SetInt32(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                        const fmi3Int32 values[], size_t nValues)
{
    Front* f = (Front*)instance;
    if (!allowed(f, "fmi3SetInt32", SET_MODES) || !scalars(f, "fmi3SetInt32", nvr, nValues))
        return fmi3Error;
    if (nvr == 0)
        return fmi3OK;
    if (holding(f)) {
        for (size_t i = 0; i < nvr; ++i)
            if (!hold(f, (HeldInput){'i', vr[i], 0.0, values[i], NULL}))
                return fmi3Error;
        return fmi3OK;
    }
    if (!backend->set_integer)
        return missing(f, "fmi3SetInt32");
    return forwarded(f, backend->set_integer(f->inner, vr, nvr, values));
}

fmi3Status fmi3GetBoolean(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                          fmi3Boolean values[], size_t nValues)
{
    Front* f = (Front*)instance;
    if (!allowed(f, "fmi3GetBoolean", GET_MODES) || !scalars(f, "fmi3GetBoolean", nvr, nValues))
        return fmi3Error;
    if (nvr == 0)
        return fmi3OK;
    if (!backend->get_boolean)
        return missing(f, "fmi3GetBoolean");
    fmi2Boolean* tmp = (fmi2Boolean*)calloc(nvr, sizeof *tmp);
    if (!tmp)
        return fmi3Error;
    fmi3Status s = forwarded(f, backend->get_boolean(f->inner, vr, nvr, tmp));
    if (s <= fmi3Warning)
        for (size_t i = 0; i < nvr; ++i)
            values[i] = tmp[i] != fmi2False;
    free(tmp);
    return s;
}

fmi3Status fmi3SetBoolean(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                          const fmi3Boolean values[], size_t nValues)
{
    Front* f = (Front*)instance;
    if (!allowed(f, "fmi3SetBoolean", SET_MODES) || !scalars(f, "fmi3SetBoolean", nvr, nValues))
        return fmi3Error;
    if (nvr == 0)
        return fmi3OK;
    if (holding(f)) {
        for (size_t i = 0; i < nvr; ++i)
            if (!hold(f, (HeldInput){'b', vr[i], 0.0, values[i] ? fmi2True : fmi2False, NULL}))
                return fmi3Error;
        return fmi3OK;
    }
    if (!backend->set_boolean)
        return missing(f, "fmi3SetBoolean");
    fmi2Boolean* tmp = (fmi2Boolean*)calloc(nvr, sizeof *tmp);
    if (!tmp)
        return fmi3Error;
    for (size_t i = 0; i < nvr; ++i)
        tmp[i] = values[i] ? fmi2True : fmi2False;
    fmi3Status s = forwarded(f, backend->set_boolean(f->inner, vr, nvr, tmp));
    free(tmp);
    return s;
}

fmi3Status fmi3GetString(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                         fmi3String values[], size_t nValues)
{
    Front* f = (Front*)instance;
    if (!allowed(f, "fmi3GetString", GET_MODES) || !scalars(f, "fmi3GetString", nvr, nValues))
        return fmi3Error;
    if (nvr == 0)
        return fmi3OK;
    if (!backend->get_string)
        return missing(f, "fmi3GetString");
    return forwarded(f, backend->get_string(f->inner, vr, nvr, values));
}

fmi3Status fmi3SetString(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                         const fmi3String values[], size_t nValues)
{
    Front* f = (Front*)instance;
    if (!allowed(f, "fmi3SetString", SET_MODES) || !scalars(f, "fmi3SetString", nvr, nValues))
        return fmi3Error;
    if (nvr == 0)
        return fmi3OK;
    if (holding(f)) {
        for (size_t i = 0; i < nvr; ++i) {
            char* copy = strdup(values[i] ? values[i] : "");
            if (!copy || !hold(f, (HeldInput){'s', vr[i], 0.0, 0, copy}))
                return fmi3Error;
        }
        return fmi3OK;
    }
    if (!backend->set_string)
        return missing(f, "fmi3SetString");
    return forwarded(f, backend->set_string(f->inner, vr, nvr, values));
}

/* the FMI 3 types these FMUs have no variables of: fine with no value references */
#define NO_SUCH_TYPE(name, ctype, constness)                                                  \
    fmi3Status name(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,        \
                    constness ctype values[], size_t nValues)                                 \
    {                                                                                         \
        (void)vr, (void)values, (void)nValues;                                                \
        if (nvr == 0)                                                                         \
            return fmi3OK;                                                                    \
        return unsupported(instance, #name, "it has no variable of this type");               \
    }
NO_SUCH_TYPE(fmi3GetFloat32, fmi3Float32, )
NO_SUCH_TYPE(fmi3GetInt8, fmi3Int8, )
NO_SUCH_TYPE(fmi3GetUInt8, fmi3UInt8, )
NO_SUCH_TYPE(fmi3GetInt16, fmi3Int16, )
NO_SUCH_TYPE(fmi3GetUInt16, fmi3UInt16, )
NO_SUCH_TYPE(fmi3GetUInt32, fmi3UInt32, )
NO_SUCH_TYPE(fmi3GetInt64, fmi3Int64, )
NO_SUCH_TYPE(fmi3GetUInt64, fmi3UInt64, )
NO_SUCH_TYPE(fmi3SetFloat32, fmi3Float32, const)
NO_SUCH_TYPE(fmi3SetInt8, fmi3Int8, const)
NO_SUCH_TYPE(fmi3SetUInt8, fmi3UInt8, const)
NO_SUCH_TYPE(fmi3SetInt16, fmi3Int16, const)
NO_SUCH_TYPE(fmi3SetUInt16, fmi3UInt16, const)
NO_SUCH_TYPE(fmi3SetUInt32, fmi3UInt32, const)
NO_SUCH_TYPE(fmi3SetInt64, fmi3Int64, const)
NO_SUCH_TYPE(fmi3SetUInt64, fmi3UInt64, const)

fmi3Status fmi3GetBinary(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                         size_t valueSizes[], fmi3Binary values[], size_t nValues)
{
    (void)vr, (void)valueSizes, (void)values, (void)nValues;
    return nvr == 0 ? fmi3OK : unsupported(instance, "fmi3GetBinary", "no Binary variables");
}

fmi3Status fmi3SetBinary(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                         const size_t valueSizes[], const fmi3Binary values[], size_t nValues)
{
    (void)vr, (void)valueSizes, (void)values, (void)nValues;
    return nvr == 0 ? fmi3OK : unsupported(instance, "fmi3SetBinary", "no Binary variables");
}

fmi3Status fmi3GetClock(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                        fmi3Clock values[])
{
    (void)vr, (void)values;
    return nvr == 0 ? fmi3OK : unsupported(instance, "fmi3GetClock", "no clocks");
}

static int is_clock(fmi3ValueReference vr)
{
#if ATO_CLOCK_VR >= 0
    return vr == (fmi3ValueReference)ATO_CLOCK_VR;
#else
    (void)vr;
    return 0;
#endif
}

/* every value reference of vr[] is the input Clock's, else fmi3Error with a message */
static int clock_references(Front* f, const char* call, const fmi3ValueReference vr[],
                            size_t nvr)
{
    for (size_t i = 0; i < nvr; i++) {
        if (!is_clock(vr[i])) {
            front_log(f, fmi3Error, "logStatusError", "%s: %s: value reference %u is not a "
                      "Clock of this FMU (FMI 3.0 sec. 2.2.8)", f->name, call, (unsigned)vr[i]);
            return 0;
        }
    }
    return 1;
}

fmi3Status fmi3SetClock(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                        const fmi3Clock values[])
{
    Front* f = (Front*)instance;
    (void)values; /* the backend's events run at their times; the tick only says when */
    if (!allowed(f, "fmi3SetClock", ALLOW_EVENT))
        return fmi3Error;
    return clock_references(f, "fmi3SetClock", vr, nvr) ? fmi3OK : fmi3Error;
}

/* -- FMU state (the backend's; FMI 3.0 sec. 2.2.7.4) ------------------------------------------ */
#define STATE_MODES (ALLOW_INSTANTIATED | ALLOW_INITIALIZATION | ALLOW_EVENT | ALLOW_STEP |    \
                     ALLOW_TERMINATED)

fmi3Status fmi3GetFMUState(fmi3Instance instance, fmi3FMUState* FMUState)
{
    Front* f = (Front*)instance;
    if (!allowed(f, "fmi3GetFMUState", STATE_MODES) || !FMUState)
        return fmi3Error;
    if (!backend->get_fmu_state)
        return missing(f, "fmi3GetFMUState");
    FrontState* st = (FrontState*)*FMUState;
    int fresh = st == NULL;
    if (fresh && !(st = (FrontState*)calloc(1, sizeof *st)))
        return fmi3Error;
    fmi3Status s = forwarded(f, backend->get_fmu_state(f->inner, &st->inner));
    if (s > fmi3Warning) {
        if (fresh)
            free(st);
        return s;
    }
    st->time = f->time;
    *FMUState = st;
    return s;
}

fmi3Status fmi3SetFMUState(fmi3Instance instance, fmi3FMUState FMUState)
{
    Front* f = (Front*)instance;
    FrontState* st = (FrontState*)FMUState;
    if (!allowed(f, "fmi3SetFMUState", STATE_MODES) || !st)
        return fmi3Error;
    if (!backend->set_fmu_state)
        return missing(f, "fmi3SetFMUState");
    fmi3Status s = forwarded(f, backend->set_fmu_state(f->inner, st->inner));
    if (s <= fmi3Warning) {
        f->time = st->time;
        f->clock_given = 0; /* countdown: the next event is given again (the same tick) */
    }
    return s;
}

fmi3Status fmi3FreeFMUState(fmi3Instance instance, fmi3FMUState* FMUState)
{
    Front* f = (Front*)instance;
    if (!f || !FMUState)
        return fmi3Error;
    FrontState* st = (FrontState*)*FMUState;
    if (!st)
        return fmi3OK;
    if (!backend->free_fmu_state)
        return missing(f, "fmi3FreeFMUState");
    fmi3Status s = forwarded(f, backend->free_fmu_state(f->inner, &st->inner));
    free(st);
    *FMUState = NULL;
    return s;
}

/* a serialized state: the front's time (8 bytes, this machine's double) and the backend's */
fmi3Status fmi3SerializedFMUStateSize(fmi3Instance instance, fmi3FMUState FMUState, size_t* size)
{
    Front* f = (Front*)instance;
    FrontState* st = (FrontState*)FMUState;
    size_t inner = 0;
    if (!f || !st || !size)
        return fmi3Error;
    if (!backend->serialized_fmu_state_size)
        return missing(f, "fmi3SerializedFMUStateSize");
    fmi3Status s = forwarded(f, backend->serialized_fmu_state_size(f->inner, st->inner, &inner));
    *size = inner + sizeof st->time;
    return s;
}

fmi3Status fmi3SerializeFMUState(fmi3Instance instance, fmi3FMUState FMUState,
                                 fmi3Byte serializedState[], size_t size)
{
    Front* f = (Front*)instance;
    FrontState* st = (FrontState*)FMUState;
    if (!f || !st || size < sizeof st->time)
        return fmi3Error;
    if (!backend->serialize_fmu_state)
        return missing(f, "fmi3SerializeFMUState");
    memcpy(serializedState, &st->time, sizeof st->time);
    return forwarded(f, backend->serialize_fmu_state(f->inner, st->inner,
                                                     (fmi2Byte*)serializedState + sizeof st->time,
                                                     size - sizeof st->time));
}

fmi3Status fmi3DeserializeFMUState(fmi3Instance instance, const fmi3Byte serializedState[],
                                   size_t size, fmi3FMUState* FMUState)
{
    Front* f = (Front*)instance;
    FrontState* st;
    if (!f || !FMUState || size < sizeof st->time) {
        if (f)
            front_log(f, fmi3Error, "logStatusError", "%s: fmi3DeserializeFMUState: %zu "
                      "bytes is no state of this FMU", f->name, size);
        return fmi3Error;
    }
    if (!backend->deserialize_fmu_state)
        return missing(f, "fmi3DeserializeFMUState");
    if (!(st = (FrontState*)calloc(1, sizeof *st)))
        return fmi3Error;
    memcpy(&st->time, serializedState, sizeof st->time);
    fmi3Status s = forwarded(f, backend->deserialize_fmu_state(
        f->inner, (const fmi2Byte*)serializedState + sizeof st->time, size - sizeof st->time,
        &st->inner));
    if (s > fmi3Warning) {
        free(st);
        return s;
    }
    *FMUState = st;
    return s;
}

/* -- what these FMUs do not provide (their modelDescription.xml says so) ------------------------- */
fmi3Status fmi3GetNumberOfVariableDependencies(fmi3Instance instance,
                                               fmi3ValueReference valueReference,
                                               size_t* nDependencies)
{
    (void)valueReference, (void)nDependencies;
    return unsupported(instance, "fmi3GetNumberOfVariableDependencies",
                       "providesPerElementDependencies = false");
}

fmi3Status fmi3GetVariableDependencies(fmi3Instance instance, fmi3ValueReference dependent,
                                       size_t elementIndicesOfDependent[],
                                       fmi3ValueReference independents[],
                                       size_t elementIndicesOfIndependents[],
                                       fmi3DependencyKind dependencyKinds[], size_t nDependencies)
{
    (void)dependent, (void)elementIndicesOfDependent, (void)independents;
    (void)elementIndicesOfIndependents, (void)dependencyKinds, (void)nDependencies;
    return unsupported(instance, "fmi3GetVariableDependencies",
                       "providesPerElementDependencies = false");
}

fmi3Status fmi3GetDirectionalDerivative(fmi3Instance instance, const fmi3ValueReference unknowns[],
                                        size_t nUnknowns, const fmi3ValueReference knowns[],
                                        size_t nKnowns, const fmi3Float64 seed[], size_t nSeed,
                                        fmi3Float64 sensitivity[], size_t nSensitivity)
{
    (void)unknowns, (void)nUnknowns, (void)knowns, (void)nKnowns, (void)seed, (void)nSeed;
    (void)sensitivity, (void)nSensitivity;
    return unsupported(instance, "fmi3GetDirectionalDerivative",
                       "providesDirectionalDerivatives = false");
}

fmi3Status fmi3GetAdjointDerivative(fmi3Instance instance, const fmi3ValueReference unknowns[],
                                    size_t nUnknowns, const fmi3ValueReference knowns[],
                                    size_t nKnowns, const fmi3Float64 seed[], size_t nSeed,
                                    fmi3Float64 sensitivity[], size_t nSensitivity)
{
    (void)unknowns, (void)nUnknowns, (void)knowns, (void)nKnowns, (void)seed, (void)nSeed;
    (void)sensitivity, (void)nSensitivity;
    return unsupported(instance, "fmi3GetAdjointDerivative", "providesAdjointDerivatives = false");
}

fmi3Status fmi3EnterConfigurationMode(fmi3Instance instance)
{
    return unsupported(instance, "fmi3EnterConfigurationMode", "no structural parameters");
}

fmi3Status fmi3ExitConfigurationMode(fmi3Instance instance)
{
    return unsupported(instance, "fmi3ExitConfigurationMode", "no structural parameters");
}

/* the Clock's interval (s) and qualifier now (FMI 3.0 sec. 2.2.8.2, fmi3GetIntervalDecimal);
 * 0 on error (logged) */
static int clock_interval(Front* f, double* interval, fmi3IntervalQualifier* qualifier)
{
    *interval = 0.0;
    *qualifier = fmi3IntervalUnchanged;
    if (!ATO_CLOCK_COUNTDOWN) { /* fixed: the sample time, given in Initialization Mode */
        fmi2ValueReference vr = (fmi2ValueReference)ATO_SAMPLE_TIME_VR;
        fmi2Status s = backend->get_real ? backend->get_real(f->inner, &vr, 1, interval)
                                         : fmi2Error;
        if (s > fmi2Warning) {
            forwarded(f, s);
            return 0;
        }
        if (f->mode == MODE_INITIALIZATION)
            *qualifier = fmi3IntervalChanged;
        return 1;
    }
    if (ATO_SCHEDULED && f->mode == MODE_INITIALIZATION) {
        /* sec. 2.2.8.2 (countdown Clock): t_0 = t_start + interval; the model's first event
         * is at the start time */
        *qualifier = fmi3IntervalChanged;
        return 1;
    }
    if (f->mode != MODE_EVENT && f->mode != MODE_CLOCK_ACTIVATION) {
        *qualifier = fmi3IntervalNotYetKnown; /* countdown: known in Event Mode */
        return 1;
    }
    double te = 0.0;
    int found = next_event(f, &te);
    if (found < 0)
        return 0;
    if (found && te > f->time && !(f->clock_given && te == f->clock_next)) {
        *interval = te - f->time;
        *qualifier = fmi3IntervalChanged;
        f->clock_next = te;
        f->clock_given = 1;
    }
    return 1;
}

fmi3Status fmi3GetIntervalDecimal(fmi3Instance instance, const fmi3ValueReference vr[],
                                  size_t nvr, fmi3Float64 intervals[],
                                  fmi3IntervalQualifier qualifiers[])
{
    Front* f = (Front*)instance;
    if (nvr == 0)
        return fmi3OK;
    if (!allowed(f, "fmi3GetIntervalDecimal", ALLOW_INITIALIZATION | ALLOW_EVENT |
                                              ALLOW_CLOCK_ACTIVATION) ||
        !clock_references(f, "fmi3GetIntervalDecimal", vr, nvr))
        return fmi3Error;
    for (size_t i = 0; i < nvr; i++)
        if (!clock_interval(f, &intervals[i], &qualifiers[i]))
            return fmi3Error;
    return fmi3OK;
}

fmi3Status fmi3GetIntervalFraction(fmi3Instance instance, const fmi3ValueReference vr[],
                                   size_t nvr, fmi3UInt64 counters[], fmi3UInt64 resolutions[],
                                   fmi3IntervalQualifier qualifiers[])
{
    (void)vr, (void)counters, (void)resolutions, (void)qualifiers;
    return nvr == 0 ? fmi3OK : unsupported(instance, "fmi3GetIntervalFraction", "no clocks");
}

fmi3Status fmi3GetShiftDecimal(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                               fmi3Float64 shifts[])
{
    Front* f = (Front*)instance;
    if (nvr == 0)
        return fmi3OK;
    if (ATO_CLOCK_COUNTDOWN)
        return unsupported(instance, "fmi3GetShiftDecimal", "a countdown Clock has no shift");
    if (!allowed(f, "fmi3GetShiftDecimal", ALLOW_INITIALIZATION | ALLOW_EVENT) ||
        !clock_references(f, "fmi3GetShiftDecimal", vr, nvr))
        return fmi3Error;
    for (size_t i = 0; i < nvr; i++)
        shifts[i] = 0.0; /* the first tick at the start time, the model's first event */
    return fmi3OK;
}

fmi3Status fmi3GetShiftFraction(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                                fmi3UInt64 counters[], fmi3UInt64 resolutions[])
{
    (void)vr, (void)counters, (void)resolutions;
    return nvr == 0 ? fmi3OK : unsupported(instance, "fmi3GetShiftFraction", "no clocks");
}

fmi3Status fmi3SetIntervalDecimal(fmi3Instance instance, const fmi3ValueReference vr[],
                                  size_t nvr, const fmi3Float64 intervals[])
{
    (void)vr, (void)intervals;
    return nvr == 0 ? fmi3OK : unsupported(instance, "fmi3SetIntervalDecimal", "no clocks");
}

fmi3Status fmi3SetIntervalFraction(fmi3Instance instance, const fmi3ValueReference vr[],
                                   size_t nvr, const fmi3UInt64 counters[],
                                   const fmi3UInt64 resolutions[])
{
    (void)vr, (void)counters, (void)resolutions;
    return nvr == 0 ? fmi3OK : unsupported(instance, "fmi3SetIntervalFraction", "no clocks");
}

fmi3Status fmi3SetShiftDecimal(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                               const fmi3Float64 shifts[])
{
    (void)vr, (void)shifts;
    return nvr == 0 ? fmi3OK : unsupported(instance, "fmi3SetShiftDecimal", "no clocks");
}

fmi3Status fmi3SetShiftFraction(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                                const fmi3UInt64 counters[], const fmi3UInt64 resolutions[])
{
    (void)vr, (void)counters, (void)resolutions;
    return nvr == 0 ? fmi3OK : unsupported(instance, "fmi3SetShiftFraction", "no clocks");
}

fmi3Status fmi3EvaluateDiscreteStates(fmi3Instance instance)
{
    return unsupported(instance, "fmi3EvaluateDiscreteStates", "model exchange only");
}

fmi3Status fmi3EnterContinuousTimeMode(fmi3Instance instance)
{
    return unsupported(instance, "fmi3EnterContinuousTimeMode", "model exchange only");
}

fmi3Status fmi3CompletedIntegratorStep(fmi3Instance instance,
                                       fmi3Boolean noSetFMUStatePriorToCurrentPoint,
                                       fmi3Boolean* enterEventMode,
                                       fmi3Boolean* terminateSimulation)
{
    (void)noSetFMUStatePriorToCurrentPoint, (void)enterEventMode, (void)terminateSimulation;
    return unsupported(instance, "fmi3CompletedIntegratorStep", "model exchange only");
}

fmi3Status fmi3SetTime(fmi3Instance instance, fmi3Float64 time)
{
    (void)time;
    return unsupported(instance, "fmi3SetTime", "model exchange only");
}

fmi3Status fmi3SetContinuousStates(fmi3Instance instance, const fmi3Float64 continuousStates[],
                                   size_t nContinuousStates)
{
    (void)continuousStates, (void)nContinuousStates;
    return unsupported(instance, "fmi3SetContinuousStates", "model exchange only");
}

fmi3Status fmi3GetContinuousStateDerivatives(fmi3Instance instance, fmi3Float64 derivatives[],
                                             size_t nContinuousStates)
{
    (void)derivatives, (void)nContinuousStates;
    return unsupported(instance, "fmi3GetContinuousStateDerivatives", "model exchange only");
}

fmi3Status fmi3GetEventIndicators(fmi3Instance instance, fmi3Float64 eventIndicators[],
                                  size_t nEventIndicators)
{
    (void)eventIndicators, (void)nEventIndicators;
    return unsupported(instance, "fmi3GetEventIndicators", "model exchange only");
}

fmi3Status fmi3GetContinuousStates(fmi3Instance instance, fmi3Float64 continuousStates[],
                                   size_t nContinuousStates)
{
    (void)continuousStates, (void)nContinuousStates;
    return unsupported(instance, "fmi3GetContinuousStates", "model exchange only");
}

fmi3Status fmi3GetNominalsOfContinuousStates(fmi3Instance instance, fmi3Float64 nominals[],
                                             size_t nContinuousStates)
{
    (void)nominals, (void)nContinuousStates;
    return unsupported(instance, "fmi3GetNominalsOfContinuousStates", "model exchange only");
}

fmi3Status fmi3GetNumberOfEventIndicators(fmi3Instance instance, size_t* nEventIndicators)
{
    (void)nEventIndicators;
    return unsupported(instance, "fmi3GetNumberOfEventIndicators", "model exchange only");
}

fmi3Status fmi3GetNumberOfContinuousStates(fmi3Instance instance, size_t* nContinuousStates)
{
    (void)nContinuousStates;
    return unsupported(instance, "fmi3GetNumberOfContinuousStates", "model exchange only");
}

fmi3Status fmi3GetOutputDerivatives(fmi3Instance instance, const fmi3ValueReference vr[],
                                    size_t nvr, const fmi3Int32 orders[], fmi3Float64 values[],
                                    size_t nValues)
{
    (void)vr, (void)orders, (void)values, (void)nValues;
    return nvr == 0 ? fmi3OK
                    : unsupported(instance, "fmi3GetOutputDerivatives",
                                  "maxOutputDerivativeOrder = 0");
}

/* FMI 3.0 sec. 5.2.1: the event at activationTime (steps 1-4 at the top of this file) */
fmi3Status fmi3ActivateModelPartition(fmi3Instance instance, fmi3ValueReference clockReference,
                                      fmi3Float64 activationTime)
{
    Front* f = (Front*)instance;
    double t = activationTime, te = 0.0;
    if (!ATO_SCHEDULED)
        return unsupported(instance, "fmi3ActivateModelPartition", "scheduled execution only");
    if (!allowed(f, "fmi3ActivateModelPartition", ALLOW_CLOCK_ACTIVATION) ||
        !clock_references(f, "fmi3ActivateModelPartition", &clockReference, 1))
        return fmi3Error;
    if (!isfinite(t) || ticks(t) < ticks(f->time) ||
        (f->activated && ticks(t) == ticks(f->time))) {
        front_log(f, fmi3Error, "logStatusError", "%s: fmi3ActivateModelPartition at "
                  "activationTime = %.17g s after the %s at %.17g s (FMI 3.0 sec. 5.2.1: "
                  "activation times of a Clock increase strictly)", f->name, t,
                  f->activated ? "activation" : "start time", f->time);
        return fmi3Error;
    }
    if (ticks(t) > ticks(f->time)) { /* 1. commit the previous event, step to t */
        if (!backend->do_step)
            return missing(f, "fmi3ActivateModelPartition");
        fmi3Status s = forwarded(f, backend->do_step(f->inner, f->time, t - f->time, fmi2True));
        if (s > fmi3Warning)
            return s;
    }
    f->time = t;
    f->activated = 1;
    fmi3Status s = release_held(f); /* 2. the inputs of this activation */
    if (s > fmi3Warning)
        return s;
    int found = next_event(f, &te); /* 3. the event computed (its outputs shown) */
    if (found < 0)
        return fmi3Error;
    if (found && !on_periodic_clock(f, te))
        return fmi3Error;
    if (ATO_CLOCK_COUNTDOWN && found && te > t && !(f->clock_given && te == f->clock_next))
        f->clockUpdate(f->environment); /* 4. a new next event: Clock Update Mode */
    return s;
}
