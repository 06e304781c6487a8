/* The pendulum as an FMI 2.0 FMU, Model Exchange and Co-Simulation (pendulum.h has the model).
 * Every FMI 2.0 function is defined (importers such as fmpy bind them all); those this model has
 * no use for (directional derivatives, strings, input derivatives, asynchronous steps) answer
 * fmi2Error. The FMU state is a copy of the Pendulum struct; its serialisation is its bytes. */

#include "fmi2Functions.h"
#include "pendulum.h"

#define GUID "{8c4e810f-3df3-4a00-8276-176fa3c9f000}"

typedef struct {
    Pendulum s;
    fmi2Type type;
    fmi2CallbackFunctions cb;
    char name[64];
} Instance;

static fmi2Status fail(Instance *m, const char *message) {
    if (m && m->cb.logger) m->cb.logger(m->cb.componentEnvironment, m->name, fmi2Error, "logStatusError", message);
    return fmi2Error;
}

const char *fmi2GetTypesPlatform(void) { return fmi2TypesPlatform; }
const char *fmi2GetVersion(void) { return fmi2Version; }
fmi2Status fmi2SetDebugLogging(fmi2Component c, fmi2Boolean on, size_t n, const fmi2String cats[]) {
    (void)c; (void)on; (void)n; (void)cats;
    return fmi2OK;
}

fmi2Component fmi2Instantiate(fmi2String name, fmi2Type type, fmi2String guid, fmi2String resources,
                              const fmi2CallbackFunctions *functions, fmi2Boolean visible, fmi2Boolean logging) {
    (void)resources; (void)visible; (void)logging;
    if (!guid || strcmp(guid, GUID) != 0) return NULL;
    Instance *m = calloc(1, sizeof *m);
    if (!m) return NULL;
    pendulum_defaults(&m->s);
    m->type = type;
    if (functions) m->cb = *functions;
    strncpy(m->name, name ? name : "pendulum", sizeof m->name - 1);
    return m;
}

void fmi2FreeInstance(fmi2Component c) { free(c); }

fmi2Status fmi2SetupExperiment(fmi2Component c, fmi2Boolean tolDefined, fmi2Real tol, fmi2Real start,
                               fmi2Boolean stopDefined, fmi2Real stop) {
    (void)tolDefined; (void)tol; (void)stopDefined; (void)stop;
    ((Instance *)c)->s.time = start;
    return fmi2OK;
}
fmi2Status fmi2EnterInitializationMode(fmi2Component c) { (void)c; return fmi2OK; }
fmi2Status fmi2ExitInitializationMode(fmi2Component c) { (void)c; return fmi2OK; }
fmi2Status fmi2Terminate(fmi2Component c) { (void)c; return fmi2OK; }
fmi2Status fmi2Reset(fmi2Component c) {
    Instance *m = c;
    pendulum_defaults(&m->s);
    return fmi2OK;
}

fmi2Status fmi2GetReal(fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2Real value[]) {
    for (size_t i = 0; i < n; i++)
        if (pendulum_get(&((Instance *)c)->s, vr[i], &value[i])) return fail(c, "fmi2GetReal: unknown value reference");
    return fmi2OK;
}
fmi2Status fmi2SetReal(fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2Real value[]) {
    for (size_t i = 0; i < n; i++)
        if (pendulum_set(&((Instance *)c)->s, vr[i], value[i])) return fail(c, "fmi2SetReal: not settable");
    return fmi2OK;
}
fmi2Status fmi2GetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2Integer value[]) {
    for (size_t i = 0; i < n; i++) {
        if (vr[i] != VR_SUBSTEPS) return fail(c, "fmi2GetInteger: unknown value reference");
        value[i] = ((Instance *)c)->s.substeps;
    }
    return fmi2OK;
}
fmi2Status fmi2SetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2Integer value[]) {
    for (size_t i = 0; i < n; i++) {
        if (vr[i] != VR_SUBSTEPS || value[i] < 1) return fail(c, "fmi2SetInteger: substeps must be 1 or more");
        ((Instance *)c)->s.substeps = value[i];
    }
    return fmi2OK;
}
fmi2Status fmi2GetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2Boolean v[]) {
    (void)vr; (void)v; return n ? fail(c, "no Boolean variables") : fmi2OK;
}
fmi2Status fmi2SetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2Boolean v[]) {
    (void)vr; (void)v; return n ? fail(c, "no Boolean variables") : fmi2OK;
}
fmi2Status fmi2GetString(fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2String v[]) {
    (void)vr; (void)v; return n ? fail(c, "no String variables") : fmi2OK;
}
fmi2Status fmi2SetString(fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2String v[]) {
    (void)vr; (void)v; return n ? fail(c, "no String variables") : fmi2OK;
}

