/* The pendulum as an FMI 3.0 FMU, Model Exchange and Co-Simulation (pendulum.h has the model).
 * Every FMI 3.0 function is defined (importers such as fmpy bind them all); those this model has
 * no use for (other integer widths, strings, binaries, clocks, scheduled execution, directional
 * and adjoint derivatives) answer fmi3Error. The FMU state is a copy of the Pendulum struct; its
 * serialisation is its bytes. */

#include "fmi3Functions.h"
#include "pendulum.h"

#define TOKEN "{8c4e810f-3df3-4a00-8276-176fa3c9f003}"

typedef struct {
    Pendulum s;
    fmi3InstanceEnvironment env;
    fmi3LogMessageCallback log;
} Instance;

static fmi3Status fail(Instance *m, const char *message) {
    if (m && m->log) m->log(m->env, fmi3Error, "logStatusError", message);
    return fmi3Error;
}

static Instance *instantiate(fmi3String token, fmi3InstanceEnvironment env, fmi3LogMessageCallback log) {
    if (!token || strcmp(token, TOKEN) != 0) return NULL;
    Instance *m = calloc(1, sizeof *m);
    if (!m) return NULL;
    pendulum_defaults(&m->s);
    m->env = env;
    m->log = log;
    return m;
}

const char *fmi3GetVersion(void) { return fmi3Version; }
fmi3Status fmi3SetDebugLogging(fmi3Instance c, fmi3Boolean on, size_t n, const fmi3String cats[]) {
    (void)c; (void)on; (void)n; (void)cats;
    return fmi3OK;
}
fmi3Instance fmi3InstantiateModelExchange(fmi3String name, fmi3String token, fmi3String resources, fmi3Boolean visible,
                                          fmi3Boolean logging, fmi3InstanceEnvironment env, fmi3LogMessageCallback log) {
    (void)name; (void)resources; (void)visible; (void)logging;
    return instantiate(token, env, log);
}
fmi3Instance fmi3InstantiateCoSimulation(fmi3String name, fmi3String token, fmi3String resources, fmi3Boolean visible,
                                         fmi3Boolean logging, fmi3Boolean eventMode, fmi3Boolean earlyReturn,
                                         const fmi3ValueReference required[], size_t nRequired,
                                         fmi3InstanceEnvironment env, fmi3LogMessageCallback log,
                                         fmi3IntermediateUpdateCallback update) {
    (void)name; (void)resources; (void)visible; (void)logging; (void)eventMode; (void)earlyReturn;
    (void)required; (void)nRequired; (void)update;
    return instantiate(token, env, log);
}
fmi3Instance fmi3InstantiateScheduledExecution(fmi3String name, fmi3String token, fmi3String resources,
                                               fmi3Boolean visible, fmi3Boolean logging, fmi3InstanceEnvironment env,
                                               fmi3LogMessageCallback log, fmi3ClockUpdateCallback clock,
                                               fmi3LockPreemptionCallback lock, fmi3UnlockPreemptionCallback unlock) {
    (void)name; (void)token; (void)resources; (void)visible; (void)logging; (void)env; (void)log;
    (void)clock; (void)lock; (void)unlock;
    return NULL;
}
void fmi3FreeInstance(fmi3Instance c) { free(c); }

fmi3Status fmi3EnterInitializationMode(fmi3Instance c, fmi3Boolean tolDefined, fmi3Float64 tol, fmi3Float64 start,
                                       fmi3Boolean stopDefined, fmi3Float64 stop) {
    (void)tolDefined; (void)tol; (void)stopDefined; (void)stop;
    ((Instance *)c)->s.time = start;
    return fmi3OK;
}
fmi3Status fmi3ExitInitializationMode(fmi3Instance c) { (void)c; return fmi3OK; }
fmi3Status fmi3EnterEventMode(fmi3Instance c) { (void)c; return fmi3OK; }
fmi3Status fmi3Terminate(fmi3Instance c) { (void)c; return fmi3OK; }
fmi3Status fmi3Reset(fmi3Instance c) {
    pendulum_defaults(&((Instance *)c)->s);
    return fmi3OK;
}

