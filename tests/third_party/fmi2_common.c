/* Minimal FMI 2.0 co-simulation runtime shared by the test FMUs of tests/third_party (written in
 * plain C, as a third-party tool would export them). A model file defines NR, NI, NB, NS (number
 * of Real, Integer (incl. Enumeration), Boolean and String variables; value reference = index in
 * its type), includes this file and implements model_defaults, model_outputs (direct
 * feedthrough, run on every get) and model_step. Values live in one struct, so FMU state is a
 * copy of it. Calls in the wrong state are rejected with fmi2Error (FMI 2.0.4 sec. 4.2.4);
 * NaN parameters and inputs are NOT checked (the standard leaves that to the master). */
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fmi2Functions.h"

enum { INSTANTIATED, INIT_MODE, STEPPING, TERMINATED };

typedef struct {
    fmi2Real r[NR + 1];
    fmi2Integer i[NI + 1];
    fmi2Boolean b[NB + 1];
    char s[NS + 1][64];
    fmi2Real time;
    fmi2Real last_successful;
    fmi2Boolean terminated;
    int mode;
    fmi2CallbackFunctions cb;
    char name[64];
} Inst;

static void model_defaults(Inst *m);
static void model_outputs(Inst *m);
static fmi2Status model_step(Inst *m, fmi2Real t, fmi2Real h);

/* a message as most FMUs log one: the printf format and its arguments handed to the host's
 * logger, which formats them (FMI 2.0.4 sec. 2.1.5) */
#define logf_(m, status, ...) do { \
    if (((Inst *)(m))->cb.logger) \
        ((Inst *)(m))->cb.logger(((Inst *)(m))->cb.componentEnvironment, ((Inst *)(m))->name, \
                                 status, "log", __VA_ARGS__); \
} while (0)

static int in_mode(Inst *m, const char *call, int allowed_mask) {
    if (allowed_mask & (1 << m->mode)) return 1;
    logf_(m, fmi2Error, "%s not allowed in state %d", call, m->mode);
    return 0;
}
#define ANY ((1 << INSTANTIATED) | (1 << INIT_MODE) | (1 << STEPPING) | (1 << TERMINATED))
#define SETTABLE ((1 << INSTANTIATED) | (1 << INIT_MODE) | (1 << STEPPING))

const char *fmi2GetTypesPlatform(void) { return fmi2TypesPlatform; }
const char *fmi2GetVersion(void) { return fmi2Version; }
fmi2Status fmi2SetDebugLogging(fmi2Component c, fmi2Boolean on, size_t n, const fmi2String cat[]) {
    (void)c; (void)on; (void)n; (void)cat;
    return fmi2OK;
}

fmi2Component fmi2Instantiate(fmi2String name, fmi2Type type, fmi2String guid,
                              fmi2String resources, const fmi2CallbackFunctions *cb,
                              fmi2Boolean visible, fmi2Boolean logging) {
    (void)guid; (void)resources; (void)visible; (void)logging;
    if (type != fmi2CoSimulation) return NULL;
#ifdef ON_INSTANTIATE
    ON_INSTANTIATE; /* a hostile test FMU's misbehaviour (hostile.c) */
#endif
    Inst *m = calloc(1, sizeof(Inst));
    if (!m) return NULL;
    if (cb) m->cb = *cb;
    snprintf(m->name, sizeof m->name, "%s", name ? name : "fmu");
    model_defaults(m);
    m->mode = INSTANTIATED;
    return m;
}

void fmi2FreeInstance(fmi2Component c) { free(c); }

fmi2Status fmi2SetupExperiment(fmi2Component c, fmi2Boolean tolDef, fmi2Real tol,
                               fmi2Real start, fmi2Boolean stopDef, fmi2Real stop) {
    Inst *m = c;
    (void)tolDef; (void)tol; (void)stopDef; (void)stop;
    if (!in_mode(m, "fmi2SetupExperiment", 1 << INSTANTIATED)) return fmi2Error;
    m->time = start;
    m->last_successful = start;
    return fmi2OK;
}

fmi2Status fmi2EnterInitializationMode(fmi2Component c) {
    Inst *m = c;
    if (!in_mode(m, "fmi2EnterInitializationMode", 1 << INSTANTIATED)) return fmi2Error;
    m->mode = INIT_MODE;
    return fmi2OK;
}

fmi2Status fmi2ExitInitializationMode(fmi2Component c) {
    Inst *m = c;
    if (!in_mode(m, "fmi2ExitInitializationMode", 1 << INIT_MODE)) return fmi2Error;
    m->mode = STEPPING;
    model_outputs(m);
    return fmi2OK;
}

