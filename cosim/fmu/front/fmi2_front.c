/*
 * fmi2_front.c: the FMI 2.0 co-simulation entry points over one statically linked backend
 * (ato_backend.h), for native C models.
 *
 * It keeps the calling-sequence state machine (FMI 2.0.4 sec. 4.2.4: instantiated,
 * initialization mode, step complete, terminated, error): a call in the wrong state returns
 * fmi2Error and says which states allow it; every error goes to the host's logger whether
 * logging is on or not (the backend logs its own errors the same way). Model calls are
 * forwarded to the backend unchanged.
 */
#include <stdarg.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fmi2Functions.h"
#include "ato_backend.h"
#include "instance_registry.h"

enum mode { INSTANTIATED = 1, INIT = 2, STEP = 4, TERMINATED = 8, ERROR_ = 16 };
static const char* mode_name(int m) {
    switch (m) {
    case INSTANTIATED: return "instantiated";
    case INIT: return "initialization mode";
    case STEP: return "step complete";
    case TERMINATED: return "terminated";
    default: return "error";
    }
}

typedef struct {
    const ato_backend* be;
    fmi2Component model;
    fmi2CallbackFunctions cb;
    char* name;
    int mode;
} front;

static void front_error(const fmi2CallbackFunctions* cb, const char* name, const char* fmt,
                        ...) {
    char buf[1024];
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(buf, sizeof buf, fmt, ap);
    va_end(ap);
    char esc[2048]; /* the complete message as the format, '%' doubled (see brake_delay.c) */
    size_t k = 0;
    for (const char* p = buf; *p && k + 2 < sizeof esc; p++) {
        if (*p == '%') esc[k++] = '%';
        esc[k++] = *p;
    }
    esc[k] = 0;
    if (cb && cb->logger)
        cb->logger(cb->componentEnvironment, name ? name : "?", fmi2Error, "logStatusError",
                   esc);
}

static int allowed(front* f, const char* call, int modes) {
    if (f->mode & modes) return 1;
    char list[200] = "";
    for (int m = INSTANTIATED; m <= ERROR_; m <<= 1)
        if (modes & m) {
            if (list[0]) strcat(list, ", ");
            strcat(list, mode_name(m));
        }
    front_error(&f->cb, f->name, "%s not allowed in state '%s' (allowed in: %s)", call,
                mode_name(f->mode), list);
    return 0;
}

static fmi2Status missing(front* f, const char* call) {
    front_error(&f->cb, f->name, "%s: not provided by backend %s", call, f->be->name);
    return fmi2Error;
}

/* a backend error puts the instance in the error state only when FMI says so (fatal) */
static fmi2Status after(front* f, fmi2Status st) {
    if (st == fmi2Fatal) f->mode = ERROR_;
    return st;
}

#define ANY (INSTANTIATED | INIT | STEP | TERMINATED | ERROR_)
#define GETTABLE (INIT | STEP | TERMINATED | ERROR_)
#define SETTABLE (INSTANTIATED | INIT | STEP)

const char* fmi2GetTypesPlatform(void) { return fmi2TypesPlatform; }
const char* fmi2GetVersion(void) { return fmi2Version; }

fmi2Component fmi2Instantiate(fmi2String name, fmi2Type type, fmi2String guid,
                              fmi2String resources, const fmi2CallbackFunctions* cb,
                              fmi2Boolean visible, fmi2Boolean logging_on) {
    char err[512] = "";
    const ato_backend* be = ato_backend_get(err, sizeof err);
    if (!be) {
        front_error(cb, name, "fmi2Instantiate: no backend: %s", err);
        return NULL;
    }
    if (!cb || !cb->logger) {
        /* FMI 2 requires a logger; without one errors could not be reported */
        return NULL;
    }
    fmi2Component model = be->instantiate(name, type, guid, resources, cb, visible, logging_on);
    if (!model) return NULL; /* the backend logged why */
    front* f = calloc(1, sizeof(front));
    f->be = be;
    f->model = model;
    f->cb = *cb;
    f->name = malloc(strlen(name ? name : "?") + 1);
    strcpy(f->name, name ? name : "?");
    f->mode = INSTANTIATED;
    if (!registry_add(f)) {
        front_error(cb, name, "fmi2Instantiate: out of memory");
        be->free_instance(model);
        free(f->name);
        free(f);
        return NULL;
    }
    return f;
}