fmi3Status fmi3GetFloat64(fmi3Instance c, const fmi3ValueReference vr[], size_t n, fmi3Float64 v[], size_t nv) {
    if (nv != n) return fail(c, "fmi3GetFloat64: the pendulum has scalars only");
    for (size_t i = 0; i < n; i++)
        if (pendulum_get(&((Instance *)c)->s, vr[i], &v[i])) return fail(c, "fmi3GetFloat64: unknown value reference");
    return fmi3OK;
}
fmi3Status fmi3SetFloat64(fmi3Instance c, const fmi3ValueReference vr[], size_t n, const fmi3Float64 v[], size_t nv) {
    if (nv != n) return fail(c, "fmi3SetFloat64: the pendulum has scalars only");
    for (size_t i = 0; i < n; i++)
        if (pendulum_set(&((Instance *)c)->s, vr[i], v[i])) return fail(c, "fmi3SetFloat64: not settable");
    return fmi3OK;
}
fmi3Status fmi3GetInt32(fmi3Instance c, const fmi3ValueReference vr[], size_t n, fmi3Int32 v[], size_t nv) {
    if (nv != n) return fail(c, "fmi3GetInt32: the pendulum has scalars only");
    for (size_t i = 0; i < n; i++) {
        if (vr[i] != VR_SUBSTEPS) return fail(c, "fmi3GetInt32: unknown value reference");
        v[i] = ((Instance *)c)->s.substeps;
    }
    return fmi3OK;
}
fmi3Status fmi3SetInt32(fmi3Instance c, const fmi3ValueReference vr[], size_t n, const fmi3Int32 v[], size_t nv) {
    if (nv != n) return fail(c, "fmi3SetInt32: the pendulum has scalars only");
    for (size_t i = 0; i < n; i++) {
        if (vr[i] != VR_SUBSTEPS || v[i] < 1) return fail(c, "fmi3SetInt32: substeps must be 1 or more");
        ((Instance *)c)->s.substeps = v[i];
    }
    return fmi3OK;
}