fmi2Status fmi2Terminate(fmi2Component c) {
    Inst *m = c;
    if (!in_mode(m, "fmi2Terminate", 1 << STEPPING)) return fmi2Error;
    m->mode = TERMINATED;
    return fmi2OK;
}

fmi2Status fmi2Reset(fmi2Component c) {
    Inst *m = c;
    model_defaults(m);
    m->time = 0.0;
    m->terminated = fmi2False;
    m->mode = INSTANTIATED;
    return fmi2OK;
}

static int bad_vr(fmi2ValueReference vr, size_t n) { return (size_t)vr + 1 > n; }
#define CHECK_VR(kind, n)                                                        \
    for (size_t k = 0; k < nvr; k++)                                             \
        if (bad_vr(vr[k], (n))) {                                                \
            logf_(m, fmi2Error, "%s: no value reference %u", kind, vr[k]);        \
            return fmi2Error;                                                    \
        }

fmi2Status fmi2GetReal(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2Real v[]) {
    Inst *m = c;
    if (!in_mode(m, "fmi2GetReal", ANY)) return fmi2Error;
    CHECK_VR("fmi2GetReal", NR)
    if (m->mode != INSTANTIATED) model_outputs(m);
    for (size_t k = 0; k < nvr; k++) v[k] = m->r[vr[k]];
    return fmi2OK;
}
fmi2Status fmi2GetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                          fmi2Integer v[]) {
    Inst *m = c;
    if (!in_mode(m, "fmi2GetInteger", ANY)) return fmi2Error;
    CHECK_VR("fmi2GetInteger", NI)
    if (m->mode != INSTANTIATED) model_outputs(m);
    for (size_t k = 0; k < nvr; k++) v[k] = m->i[vr[k]];
    return fmi2OK;
}
fmi2Status fmi2GetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                          fmi2Boolean v[]) {
    Inst *m = c;
    if (!in_mode(m, "fmi2GetBoolean", ANY)) return fmi2Error;
    CHECK_VR("fmi2GetBoolean", NB)
    if (m->mode != INSTANTIATED) model_outputs(m);
    for (size_t k = 0; k < nvr; k++) v[k] = m->b[vr[k]];
    return fmi2OK;
}
fmi2Status fmi2GetString(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                         fmi2String v[]) {
    Inst *m = c;
    if (!in_mode(m, "fmi2GetString", ANY)) return fmi2Error;
    CHECK_VR("fmi2GetString", NS)
    if (m->mode != INSTANTIATED) model_outputs(m);
    for (size_t k = 0; k < nvr; k++) v[k] = m->s[vr[k]];
    return fmi2OK;
}
fmi2Status fmi2SetReal(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                       const fmi2Real v[]) {
    Inst *m = c;
    if (!in_mode(m, "fmi2SetReal", SETTABLE)) return fmi2Error;
    CHECK_VR("fmi2SetReal", NR)
    for (size_t k = 0; k < nvr; k++) m->r[vr[k]] = v[k];
    return fmi2OK;
}
fmi2Status fmi2SetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                          const fmi2Integer v[]) {
    Inst *m = c;
    if (!in_mode(m, "fmi2SetInteger", SETTABLE)) return fmi2Error;
    CHECK_VR("fmi2SetInteger", NI)
    for (size_t k = 0; k < nvr; k++) m->i[vr[k]] = v[k];
    return fmi2OK;
}
fmi2Status fmi2SetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                          const fmi2Boolean v[]) {
    Inst *m = c;
    if (!in_mode(m, "fmi2SetBoolean", SETTABLE)) return fmi2Error;
    CHECK_VR("fmi2SetBoolean", NB)
    for (size_t k = 0; k < nvr; k++) m->b[vr[k]] = v[k];
    return fmi2OK;
}
fmi2Status fmi2SetString(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                         const fmi2String v[]) {
    Inst *m = c;
    if (!in_mode(m, "fmi2SetString", SETTABLE)) return fmi2Error;
    CHECK_VR("fmi2SetString", NS)
    for (size_t k = 0; k < nvr; k++) snprintf(m->s[vr[k]], sizeof m->s[0], "%s", v[k] ? v[k] : "");
    return fmi2OK;
}