/* what a second fmi2FreeInstance needs for its message (instance_registry.h) */
typedef struct {
    fmi2CallbackFunctions cb;
    char name[256];
} freed_memo;

void fmi2FreeInstance(fmi2Component c) {
    front* f = c;
    unsigned char buf[REGISTRY_MEMO] = {0};
    freed_memo memo;
    if (!f) return;
    if (registry_is_live(f)) {
        memset(&memo, 0, sizeof memo);
        memo.cb = f->cb;
        snprintf(memo.name, sizeof memo.name, "%s", f->name);
        memcpy(buf, &memo, sizeof memo);
        registry_release(f, buf);
        f->be->free_instance(f->model);
        free(f->name);
        free(f);
        return;
    }
    if (registry_release(f, buf) == -1) {
        memcpy(&memo, buf, sizeof memo);
        front_error(&memo.cb, memo.name, "fmi2FreeInstance: instance '%s' was freed already; "
                    "call refused", memo.name);
    } else {
        fprintf(stderr, "fmi2FreeInstance: %p is not a live instance of this FMU; call "
                "refused\n", (void*)c);
    }
}

fmi2Status fmi2SetDebugLogging(fmi2Component c, fmi2Boolean on, size_t n,
                               const fmi2String cats[]) {
    front* f = c;
    if (!f->be->set_debug_logging) return missing(f, "fmi2SetDebugLogging");
    return after(f, f->be->set_debug_logging(f->model, on, n, cats));
}

fmi2Status fmi2SetupExperiment(fmi2Component c, fmi2Boolean tol_def, fmi2Real tol,
                               fmi2Real start, fmi2Boolean stop_def, fmi2Real stop) {
    front* f = c;
    if (!allowed(f, "fmi2SetupExperiment", INSTANTIATED)) return fmi2Error;
    return after(f, f->be->setup_experiment(f->model, tol_def, tol, start, stop_def, stop));
}

fmi2Status fmi2EnterInitializationMode(fmi2Component c) {
    front* f = c;
    if (!allowed(f, "fmi2EnterInitializationMode", INSTANTIATED)) return fmi2Error;
    fmi2Status st = f->be->enter_initialization_mode(f->model);
    if (st <= fmi2Warning) f->mode = INIT;
    return after(f, st);
}

fmi2Status fmi2ExitInitializationMode(fmi2Component c) {
    front* f = c;
    if (!allowed(f, "fmi2ExitInitializationMode", INIT)) return fmi2Error;
    fmi2Status st = f->be->exit_initialization_mode(f->model);
    if (st <= fmi2Warning) f->mode = STEP;
    return after(f, st);
}

fmi2Status fmi2Terminate(fmi2Component c) {
    front* f = c;
    if (!allowed(f, "fmi2Terminate", STEP)) return fmi2Error;
    fmi2Status st = f->be->terminate(f->model);
    if (st <= fmi2Warning) f->mode = TERMINATED;
    return after(f, st);
}

fmi2Status fmi2Reset(fmi2Component c) {
    front* f = c;
    fmi2Status st = f->be->reset(f->model);
    if (st <= fmi2Warning) f->mode = INSTANTIATED;
    return after(f, st);
}