/* The types the pendulum has no variables of. */
#define NONE_GET(T, NAME)                                                                                   \
    fmi3Status NAME(fmi3Instance c, const fmi3ValueReference vr[], size_t n, T v[], size_t nv) {         \
        (void)vr; (void)v; (void)nv;                                                                       \
        return n ? fail(c, #NAME ": no variables of this type") : fmi3OK;                                  \
    }
#define NONE_SET(T, NAME)                                                                                   \
    fmi3Status NAME(fmi3Instance c, const fmi3ValueReference vr[], size_t n, const T v[], size_t nv) {   \
        (void)vr; (void)v; (void)nv;                                                                       \
        return n ? fail(c, #NAME ": no variables of this type") : fmi3OK;                                  \
    }
NONE_GET(fmi3Float32, fmi3GetFloat32) NONE_SET(fmi3Float32, fmi3SetFloat32)
NONE_GET(fmi3Int8, fmi3GetInt8) NONE_SET(fmi3Int8, fmi3SetInt8)
NONE_GET(fmi3UInt8, fmi3GetUInt8) NONE_SET(fmi3UInt8, fmi3SetUInt8)
NONE_GET(fmi3Int16, fmi3GetInt16) NONE_SET(fmi3Int16, fmi3SetInt16)
NONE_GET(fmi3UInt16, fmi3GetUInt16) NONE_SET(fmi3UInt16, fmi3SetUInt16)
NONE_GET(fmi3UInt32, fmi3GetUInt32) NONE_SET(fmi3UInt32, fmi3SetUInt32)
NONE_GET(fmi3Int64, fmi3GetInt64) NONE_SET(fmi3Int64, fmi3SetInt64)
NONE_GET(fmi3UInt64, fmi3GetUInt64) NONE_SET(fmi3UInt64, fmi3SetUInt64)
NONE_GET(fmi3Boolean, fmi3GetBoolean) NONE_SET(fmi3Boolean, fmi3SetBoolean)
NONE_GET(fmi3String, fmi3GetString) NONE_SET(fmi3String, fmi3SetString)

fmi3Status fmi3GetBinary(fmi3Instance c, const fmi3ValueReference vr[], size_t n, size_t sizes[], fmi3Binary v[], size_t nv) {
    (void)vr; (void)sizes; (void)v; (void)nv;
    return n ? fail(c, "no Binary variables") : fmi3OK;
}
fmi3Status fmi3SetBinary(fmi3Instance c, const fmi3ValueReference vr[], size_t n, const size_t sizes[], const fmi3Binary v[], size_t nv) {
    (void)vr; (void)sizes; (void)v; (void)nv;
    return n ? fail(c, "no Binary variables") : fmi3OK;
}
fmi3Status fmi3GetClock(fmi3Instance c, const fmi3ValueReference vr[], size_t n, fmi3Clock v[]) {
    (void)vr; (void)v; return n ? fail(c, "no clocks") : fmi3OK;
}
fmi3Status fmi3SetClock(fmi3Instance c, const fmi3ValueReference vr[], size_t n, const fmi3Clock v[]) {
    (void)vr; (void)v; return n ? fail(c, "no clocks") : fmi3OK;
}
fmi3Status fmi3GetNumberOfVariableDependencies(fmi3Instance c, fmi3ValueReference vr, size_t *n) {
    (void)vr; (void)n; return fail(c, "no dependency information");
}
fmi3Status fmi3GetVariableDependencies(fmi3Instance c, fmi3ValueReference dependent, size_t ed[], fmi3ValueReference ind[],
                                       size_t ei[], fmi3DependencyKind kinds[], size_t n) {
    (void)dependent; (void)ed; (void)ind; (void)ei; (void)kinds; (void)n;
    return fail(c, "no dependency information");
}

fmi3Status fmi3GetFMUState(fmi3Instance c, fmi3FMUState *state) {
    if (!*state) *state = malloc(sizeof(Pendulum));
    if (!*state) return fail(c, "out of memory");
    memcpy(*state, &((Instance *)c)->s, sizeof(Pendulum));
    return fmi3OK;
}
fmi3Status fmi3SetFMUState(fmi3Instance c, fmi3FMUState state) {
    memcpy(&((Instance *)c)->s, state, sizeof(Pendulum));
    return fmi3OK;
}
fmi3Status fmi3FreeFMUState(fmi3Instance c, fmi3FMUState *state) {
    (void)c;
    free(*state);
    *state = NULL;
    return fmi3OK;
}
fmi3Status fmi3SerializedFMUStateSize(fmi3Instance c, fmi3FMUState state, size_t *size) {
    (void)c; (void)state;
    *size = sizeof(Pendulum);
    return fmi3OK;
}
fmi3Status fmi3SerializeFMUState(fmi3Instance c, fmi3FMUState state, fmi3Byte bytes[], size_t size) {
    if (size != sizeof(Pendulum)) return fail(c, "fmi3SerializeFMUState: wrong size");
    memcpy(bytes, state, size);
    return fmi3OK;
}
fmi3Status fmi3DeserializeFMUState(fmi3Instance c, const fmi3Byte bytes[], size_t size, fmi3FMUState *state) {
    if (size != sizeof(Pendulum)) return fail(c, "fmi3DeserializeFMUState: not a state of this FMU");
    *state = malloc(size);
    if (!*state) return fail(c, "out of memory");
    memcpy(*state, bytes, size);
    return fmi3OK;
}

fmi3Status fmi3GetDirectionalDerivative(fmi3Instance c, const fmi3ValueReference u[], size_t nu, const fmi3ValueReference k[],
                                        size_t nk, const fmi3Float64 seed[], size_t ns, fmi3Float64 sens[], size_t nsens) {
    (void)u; (void)nu; (void)k; (void)nk; (void)seed; (void)ns; (void)sens; (void)nsens;
    return fail(c, "no directional derivatives");
}
fmi3Status fmi3GetAdjointDerivative(fmi3Instance c, const fmi3ValueReference u[], size_t nu, const fmi3ValueReference k[],
                                    size_t nk, const fmi3Float64 seed[], size_t ns, fmi3Float64 sens[], size_t nsens) {
    (void)u; (void)nu; (void)k; (void)nk; (void)seed; (void)ns; (void)sens; (void)nsens;
    return fail(c, "no adjoint derivatives");
}
fmi3Status fmi3EnterConfigurationMode(fmi3Instance c) { return fail(c, "no structural parameters"); }
fmi3Status fmi3ExitConfigurationMode(fmi3Instance c) { return fail(c, "no structural parameters"); }
fmi3Status fmi3GetIntervalDecimal(fmi3Instance c, const fmi3ValueReference vr[], size_t n, fmi3Float64 iv[], fmi3IntervalQualifier q[]) {
    (void)vr; (void)n; (void)iv; (void)q; return fail(c, "no clocks");
}
fmi3Status fmi3GetIntervalFraction(fmi3Instance c, const fmi3ValueReference vr[], size_t n, fmi3UInt64 cnt[], fmi3UInt64 res[],
                                   fmi3IntervalQualifier q[]) {
    (void)vr; (void)n; (void)cnt; (void)res; (void)q; return fail(c, "no clocks");
}
fmi3Status fmi3GetShiftDecimal(fmi3Instance c, const fmi3ValueReference vr[], size_t n, fmi3Float64 s[]) {
    (void)vr; (void)n; (void)s; return fail(c, "no clocks");
}
fmi3Status fmi3GetShiftFraction(fmi3Instance c, const fmi3ValueReference vr[], size_t n, fmi3UInt64 cnt[], fmi3UInt64 res[]) {
    (void)vr; (void)n; (void)cnt; (void)res; return fail(c, "no clocks");
}
fmi3Status fmi3SetIntervalDecimal(fmi3Instance c, const fmi3ValueReference vr[], size_t n, const fmi3Float64 iv[]) {
    (void)vr; (void)n; (void)iv; return fail(c, "no clocks");
}
fmi3Status fmi3SetIntervalFraction(fmi3Instance c, const fmi3ValueReference vr[], size_t n, const fmi3UInt64 cnt[], const fmi3UInt64 res[]) {
    (void)vr; (void)n; (void)cnt; (void)res; return fail(c, "no clocks");
}
fmi3Status fmi3SetShiftDecimal(fmi3Instance c, const fmi3ValueReference vr[], size_t n, const fmi3Float64 s[]) {
    (void)vr; (void)n; (void)s; return fail(c, "no clocks");
}
fmi3Status fmi3SetShiftFraction(fmi3Instance c, const fmi3ValueReference vr[], size_t n, const fmi3UInt64 cnt[], const fmi3UInt64 res[]) {
    (void)vr; (void)n; (void)cnt; (void)res; return fail(c, "no clocks");
}
fmi3Status fmi3EvaluateDiscreteStates(fmi3Instance c) { (void)c; return fmi3OK; }
fmi3Status fmi3UpdateDiscreteStates(fmi3Instance c, fmi3Boolean *needUpdate, fmi3Boolean *terminate, fmi3Boolean *nominalsChanged,
                                    fmi3Boolean *valuesChanged, fmi3Boolean *nextDefined, fmi3Float64 *next) {
    (void)c;
    *needUpdate = fmi3False;
    *terminate = fmi3False;
    *nominalsChanged = fmi3False;
    *valuesChanged = fmi3False;
    *nextDefined = fmi3False;
    *next = 0.0;
    return fmi3OK;
}

/* Model Exchange */
fmi3Status fmi3EnterContinuousTimeMode(fmi3Instance c) { (void)c; return fmi3OK; }
fmi3Status fmi3CompletedIntegratorStep(fmi3Instance c, fmi3Boolean noPrior, fmi3Boolean *enterEvent, fmi3Boolean *terminate) {
    (void)c; (void)noPrior;
    *enterEvent = fmi3False;
    *terminate = fmi3False;
    return fmi3OK;
}
fmi3Status fmi3SetTime(fmi3Instance c, fmi3Float64 time) {
    ((Instance *)c)->s.time = time;
    return fmi3OK;
}
fmi3Status fmi3SetContinuousStates(fmi3Instance c, const fmi3Float64 x[], size_t nx) {
    if (nx != 3) return fail(c, "the pendulum has 3 continuous states");
    memcpy(((Instance *)c)->s.x, x, 3 * sizeof(double));
    return fmi3OK;
}
fmi3Status fmi3GetContinuousStateDerivatives(fmi3Instance c, fmi3Float64 dx[], size_t nx) {
    Pendulum *s = &((Instance *)c)->s;
    if (nx != 3) return fail(c, "the pendulum has 3 continuous states");
    pendulum_derivative(s->p, s->x, s->current, dx);
    return fmi3OK;
}
fmi3Status fmi3GetEventIndicators(fmi3Instance c, fmi3Float64 z[], size_t nz) {
    (void)z; return nz ? fail(c, "no event indicators") : fmi3OK;
}
fmi3Status fmi3GetContinuousStates(fmi3Instance c, fmi3Float64 x[], size_t nx) {
    if (nx != 3) return fail(c, "the pendulum has 3 continuous states");
    memcpy(x, ((Instance *)c)->s.x, 3 * sizeof(double));
    return fmi3OK;
}
fmi3Status fmi3GetNominalsOfContinuousStates(fmi3Instance c, fmi3Float64 nominal[], size_t nx) {
    (void)c;
    for (size_t i = 0; i < nx; i++) nominal[i] = 1.0;
    return fmi3OK;
}
fmi3Status fmi3GetNumberOfEventIndicators(fmi3Instance c, size_t *n) { (void)c; *n = 0; return fmi3OK; }
fmi3Status fmi3GetNumberOfContinuousStates(fmi3Instance c, size_t *n) { (void)c; *n = 3; return fmi3OK; }

/* Co-Simulation */
fmi3Status fmi3EnterStepMode(fmi3Instance c) { (void)c; return fmi3OK; }
fmi3Status fmi3GetOutputDerivatives(fmi3Instance c, const fmi3ValueReference vr[], size_t n, const fmi3Int32 o[], fmi3Float64 v[], size_t nv) {
    (void)vr; (void)n; (void)o; (void)v; (void)nv;
    return fail(c, "no output derivatives");
}
fmi3Status fmi3DoStep(fmi3Instance c, fmi3Float64 now, fmi3Float64 h, fmi3Boolean noPrior, fmi3Boolean *eventNeeded,
                      fmi3Boolean *terminate, fmi3Boolean *earlyReturn, fmi3Float64 *lastTime) {
    Pendulum *s = &((Instance *)c)->s;
    (void)noPrior;
    pendulum_rk4(s, h);
    s->time = now + h;
    *eventNeeded = fmi3False;
    *terminate = fmi3False;
    *earlyReturn = fmi3False;
    *lastTime = s->time;
    return fmi3OK;
}
fmi3Status fmi3ActivateModelPartition(fmi3Instance c, fmi3ValueReference clock, fmi3Float64 t) {
    (void)clock; (void)t; return fail(c, "no scheduled execution");
}