fmi2Status fmi2GetFMUstate(fmi2Component c, fmi2FMUstate *state) {
    Inst *copy = malloc(sizeof(Inst));
    if (!copy) return fmi2Error;
    memcpy(copy, c, sizeof(Inst));
    *state = copy;
    return fmi2OK;
}
fmi2Status fmi2SetFMUstate(fmi2Component c, fmi2FMUstate state) {
    Inst *m = c;
    fmi2CallbackFunctions cb = m->cb;
    char name[64];
    memcpy(name, m->name, sizeof name);
    memcpy(m, state, sizeof(Inst));
    m->cb = cb;
    memcpy(m->name, name, sizeof name);
    return fmi2OK;
}
fmi2Status fmi2FreeFMUstate(fmi2Component c, fmi2FMUstate *state) {
    (void)c;
    free(*state);
    *state = NULL;
    return fmi2OK;
}
fmi2Status fmi2SerializedFMUstateSize(fmi2Component c, fmi2FMUstate s, size_t *size) {
    (void)c; (void)s;
    *size = sizeof(Inst);
    return fmi2OK;
}
fmi2Status fmi2SerializeFMUstate(fmi2Component c, fmi2FMUstate s, fmi2Byte data[], size_t n) {
    (void)c;
    if (n < sizeof(Inst)) return fmi2Error;
    memcpy(data, s, sizeof(Inst));
    return fmi2OK;
}
fmi2Status fmi2DeSerializeFMUstate(fmi2Component c, const fmi2Byte data[], size_t n,
                                   fmi2FMUstate *s) {
    (void)c;
    if (n != sizeof(Inst)) return fmi2Error;
    Inst *copy = malloc(sizeof(Inst));
    if (!copy) return fmi2Error;
    memcpy(copy, data, sizeof(Inst));
    *s = copy;
    return fmi2OK;
}
fmi2Status fmi2GetDirectionalDerivative(fmi2Component c, const fmi2ValueReference u[], size_t nu,
                                        const fmi2ValueReference z[], size_t nz,
                                        const fmi2Real dv[], fmi2Real dz[]) {
    (void)u; (void)nu; (void)z; (void)nz; (void)dv; (void)dz;
    logf_(c, fmi2Error, "fmi2GetDirectionalDerivative is not supported");
    return fmi2Error;
}
fmi2Status fmi2SetRealInputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t n,
                                       const fmi2Integer o[], const fmi2Real v[]) {
    (void)vr; (void)n; (void)o; (void)v;
    logf_(c, fmi2Error, "fmi2SetRealInputDerivatives is not supported");
    return fmi2Error;
}
fmi2Status fmi2GetRealOutputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t n,
                                        const fmi2Integer o[], fmi2Real v[]) {
    (void)vr; (void)n; (void)o; (void)v;
    logf_(c, fmi2Error, "fmi2GetRealOutputDerivatives is not supported");
    return fmi2Error;
}

fmi2Status fmi2DoStep(fmi2Component c, fmi2Real t, fmi2Real h, fmi2Boolean noPrior) {
    Inst *m = c;
    (void)noPrior;
    if (!in_mode(m, "fmi2DoStep", 1 << STEPPING)) return fmi2Error;
#ifdef HANG_ON_NAN_STEP
    volatile int spin = h != h; /* a NaN step size never returns, as some FMUs do */
    while (spin) {
    }
#endif
    if (!(h > 0.0)) {
        logf_(m, fmi2Error, "fmi2DoStep: step size %g must be positive", h);
        return fmi2Error;
    }
    if (m->terminated) {
        logf_(m, fmi2Error, "fmi2DoStep after the FMU terminated at t = %g", m->last_successful);
        return fmi2Error;
    }
    if (fabs(t - m->time) > 1e-9 * (1.0 + fabs(t))) {
        logf_(m, fmi2Error, "fmi2DoStep at t = %g, but the FMU is at t = %.17g", t, m->time);
        return fmi2Error;
    }
    fmi2Status status = model_step(m, t, h);
    if (status == fmi2OK) {
        m->time = t + h;
        m->last_successful = m->time;
    }
    return status;
}
fmi2Status fmi2CancelStep(fmi2Component c) { (void)c; return fmi2Error; }
fmi2Status fmi2GetStatus(fmi2Component c, const fmi2StatusKind k, fmi2Status *v) {
    (void)c; (void)k; (void)v;
    return fmi2Discard;
}
fmi2Status fmi2GetRealStatus(fmi2Component c, const fmi2StatusKind k, fmi2Real *v) {
    Inst *m = c;
    if (k != fmi2LastSuccessfulTime) return fmi2Discard;
    *v = m->last_successful;
    return fmi2OK;
}
fmi2Status fmi2GetIntegerStatus(fmi2Component c, const fmi2StatusKind k, fmi2Integer *v) {
    (void)c; (void)k; (void)v;
    return fmi2Discard;
}
fmi2Status fmi2GetBooleanStatus(fmi2Component c, const fmi2StatusKind k, fmi2Boolean *v) {
    Inst *m = c;
    if (k != fmi2Terminated) return fmi2Discard;
    *v = m->terminated;
    return fmi2OK;
}
fmi2Status fmi2GetStringStatus(fmi2Component c, const fmi2StatusKind k, fmi2String *v) {
    (void)c; (void)k; (void)v;
    return fmi2Discard;
}