#define GETTER(NAME, FIELD, T)                                                               \
    fmi2Status NAME(fmi2Component c, const fmi2ValueReference vr[], size_t n, T v[]) {       \
        front* f = c;                                                                         \
        if (!allowed(f, #NAME, GETTABLE)) return fmi2Error;                                   \
        if (!f->be->FIELD) return missing(f, #NAME);                                          \
        return after(f, f->be->FIELD(f->model, vr, n, v));                                    \
    }
#define SETTER(NAME, FIELD, T)                                                               \
    fmi2Status NAME(fmi2Component c, const fmi2ValueReference vr[], size_t n, const T v[]) { \
        front* f = c;                                                                         \
        if (!allowed(f, #NAME, SETTABLE)) return fmi2Error;                                   \
        if (!f->be->FIELD) return missing(f, #NAME);                                          \
        return after(f, f->be->FIELD(f->model, vr, n, v));                                    \
    }
GETTER(fmi2GetReal, get_real, fmi2Real)
GETTER(fmi2GetInteger, get_integer, fmi2Integer)
GETTER(fmi2GetBoolean, get_boolean, fmi2Boolean)
GETTER(fmi2GetString, get_string, fmi2String)
SETTER(fmi2SetReal, set_real, fmi2Real)
SETTER(fmi2SetInteger, set_integer, fmi2Integer)
SETTER(fmi2SetBoolean, set_boolean, fmi2Boolean)
SETTER(fmi2SetString, set_string, fmi2String)

fmi2Status fmi2DoStep(fmi2Component c, fmi2Real t, fmi2Real h, fmi2Boolean no_prior) {
    front* f = c;
    if (!allowed(f, "fmi2DoStep", STEP)) return fmi2Error;
    return after(f, f->be->do_step(f->model, t, h, no_prior));
}

fmi2Status fmi2CancelStep(fmi2Component c) {
    front* f = c;
    front_error(&f->cb, f->name, "fmi2CancelStep: steps are never asynchronous");
    return fmi2Error;
}

static fmi2Status no_status(front* f, const char* call) {
    front_error(&f->cb, f->name, "%s: steps are never asynchronous (no status to report)",
                call);
    return fmi2Discard;
}
fmi2Status fmi2GetStatus(fmi2Component c, const fmi2StatusKind k, fmi2Status* v) {
    (void)k; (void)v;
    return no_status(c, "fmi2GetStatus");
}
fmi2Status fmi2GetRealStatus(fmi2Component c, const fmi2StatusKind k, fmi2Real* v) {
    (void)k; (void)v;
    return no_status(c, "fmi2GetRealStatus");
}
fmi2Status fmi2GetIntegerStatus(fmi2Component c, const fmi2StatusKind k, fmi2Integer* v) {
    (void)k; (void)v;
    return no_status(c, "fmi2GetIntegerStatus");
}
fmi2Status fmi2GetBooleanStatus(fmi2Component c, const fmi2StatusKind k, fmi2Boolean* v) {
    (void)k; (void)v;
    return no_status(c, "fmi2GetBooleanStatus");
}
fmi2Status fmi2GetStringStatus(fmi2Component c, const fmi2StatusKind k, fmi2String* v) {
    (void)k; (void)v;
    return no_status(c, "fmi2GetStringStatus");
}

/* FMU state: the backend's state plus the front's mode (FMI 2.0.4 sec. 2.1.8: a state
 * restores the FMU's situation in the calling sequence too); serialized as one int32 mode
 * followed by the backend's bytes */
typedef struct { int mode; fmi2FMUstate model; } front_state;

fmi2Status fmi2GetFMUstate(fmi2Component c, fmi2FMUstate* s) {
    front* f = c;
    if (!allowed(f, "fmi2GetFMUstate", ANY)) return fmi2Error;
    if (!f->be->get_fmu_state) return missing(f, "fmi2GetFMUstate");
    front_state* fs = *s ? (front_state*)*s : calloc(1, sizeof(front_state));
    fmi2Status st = f->be->get_fmu_state(f->model, &fs->model);
    if (st > fmi2Warning) {
        if (!*s) free(fs);
        return after(f, st);
    }
    fs->mode = f->mode;
    *s = fs;
    return st;
}
fmi2Status fmi2SetFMUstate(fmi2Component c, fmi2FMUstate s) {
    front* f = c;
    if (!allowed(f, "fmi2SetFMUstate", ANY)) return fmi2Error;
    if (!f->be->set_fmu_state) return missing(f, "fmi2SetFMUstate");
    if (!s) {
        front_error(&f->cb, f->name, "fmi2SetFMUstate: no state given");
        return fmi2Error;
    }
    front_state* fs = s;
    fmi2Status st = f->be->set_fmu_state(f->model, fs->model);
    if (st <= fmi2Warning) f->mode = fs->mode;
    return after(f, st);
}
fmi2Status fmi2FreeFMUstate(fmi2Component c, fmi2FMUstate* s) {
    front* f = c;
    if (!s || !*s) return fmi2OK;
    if (!f->be->free_fmu_state) return missing(f, "fmi2FreeFMUstate");
    front_state* fs = *s;
    fmi2Status st = f->be->free_fmu_state(f->model, &fs->model);
    free(fs);
    *s = NULL;
    return after(f, st);
}
fmi2Status fmi2SerializedFMUstateSize(fmi2Component c, fmi2FMUstate s, size_t* n) {
    front* f = c;
    if (!f->be->serialized_fmu_state_size) return missing(f, "fmi2SerializedFMUstateSize");
    fmi2Status st = f->be->serialized_fmu_state_size(f->model, ((front_state*)s)->model, n);
    *n += 4;
    return after(f, st);
}
fmi2Status fmi2SerializeFMUstate(fmi2Component c, fmi2FMUstate s, fmi2Byte b[], size_t n) {
    front* f = c;
    if (!f->be->serialize_fmu_state) return missing(f, "fmi2SerializeFMUstate");
    if (n < 4) {
        front_error(&f->cb, f->name, "fmi2SerializeFMUstate: buffer of %zu bytes too small", n);
        return fmi2Error;
    }
    int32_t mode = ((front_state*)s)->mode;
    memcpy(b, &mode, 4);
    return after(f, f->be->serialize_fmu_state(f->model, ((front_state*)s)->model, b + 4,
                                               n - 4));
}
fmi2Status fmi2DeSerializeFMUstate(fmi2Component c, const fmi2Byte b[], size_t n,
                                   fmi2FMUstate* s) {
    front* f = c;
    if (!f->be->deserialize_fmu_state) return missing(f, "fmi2DeSerializeFMUstate");
    int32_t mode = 0;
    if (n >= 4) memcpy(&mode, b, 4);
    if (n < 4 || !(mode == INSTANTIATED || mode == INIT || mode == STEP || mode == TERMINATED ||
                   mode == ERROR_)) {
        front_error(&f->cb, f->name, "fmi2DeSerializeFMUstate: not a state of this FMU");
        return fmi2Error;
    }
    front_state* fs = *s ? (front_state*)*s : calloc(1, sizeof(front_state));
    fmi2Status st = f->be->deserialize_fmu_state(f->model, b + 4, n - 4, &fs->model);
    if (st > fmi2Warning) {
        if (!*s) free(fs);
        return after(f, st);
    }
    fs->mode = mode;
    *s = fs;
    return st;
}

fmi2Status fmi2GetDirectionalDerivative(fmi2Component c, const fmi2ValueReference u[],
                                        size_t nu, const fmi2ValueReference z[], size_t nz,
                                        const fmi2Real dv[], fmi2Real dz[]) {
    (void)u; (void)nu; (void)z; (void)nz; (void)dv; (void)dz;
    front_error(&((front*)c)->cb, ((front*)c)->name,
                "fmi2GetDirectionalDerivative: not provided (providesDirectionalDerivative "
                "is false)");
    return fmi2Error;
}
fmi2Status fmi2SetRealInputDerivatives(fmi2Component c, const fmi2ValueReference vr[],
                                       size_t n, const fmi2Integer o[], const fmi2Real v[]) {
    (void)vr; (void)n; (void)o; (void)v;
    front_error(&((front*)c)->cb, ((front*)c)->name,
                "fmi2SetRealInputDerivatives: canInterpolateInputs is false");
    return fmi2Error;
}
fmi2Status fmi2GetRealOutputDerivatives(fmi2Component c, const fmi2ValueReference vr[],
                                        size_t n, const fmi2Integer o[], fmi2Real v[]) {
    (void)vr; (void)n; (void)o; (void)v;
    front_error(&((front*)c)->cb, ((front*)c)->name,
                "fmi2GetRealOutputDerivatives: maxOutputDerivativeOrder is 0");
    return fmi2Error;
}