fmi2Status fmi2GetFMUstate(fmi2Component c, fmi2FMUstate *state) {
    if (!*state) *state = malloc(sizeof(Pendulum));
    if (!*state) return fail(c, "out of memory");
    memcpy(*state, &((Instance *)c)->s, sizeof(Pendulum));
    return fmi2OK;
}
fmi2Status fmi2SetFMUstate(fmi2Component c, fmi2FMUstate state) {
    memcpy(&((Instance *)c)->s, state, sizeof(Pendulum));
    return fmi2OK;
}
fmi2Status fmi2FreeFMUstate(fmi2Component c, fmi2FMUstate *state) {
    (void)c;
    free(*state);
    *state = NULL;
    return fmi2OK;
}
fmi2Status fmi2SerializedFMUstateSize(fmi2Component c, fmi2FMUstate state, size_t *size) {
    (void)c; (void)state;
    *size = sizeof(Pendulum);
    return fmi2OK;
}
fmi2Status fmi2SerializeFMUstate(fmi2Component c, fmi2FMUstate state, fmi2Byte bytes[], size_t size) {
    if (size != sizeof(Pendulum)) return fail(c, "fmi2SerializeFMUstate: wrong size");
    memcpy(bytes, state, size);
    return fmi2OK;
}
fmi2Status fmi2DeSerializeFMUstate(fmi2Component c, const fmi2Byte bytes[], size_t size, fmi2FMUstate *state) {
    if (size != sizeof(Pendulum)) return fail(c, "fmi2DeSerializeFMUstate: not a state of this FMU");
    *state = malloc(size);
    if (!*state) return fail(c, "out of memory");
    memcpy(*state, bytes, size);
    return fmi2OK;
}
fmi2Status fmi2GetDirectionalDerivative(fmi2Component c, const fmi2ValueReference u[], size_t nu,
                                        const fmi2ValueReference k[], size_t nk, const fmi2Real dk[], fmi2Real du[]) {
    (void)u; (void)nu; (void)k; (void)nk; (void)dk; (void)du;
    return fail(c, "no directional derivatives");
}

/* Model Exchange */
fmi2Status fmi2EnterEventMode(fmi2Component c) { (void)c; return fmi2OK; }
fmi2Status fmi2NewDiscreteStates(fmi2Component c, fmi2EventInfo *info) {
    (void)c;
    memset(info, 0, sizeof *info);
    return fmi2OK;
}
fmi2Status fmi2EnterContinuousTimeMode(fmi2Component c) { (void)c; return fmi2OK; }
fmi2Status fmi2CompletedIntegratorStep(fmi2Component c, fmi2Boolean noPrior, fmi2Boolean *enterEvent, fmi2Boolean *terminate) {
    (void)c; (void)noPrior;
    *enterEvent = fmi2False;
    *terminate = fmi2False;
    return fmi2OK;
}
fmi2Status fmi2SetTime(fmi2Component c, fmi2Real time) {
    ((Instance *)c)->s.time = time;
    return fmi2OK;
}
fmi2Status fmi2SetContinuousStates(fmi2Component c, const fmi2Real x[], size_t nx) {
    if (nx != 3) return fail(c, "the pendulum has 3 continuous states");
    memcpy(((Instance *)c)->s.x, x, 3 * sizeof(double));
    return fmi2OK;
}
fmi2Status fmi2GetDerivatives(fmi2Component c, fmi2Real dx[], size_t nx) {
    Pendulum *s = &((Instance *)c)->s;
    if (nx != 3) return fail(c, "the pendulum has 3 continuous states");
    pendulum_derivative(s->p, s->x, s->current, dx);
    return fmi2OK;
}
fmi2Status fmi2GetEventIndicators(fmi2Component c, fmi2Real z[], size_t nz) {
    (void)z; return nz ? fail(c, "no event indicators") : fmi2OK;
}
fmi2Status fmi2GetContinuousStates(fmi2Component c, fmi2Real x[], size_t nx) {
    if (nx != 3) return fail(c, "the pendulum has 3 continuous states");
    memcpy(x, ((Instance *)c)->s.x, 3 * sizeof(double));
    return fmi2OK;
}
fmi2Status fmi2GetNominalsOfContinuousStates(fmi2Component c, fmi2Real nominal[], size_t nx) {
    (void)c;
    for (size_t i = 0; i < nx; i++) nominal[i] = 1.0;
    return fmi2OK;
}

/* Co-Simulation */
fmi2Status fmi2SetRealInputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2Integer o[], const fmi2Real v[]) {
    (void)vr; (void)n; (void)o; (void)v;
    return fail(c, "no input derivatives");
}
fmi2Status fmi2GetRealOutputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2Integer o[], fmi2Real v[]) {
    (void)vr; (void)n; (void)o; (void)v;
    return fail(c, "no output derivatives");
}
fmi2Status fmi2DoStep(fmi2Component c, fmi2Real now, fmi2Real h, fmi2Boolean noPrior) {
    Pendulum *s = &((Instance *)c)->s;
    (void)noPrior;
    pendulum_rk4(s, h);
    s->time = now + h;
    return fmi2OK;
}
fmi2Status fmi2CancelStep(fmi2Component c) { return fail(c, "doStep is synchronous"); }
fmi2Status fmi2GetStatus(fmi2Component c, const fmi2StatusKind k, fmi2Status *v) { (void)k; (void)v; return fail(c, "doStep is synchronous"); }
fmi2Status fmi2GetRealStatus(fmi2Component c, const fmi2StatusKind k, fmi2Real *v) {
    if (k != fmi2LastSuccessfulTime) return fail(c, "unknown status kind");
    *v = ((Instance *)c)->s.time;
    return fmi2OK;
}
fmi2Status fmi2GetIntegerStatus(fmi2Component c, const fmi2StatusKind k, fmi2Integer *v) { (void)k; (void)v; return fail(c, "no integer status"); }
fmi2Status fmi2GetBooleanStatus(fmi2Component c, const fmi2StatusKind k, fmi2Boolean *v) {
    if (k != fmi2Terminated) return fail(c, "unknown status kind");
    *v = fmi2False;
    return fmi2OK;
}
fmi2Status fmi2GetStringStatus(fmi2Component c, const fmi2StatusKind k, fmi2String *v) { (void)k; (void)v; return fail(c, "no string status"); }
