/* FMI 3.0 co-simulation adapter of the native loader (included by fmu_loader.c when compiled with
 * -DREEVE_FMI3; reeve_fmu.fmu.native.install_loader(..., fmi_version=3)).
 *
 * An FMI 3.0 instance is a thin shell around one FMI 2.0 instance of this loader (the fmi2* functions
 * above, with their loading, clean exit, thread states, error relay and fast path): every fmi3 call
 * becomes the fmi2 call(s) of the same meaning, so the model runs in the same guarded state machine
 * (reeve_fmu.fmu.slave.ReeveSlave) as in the FMI 2.0 FMU. Float64 is fmi2Real, Int32 fmi2Integer,
 * Boolean fmi2Boolean (converted: bool vs int), String the same. Value references: as in the FMI 3.0
 * Reference FMUs, 0 is the independent variable `time` (the slave's time, read-only); every other one
 * is the FMI 2.0 value reference + 1 (reeve_fmu.fmu.description.Declarations.to_xml3).
 *
 * What the adapter adds:
 * - the FMI 3.0 logger (no varargs, no instance name): the loader's messages are formatted here;
 * - a call that logged an Error or Fatal message returns fmi3Error (the slave rejects calls out of
 *   order, bad values, unknown value references with a logged reason; pythonfmu returns fmi2OK from
 *   several of them);
 * - the FMI 3.0 call order (instantiated, initialization mode, step mode, terminated): a call in the
 *   wrong state is fmi3Error with the reason, and is not forwarded;
 * - array variables (Declarations.add_array): views over declared scalars, listed in
 *   resources/reeve_fmi3_arrays.txt (FMI 3.0 value reference, size, the elements' FMI 2.0 references);
 * - nValues checked against the number of values the value references hold;
 * - fmi3DoStep's out-arguments: lastSuccessfulTime, terminateSimulation, earlyReturn: when the host
 *   passed earlyReturnAllowed, the slave is told so (allow_early_return) and a model that declares
 *   mightReturnEarlyFromDoStep (the elevator plant) may end a step at an event; the time it reached is
 *   lastSuccessfulTime;
 * - Event Mode (hasEventMode): a host that instantiated with eventModeUsed gets the FMI 3.0 co-simulation
 *   state machine with it: fmi3ExitInitializationMode enters Event Mode, fmi3EnterStepMode leaves it;
 *   an early return at an event sets eventHandlingNeeded, and fmi3EnterEventMode (from Step Mode) lets
 *   the host set inputs and read outputs at that instant; fmi3UpdateDiscreteStates reports no discrete
 *   state to update, no next time event (the models' events are state events the plant finds itself,
 *   and its inputs are held over a step, so there is nothing to iterate). Without eventModeUsed these
 *   calls are fmi3Error with the reason;
 * - everything the FMU does not provide (Model Exchange, Scheduled Execution, clocks, other types,
 *   derivatives, configuration mode) is fmi3Error with a logged reason, never a crash.
 */
#include <stdbool.h>
#include <stdint.h>

typedef void *fmi3Instance;
typedef void *fmi3InstanceEnvironment;
typedef void *fmi3FMUState;
typedef uint32_t fmi3ValueReference;
typedef float fmi3Float32;
typedef double fmi3Float64;
typedef int8_t fmi3Int8;
typedef uint8_t fmi3UInt8;
typedef int16_t fmi3Int16;
typedef uint16_t fmi3UInt16;
typedef int32_t fmi3Int32;
typedef uint32_t fmi3UInt32;
typedef int64_t fmi3Int64;
typedef uint64_t fmi3UInt64;
typedef bool fmi3Boolean;
typedef char fmi3Char;
typedef const fmi3Char *fmi3String;
typedef uint8_t fmi3Byte;
typedef const fmi3Byte *fmi3Binary;
typedef bool fmi3Clock;
typedef enum { fmi3OK, fmi3Warning, fmi3Discard, fmi3Error, fmi3Fatal } fmi3Status;
typedef enum { fmi3Independent, fmi3Constant, fmi3Fixed, fmi3Tunable, fmi3Discrete, fmi3Dependent } fmi3DependencyKind;
typedef enum { fmi3IntervalNotYetKnown, fmi3IntervalUnchanged, fmi3IntervalChanged } fmi3IntervalQualifier;
typedef void (*fmi3LogMessageCallback)(fmi3InstanceEnvironment, fmi3Status, fmi3String, fmi3String);
typedef void (*fmi3IntermediateUpdateCallback)(fmi3InstanceEnvironment, fmi3Float64, fmi3Boolean, fmi3Boolean,
                                               fmi3Boolean, fmi3Boolean, fmi3Boolean *, fmi3Float64 *);
typedef void (*fmi3ClockUpdateCallback)(fmi3InstanceEnvironment);
typedef void (*fmi3LockPreemptionCallback)(void);
typedef void (*fmi3UnlockPreemptionCallback)(void);

enum { S3_INSTANTIATED, S3_INIT, S3_STEP, S3_TERMINATED, S3_EVENT };
static const char *state3_name[] = {"Instantiated", "Initialization Mode", "Step Mode", "Terminated",
                                    "Event Mode"};

typedef struct {
    fmi3ValueReference vr;
    size_t n;
    fmi2ValueReference *el;
} Array3;

typedef struct {
    fmi2Component c;                /* the FMI 2.0 instance (Wrap) this instance runs on */
    Array3 *arrays;                 /* the array variables (resources/reeve_fmi3_arrays.txt) */
    size_t narrays;
    fmi3InstanceEnvironment env;
    fmi3LogMessageCallback log;
    char *name;
    unsigned errors;                /* Error/Fatal messages logged so far */
    int state;
    double start_time;              /* `time` before the slave has one */
    double refused_steps;           /* the slave's count of refused doSteps, as last seen */
    int early_allowed;              /* the host passed earlyReturnAllowed */
    int early_return;               /* ... and the slave accepted it */
    int event_mode_used;            /* the host passed eventModeUsed: Event Mode after initialization */
} Inst3;

/* the FMI 2.0 logger the inner instance gets: formats the message and hands it to the FMI 3.0 one */
static void log3_bridge(fmi2ComponentEnvironment env, fmi2String instance, fmi2Status status,
                        fmi2String category, fmi2String message, ...)
{
    Inst3 *x = (Inst3 *)env;
    char small[2048], *buf = small;
    int n;
    va_list ap;
    (void)instance;
    va_start(ap, message);
    n = vsnprintf(small, sizeof small, message ? message : "", ap);
    va_end(ap);
    if (n >= (int)sizeof small && (buf = (char *)malloc((size_t)n + 1)) != NULL) {
        va_start(ap, message);
        vsnprintf(buf, (size_t)n + 1, message, ap);
        va_end(ap);
    }
    if (!buf) buf = small;
    if (status >= fmi2Error && status != fmi2Pending) x->errors++;
    if (status == fmi2Pending) status = fmi2OK;
    if (x->log)
        x->log(x->env, (fmi3Status)status, category ? category : status_category(status), buf);
    else
        fprintf(stderr, "[%s] %s: %s\n", status_category(status), REEVE_MODEL_IDENTIFIER, buf);
    if (buf != small) free(buf);
}

static void log3(Inst3 *x, fmi3Status status, const char *fmt, ...)
{
    char buf[4096];
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(buf, sizeof buf, fmt, ap);
    va_end(ap);
    if (status >= fmi3Error) x->errors++;
    if (x->log)
        x->log(x->env, status, status_category((fmi2Status)status), buf);
    else
        fprintf(stderr, "[%s] %s: %s\n", status_category((fmi2Status)status), REEVE_MODEL_IDENTIFIER, buf);
}

/* fmi2 status of a forwarded call -> fmi3 status: Error when the call logged an error */
static fmi3Status done3(Inst3 *x, fmi2Status s, unsigned errors_before)
{
    if (s == fmi2Pending) s = fmi2Error;
    if (x->errors != errors_before && s < fmi2Error) s = fmi2Error;
    return (fmi3Status)s;
}

static int in_state(Inst3 *x, const char *fn, int allowed_mask)
{
    if (allowed_mask & (1 << x->state)) return 1;
    log3(x, fmi3Error, "%s: %s called in state %s", x->name, fn, state3_name[x->state]);
    return 0;
}
#define ANY_STATE 0x1F
#define BIT(s) (1 << (s))

/* an array variable of the FMU (resources/reeve_fmi3_arrays.txt): its elements' FMI 2.0 references */
static const Array3 *array_of(const Inst3 *x, fmi3ValueReference vr)
{
    size_t i;
    for (i = 0; i < x->narrays; i++)
        if (x->arrays[i].vr == vr) return &x->arrays[i];
    return NULL;
}

/* number of values of one FMI 3.0 value reference */
static size_t values_of(const Inst3 *x, fmi3ValueReference vr)
{
    const Array3 *a = x->narrays ? array_of(x, vr) : NULL;
    return a ? a->n : 1;
}

/* FMI 3.0 value references -> the FMI 2.0 references of their values, *n of them (into buf, or a
 * malloc'ed array when there are many; free it with unmap_vrs). nValues must be that number. A
 * reference 0 (`time`) is reported with `fn` when time_ok is 0, otherwise it becomes a 0 placeholder.
 * NULL after a logged error. */
#define SMALL_VRS 64
static fmi2ValueReference *map_vrs(Inst3 *x, const char *fn, const fmi3ValueReference *vr, size_t nvr,
                                   size_t nValues, fmi2ValueReference *buf, int time_ok, size_t *n)
{
    size_t i, j, k, total = 0;
    fmi2ValueReference *out;
    for (i = 0; i < nvr; i++) total += values_of(x, vr[i]);
    if (total != nValues) {
        log3(x, fmi3Error, "%s: %s: nValues = %zu, but the %zu value reference(s) hold %zu value(s)", x->name, fn,
             nValues, nvr, total);
        return NULL;
    }
    out = total <= SMALL_VRS ? buf : (fmi2ValueReference *)malloc(total * sizeof *out);
    if (!out) return NULL;
    for (i = 0, j = 0; i < nvr; i++) {
        const Array3 *a = x->narrays ? array_of(x, vr[i]) : NULL;
        if (a) {
            for (k = 0; k < a->n; k++) out[j++] = a->el[k];
        } else if (vr[i] == 0) {
            if (!time_ok) {
                log3(x, fmi3Error, "%s: %s: value reference 0 is the independent variable time (Float64, "
                     "read-only)", x->name, fn);
                if (out != buf) free(out);
                return NULL;
            }
            out[j++] = 0;
        } else {
            out[j++] = vr[i] - 1;
        }
    }
    *n = total;
    return out;
}

/* the table of array variables, if the FMU has one */
static void read_arrays(Inst3 *x, const char *resources)
{
    char path[4200];
    unsigned long vr, n, k, e;
    FILE *f;
    snprintf(path, sizeof path, "%s/reeve_fmi3_arrays.txt", resources);
    if (!(f = fopen(path, "r"))) return;
    while (fscanf(f, "%lu %lu", &vr, &n) == 2 && n > 0 && n < 1000000) {
        Array3 *grown = (Array3 *)realloc(x->arrays, (x->narrays + 1) * sizeof *grown);
        if (!grown) break;
        x->arrays = grown;
        grown[x->narrays].vr = (fmi3ValueReference)vr;
        grown[x->narrays].n = 0;
        if (!(grown[x->narrays].el = (fmi2ValueReference *)calloc(n, sizeof(fmi2ValueReference)))) break;
        for (k = 0; k < n && fscanf(f, "%lu", &e) == 1; k++) grown[x->narrays].el[k] = (fmi2ValueReference)e;
        grown[x->narrays].n = k;
        x->narrays++;
    }
    fclose(f);
}

static void free_inst3(Inst3 *x)
{
    size_t i;
    for (i = 0; i < x->narrays; i++) free(x->arrays[i].el);
    free(x->arrays);
    free(x->name);
    free(x);
}

static void unmap_vrs(fmi2ValueReference *v, fmi2ValueReference *buf)
{
    if (v && v != buf) free(v);
}

/* a number attribute of the Python slave (`fallback` when it has none or it is None) */
static double slave_number(Inst3 *x, const char *attr, double fallback)
{
    Wrap *w = (Wrap *)x->c;
    double v = fallback;
    int gil;
    PyObject *o;
    if (!w->slave) return fallback;
    ensure_thread_state();
    gil = py.GILStateEnsure();
    o = py.ObjectGetAttrString(w->slave, attr);
    if (o) {
        v = py.FloatAsDouble(o); /* None: -1 with an error set */
        py.DecRef(o);
        if (v == -1.0 && py.ErrOccurred()) v = fallback;
    }
    py.ErrClear();
    py.GILStateRelease(gil);
    return v;
}

/* call a method of the Python slave without arguments: 1 when it ran */
static int slave_call(Inst3 *x, const char *method)
{
    Wrap *w = (Wrap *)x->c;
    int gil, ok = 0;
    PyObject *m, *r = NULL;
    if (!w->slave) return 0;
    ensure_thread_state();
    gil = py.GILStateEnsure();
    if ((m = py.ObjectGetAttrString(w->slave, method)) != NULL) {
        r = py.CallFunctionObjArgs(m, NULL);
        py.DecRef(m);
    }
    if (r) {
        ok = 1;
        py.DecRef(r);
    }
    py.ErrClear();
    py.GILStateRelease(gil);
    return ok;
}

/* ------------------------------------------------------------------ instance lifecycle *//* ------------------------------------------------------------------ instance lifecycle */
EXPORT const char *fmi3GetVersion(void) { return "3.0"; }

/* an absolute path as a file URI the loader's uri_to_path reads back (reserved characters escaped) */
static int path_to_uri(const char *path, char *out, size_t size)
{
    size_t i, j = 7;
    if (!path || path[0] != '/' || size < 8) return -1;
    memcpy(out, "file://", 7);
    for (i = 0; path[i]; i++) {
        unsigned char ch = (unsigned char)path[i];
        if (j + 4 >= size) return -1;
        if (ch == '%' || ch == ' ' || ch == '#' || ch == '?' || ch < 0x20) {
            snprintf(out + j, 4, "%%%02X", ch);
            j += 3;
        } else {
            out[j++] = (char)ch;
        }
    }
    out[j] = 0;
    return 0;
}

EXPORT fmi3Instance fmi3InstantiateCoSimulation(
    fmi3String instanceName, fmi3String instantiationToken, fmi3String resourcePath, fmi3Boolean visible,
    fmi3Boolean loggingOn, fmi3Boolean eventModeUsed, fmi3Boolean earlyReturnAllowed,
    const fmi3ValueReference requiredIntermediateVariables[], size_t nRequiredIntermediateVariables,
    fmi3InstanceEnvironment instanceEnvironment, fmi3LogMessageCallback logMessage,
    fmi3IntermediateUpdateCallback intermediateUpdate)
{
    char uri[8300];
    fmi2CallbackFunctions cb;
    Inst3 *x = (Inst3 *)calloc(1, sizeof(Inst3));
    (void)requiredIntermediateVariables;
    (void)intermediateUpdate;
    if (!x) return NULL;
    x->env = instanceEnvironment;
    x->log = logMessage;
    x->name = strdup(instanceName ? instanceName : "");
    if (nRequiredIntermediateVariables) {
        log3(x, fmi3Error, "%s: cannot instantiate: intermediate variables were requested, but this FMU has "
             "no Intermediate Update Mode (the modelDescription declares providesIntermediateUpdate false)",
             x->name);
        goto fail;
    }
    if (path_to_uri(resourcePath, uri, sizeof uri) != 0) {
        log3(x, fmi3Error, "%s: cannot instantiate: resourcePath '%s' is not an absolute path", x->name,
             resourcePath ? resourcePath : "(null)");
        goto fail;
    }
    memset(&cb, 0, sizeof cb);
    cb.logger = log3_bridge;
    cb.componentEnvironment = x;
    x->c = fmi2Instantiate(instanceName, fmi2CoSimulation, instantiationToken, uri, &cb, visible, loggingOn);
    if (!x->c) goto fail;
    read_arrays(x, resourcePath);
    x->early_allowed = earlyReturnAllowed;
    x->event_mode_used = eventModeUsed;
    if (earlyReturnAllowed) x->early_return = slave_call(x, "allow_early_return");
    x->state = S3_INSTANTIATED;
    return (fmi3Instance)x;
fail:
    free_inst3(x);
    return NULL;
}

EXPORT void fmi3FreeInstance(fmi3Instance instance)
{
    Inst3 *x = (Inst3 *)instance;
    if (!x) return;
    fmi2FreeInstance(x->c);
    free_inst3(x);
}

#define GUARD3(fn, mask)                                                                             \
    Inst3 *x = (Inst3 *)instance;                                                                    \
    unsigned before;                                                                                 \
    if (!x) return fmi3Error;                                                                        \
    if (!in_state(x, fn, mask)) return fmi3Error;                                                    \
    before = x->errors

EXPORT fmi3Status fmi3SetDebugLogging(fmi3Instance instance, fmi3Boolean loggingOn, size_t nCategories,
                                      const fmi3String categories[])
{
    GUARD3("fmi3SetDebugLogging", ANY_STATE);
    return done3(x, fmi2SetDebugLogging(x->c, loggingOn, nCategories, categories), before);
}

EXPORT fmi3Status fmi3EnterInitializationMode(fmi3Instance instance, fmi3Boolean toleranceDefined,
                                              fmi3Float64 tolerance, fmi3Float64 startTime,
                                              fmi3Boolean stopTimeDefined, fmi3Float64 stopTime)
{
    fmi2Status s;
    GUARD3("fmi3EnterInitializationMode", BIT(S3_INSTANTIATED));
    s = fmi2SetupExperiment(x->c, toleranceDefined, tolerance, startTime, stopTimeDefined, stopTime);
    if (s < fmi2Error && x->errors == before) s = fmi2EnterInitializationMode(x->c);
    if (s < fmi2Error && x->errors == before) {
        x->state = S3_INIT;
        x->start_time = startTime;
    }
    return done3(x, s, before);
}

EXPORT fmi3Status fmi3ExitInitializationMode(fmi3Instance instance)
{
    fmi2Status s;
    GUARD3("fmi3ExitInitializationMode", BIT(S3_INIT));
    s = fmi2ExitInitializationMode(x->c);
    /* as the slave: a failed initialization is reported by every later doStep. With eventModeUsed the
     * FMI 3.0 co-simulation state machine goes to Event Mode first (fmi3EnterStepMode then). */
    x->state = x->event_mode_used ? S3_EVENT : S3_STEP;
    return done3(x, s, before);
}

EXPORT fmi3Status fmi3Terminate(fmi3Instance instance)
{
    GUARD3("fmi3Terminate", BIT(S3_INIT) | BIT(S3_STEP) | BIT(S3_EVENT));
    x->state = S3_TERMINATED;
    return done3(x, fmi2Terminate(x->c), before);
}

EXPORT fmi3Status fmi3Reset(fmi3Instance instance)
{
    fmi2Status s;
    GUARD3("fmi3Reset", ANY_STATE);
    s = fmi2Reset(x->c);
    x->state = S3_INSTANTIATED;
    x->refused_steps = 0; /* a new Python slave */
    if (x->early_allowed) x->early_return = slave_call(x, "allow_early_return");
    return done3(x, s, before);
}

EXPORT fmi3Status fmi3DoStep(fmi3Instance instance, fmi3Float64 currentCommunicationPoint,
                             fmi3Float64 communicationStepSize, fmi3Boolean noSetFMUStatePriorToCurrentPoint,
                             fmi3Boolean *eventHandlingNeeded, fmi3Boolean *terminateSimulation,
                             fmi3Boolean *earlyReturn, fmi3Float64 *lastSuccessfulTime)
{
    fmi2Status s;
    fmi2Real last = currentCommunicationPoint;
    fmi2Boolean stop = 0;
    bool early = false;
    GUARD3("fmi3DoStep", BIT(S3_STEP));
    s = fmi2DoStep(x->c, currentCommunicationPoint, communicationStepSize, noSetFMUStatePriorToCurrentPoint);
    if (s <= fmi2Warning) {
        last = currentCommunicationPoint + communicationStepSize;
        if (x->early_return) { /* the slave's time: before t + h after an event (reason logged) */
            double reached = slave_number(x, "time", last);
            if (reached < last) {
                last = reached;
                early = true;
            }
        }
    } else if (s == fmi2Discard) {
        if (fmi2GetRealStatus(x->c, fmi2LastSuccessfulTime, &last) != fmi2OK || last != last)
            last = currentCommunicationPoint;
        if (fmi2GetBooleanStatus(x->c, fmi2Terminated, &stop) != fmi2OK) stop = 0;
    }
    if (eventHandlingNeeded) *eventHandlingNeeded = early && x->event_mode_used;
    if (earlyReturn) *earlyReturn = early;
    if (terminateSimulation) *terminateSimulation = stop != 0;
    if (lastSuccessfulTime) *lastSuccessfulTime = last;
    if (s == fmi2Discard) {
        /* the slave refused the call (time not contiguous, bad inputs, ...): the host's error; the
         * model could not do the step: Discard, as in FMI 2.0. Both are logged with the reason. */
        double refused = slave_number(x, "refused_steps", 0.0);
        if (refused == x->refused_steps) return fmi3Discard;
        x->refused_steps = refused;
        return fmi3Error;
    }
    return done3(x, s, before);
}

/* ------------------------------------------------------------------ values */
#define SETTABLE (BIT(S3_INSTANTIATED) | BIT(S3_INIT) | BIT(S3_STEP) | BIT(S3_EVENT))

EXPORT fmi3Status fmi3GetFloat64(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                                 fmi3Float64 values[], size_t nValues)
{
    fmi2ValueReference buf[SMALL_VRS], *v;
    fmi2Status s = fmi2OK;
    size_t i, j, m, n;
    GUARD3("fmi3GetFloat64", ANY_STATE);
    if (!(v = map_vrs(x, "fmi3GetFloat64", vr, nvr, nValues, buf, 1, &n))) return fmi3Error;
    for (i = 0; i < nvr && vr[i] != 0; i++) {}
    if (i == nvr) {
        s = fmi2GetReal(x->c, v, n, values);
    } else {
        double t = slave_number(x, "time", x->start_time);
        for (i = 0, j = 0; i < nvr && s < fmi2Error; i++, j += m) { /* time among the others: one by one */
            m = values_of(x, vr[i]);
            s = vr[i] == 0 ? (values[j] = t, fmi2OK) : fmi2GetReal(x->c, &v[j], m, &values[j]);
        }
    }
    unmap_vrs(v, buf);
    return done3(x, s, before);
}

EXPORT fmi3Status fmi3SetFloat64(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                                 const fmi3Float64 values[], size_t nValues)
{
    fmi2ValueReference buf[SMALL_VRS], *v;
    fmi2Status s;
    size_t n;
    GUARD3("fmi3SetFloat64", SETTABLE);
    if (!(v = map_vrs(x, "fmi3SetFloat64", vr, nvr, nValues, buf, 0, &n))) return fmi3Error;
    s = fmi2SetReal(x->c, v, n, values);
    unmap_vrs(v, buf);
    return done3(x, s, before);
}

/* the other types: value references mapped (arrays are Float64: none among them), no `time` */
#define MAPPED(fn, call)                                                                             \
    do {                                                                                             \
        fmi2ValueReference buf[SMALL_VRS], *v;                                                       \
        fmi2Status s;                                                                                \
        size_t n;                                                                                    \
        if (!(v = map_vrs(x, fn, vr, nvr, nValues, buf, 0, &n))) return fmi3Error;                   \
        s = call;                                                                                    \
        unmap_vrs(v, buf);                                                                           \
        return done3(x, s, before);                                                                  \
    } while (0)

/* fmi3Boolean is a bool, fmi2Boolean an int: converted through tmp; `get` receives, or `set` gives, them */
static fmi2Status bools(fmi2Component c, const fmi2ValueReference *v, size_t nvr, fmi3Boolean *get,
                        const fmi3Boolean *set)
{
    size_t i;
    fmi2Status s;
    fmi2Boolean *tmp = (fmi2Boolean *)calloc(nvr ? nvr : 1, sizeof *tmp);
    if (!tmp) return fmi2Error;
    for (i = 0; set && i < nvr; i++) tmp[i] = set[i] ? 1 : 0;
    s = set ? fmi2SetBoolean(c, v, nvr, tmp) : fmi2GetBoolean(c, v, nvr, tmp);
    for (i = 0; get && i < nvr; i++) get[i] = tmp[i] != 0;
    free(tmp);
    return s;
}

/* Int32, Boolean and String: the fmi2 call on the mapped references */
#define GET_SET(T, C3, GET, SET)                                                                     \
    EXPORT fmi3Status fmi3Get##T(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,   \
                                 C3 values[], size_t nValues)                                        \
    {                                                                                                \
        GUARD3("fmi3Get" #T, ANY_STATE);                                                             \
        MAPPED("fmi3Get" #T, GET);                                                                   \
    }                                                                                                \
    EXPORT fmi3Status fmi3Set##T(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,   \
                                 const C3 values[], size_t nValues)                                  \
    {                                                                                                \
        GUARD3("fmi3Set" #T, SETTABLE);                                                              \
        MAPPED("fmi3Set" #T, SET);                                                                   \
    }
GET_SET(Int32, fmi3Int32, fmi2GetInteger(x->c, v, n, values), fmi2SetInteger(x->c, v, n, values))
GET_SET(Boolean, fmi3Boolean, bools(x->c, v, n, values, NULL), bools(x->c, v, n, NULL, values))
GET_SET(String, fmi3String, fmi2GetString(x->c, v, n, values), fmi2SetString(x->c, v, n, values))

/* types this FMU has no variables of: an empty call is fine, anything else names the reference */
static fmi3Status no_such_type(fmi3Instance instance, const char *fn, const fmi3ValueReference vr[], size_t nvr)
{
    Inst3 *x = (Inst3 *)instance;
    if (!x) return fmi3Error;
    if (nvr == 0) return fmi3OK;
    log3(x, fmi3Error, "%s: %s: value reference %u is not a variable of this type (the FMU's variables "
         "are Float64, Int32, Boolean and String)", x->name, fn, vr ? vr[0] : 0u);
    return fmi3Error;
}

#define NO_TYPE(T)                                                                                   \
    EXPORT fmi3Status fmi3Get##T(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,   \
                                 fmi3##T values[], size_t nValues)                                   \
    {                                                                                                \
        (void)values; (void)nValues;                                                                 \
        return no_such_type(instance, "fmi3Get" #T, vr, nvr);                                        \
    }                                                                                                \
    EXPORT fmi3Status fmi3Set##T(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,   \
                                 const fmi3##T values[], size_t nValues)                             \
    {                                                                                                \
        (void)values; (void)nValues;                                                                 \
        return no_such_type(instance, "fmi3Set" #T, vr, nvr);                                        \
    }
NO_TYPE(Float32)
NO_TYPE(Int8)
NO_TYPE(UInt8)
NO_TYPE(Int16)
NO_TYPE(UInt16)
NO_TYPE(UInt32)
NO_TYPE(Int64)
NO_TYPE(UInt64)

EXPORT fmi3Status fmi3GetBinary(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                                size_t valueSizes[], fmi3Binary values[], size_t nValues)
{
    (void)valueSizes; (void)values; (void)nValues;
    return no_such_type(instance, "fmi3GetBinary", vr, nvr);
}

EXPORT fmi3Status fmi3SetBinary(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                                const size_t valueSizes[], const fmi3Binary values[], size_t nValues)
{
    (void)valueSizes; (void)values; (void)nValues;
    return no_such_type(instance, "fmi3SetBinary", vr, nvr);
}

EXPORT fmi3Status fmi3GetClock(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr, fmi3Clock values[])
{
    (void)values;
    return no_such_type(instance, "fmi3GetClock", vr, nvr);
}

EXPORT fmi3Status fmi3SetClock(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                               const fmi3Clock values[])
{
    (void)values;
    return no_such_type(instance, "fmi3SetClock", vr, nvr);
}

/* ------------------------------------------------------------------ FMU state */
EXPORT fmi3Status fmi3GetFMUState(fmi3Instance instance, fmi3FMUState *state)
{
    GUARD3("fmi3GetFMUState", SETTABLE | BIT(S3_TERMINATED));
    return done3(x, fmi2GetFMUstate(x->c, state), before);
}

EXPORT fmi3Status fmi3SetFMUState(fmi3Instance instance, fmi3FMUState state)
{
    GUARD3("fmi3SetFMUState", SETTABLE | BIT(S3_TERMINATED));
    if (!state) {
        log3(x, fmi3Error, "%s: fmi3SetFMUState: the state is NULL", x->name);
        return fmi3Error;
    }
    return done3(x, fmi2SetFMUstate(x->c, state), before);
}

EXPORT fmi3Status fmi3FreeFMUState(fmi3Instance instance, fmi3FMUState *state)
{
    GUARD3("fmi3FreeFMUState", ANY_STATE);
    if (!state || !*state) return fmi3OK;
    return done3(x, fmi2FreeFMUstate(x->c, state), before);
}

EXPORT fmi3Status fmi3SerializedFMUStateSize(fmi3Instance instance, fmi3FMUState state, size_t *size)
{
    GUARD3("fmi3SerializedFMUStateSize", ANY_STATE);
    return done3(x, fmi2SerializedFMUstateSize(x->c, state, size), before);
}

EXPORT fmi3Status fmi3SerializeFMUState(fmi3Instance instance, fmi3FMUState state, fmi3Byte serializedState[],
                                        size_t size)
{
    GUARD3("fmi3SerializeFMUState", ANY_STATE);
    return done3(x, fmi2SerializeFMUstate(x->c, state, (fmi2Byte *)serializedState, size), before);
}

EXPORT fmi3Status fmi3DeserializeFMUState(fmi3Instance instance, const fmi3Byte serializedState[], size_t size,
                                          fmi3FMUState *state)
{
    GUARD3("fmi3DeserializeFMUState", ANY_STATE);
    return done3(x, fmi2DeSerializeFMUstate(x->c, (const fmi2Byte *)serializedState, size, state), before);
}

/* ------------------------------------------------------------------ Event Mode (eventModeUsed) */
static int event_mode_used(Inst3 *x, const char *fn)
{
    if (x->event_mode_used) return 1;
    log3(x, fmi3Error, "%s: %s: the instance was created with eventModeUsed = false (it has no Event Mode; "
         "instantiate with eventModeUsed = true to use it)", x->name, fn);
    return 0;
}

EXPORT fmi3Status fmi3EnterEventMode(fmi3Instance instance)
{
    GUARD3("fmi3EnterEventMode", BIT(S3_STEP));
    if (!event_mode_used(x, "fmi3EnterEventMode")) return fmi3Error;
    x->state = S3_EVENT;
    return fmi3OK;
}

EXPORT fmi3Status fmi3UpdateDiscreteStates(fmi3Instance instance, fmi3Boolean *discreteStatesNeedUpdate,
                                           fmi3Boolean *terminateSimulation,
                                           fmi3Boolean *nominalsOfContinuousStatesChanged,
                                           fmi3Boolean *valuesOfContinuousStatesChanged,
                                           fmi3Boolean *nextEventTimeDefined, fmi3Float64 *nextEventTime)
{
    GUARD3("fmi3UpdateDiscreteStates", BIT(S3_EVENT));
    (void)before;
    /* no discrete states: the event iteration has converged at once; no time events are scheduled */
    if (discreteStatesNeedUpdate) *discreteStatesNeedUpdate = false;
    if (terminateSimulation) *terminateSimulation = false;
    if (nominalsOfContinuousStatesChanged) *nominalsOfContinuousStatesChanged = false;
    if (valuesOfContinuousStatesChanged) *valuesOfContinuousStatesChanged = false;
    if (nextEventTimeDefined) *nextEventTimeDefined = false;
    if (nextEventTime) *nextEventTime = 0.0;
    return fmi3OK;
}

EXPORT fmi3Status fmi3EnterStepMode(fmi3Instance instance)
{
    GUARD3("fmi3EnterStepMode", BIT(S3_EVENT));
    (void)before;
    x->state = S3_STEP;
    return fmi3OK;
}

/* ------------------------------------------------------------------ what this FMU does not provide */
static fmi3Status unsupported(fmi3Instance instance, const char *fn)
{
    Inst3 *x = (Inst3 *)instance;
    if (!x) return fmi3Error;
    log3(x, fmi3Error, "%s: %s is not supported by this FMU (co-simulation without Intermediate Update "
         "Mode, clocks or derivatives)", x->name, fn);
    return fmi3Error;
}

EXPORT fmi3Instance fmi3InstantiateModelExchange(fmi3String instanceName, fmi3String instantiationToken,
                                                 fmi3String resourcePath, fmi3Boolean visible,
                                                 fmi3Boolean loggingOn, fmi3InstanceEnvironment instanceEnvironment,
                                                 fmi3LogMessageCallback logMessage)
{
    (void)instantiationToken; (void)resourcePath; (void)visible; (void)loggingOn;
    if (logMessage)
        logMessage(instanceEnvironment, fmi3Error, "logStatusError",
                   "this FMU supports co-simulation only (fmi3InstantiateModelExchange)");
    (void)instanceName;
    return NULL;
}

EXPORT fmi3Instance fmi3InstantiateScheduledExecution(
    fmi3String instanceName, fmi3String instantiationToken, fmi3String resourcePath, fmi3Boolean visible,
    fmi3Boolean loggingOn, fmi3InstanceEnvironment instanceEnvironment, fmi3LogMessageCallback logMessage,
    fmi3ClockUpdateCallback clockUpdate, fmi3LockPreemptionCallback lockPreemption,
    fmi3UnlockPreemptionCallback unlockPreemption)
{
    (void)instanceName; (void)instantiationToken; (void)resourcePath; (void)visible; (void)loggingOn;
    (void)clockUpdate; (void)lockPreemption; (void)unlockPreemption;
    if (logMessage)
        logMessage(instanceEnvironment, fmi3Error, "logStatusError",
                   "this FMU supports co-simulation only (fmi3InstantiateScheduledExecution)");
    return NULL;
}

#define UNSUPPORTED(name, params, uses)                                                              \
    EXPORT fmi3Status name params                                                                    \
    {                                                                                                \
        uses;                                                                                        \
        return unsupported(instance, #name);                                                         \
    }
UNSUPPORTED(fmi3EnterConfigurationMode, (fmi3Instance instance), (void)0)
UNSUPPORTED(fmi3ExitConfigurationMode, (fmi3Instance instance), (void)0)
UNSUPPORTED(fmi3EvaluateDiscreteStates, (fmi3Instance instance), (void)0)
UNSUPPORTED(fmi3EnterContinuousTimeMode, (fmi3Instance instance), (void)0)
UNSUPPORTED(fmi3GetNumberOfVariableDependencies, (fmi3Instance instance, fmi3ValueReference v, size_t *n),
            (void)v; (void)n)
UNSUPPORTED(fmi3GetVariableDependencies, (fmi3Instance instance, fmi3ValueReference d, size_t e[],
                                          fmi3ValueReference i[], size_t ei[], fmi3DependencyKind k[], size_t n),
            (void)d; (void)e; (void)i; (void)ei; (void)k; (void)n)
UNSUPPORTED(fmi3GetDirectionalDerivative, (fmi3Instance instance, const fmi3ValueReference u[], size_t nu,
                                           const fmi3ValueReference k[], size_t nk, const fmi3Float64 s[],
                                           size_t ns, fmi3Float64 o[], size_t no),
            (void)u; (void)nu; (void)k; (void)nk; (void)s; (void)ns; (void)o; (void)no)
UNSUPPORTED(fmi3GetAdjointDerivative, (fmi3Instance instance, const fmi3ValueReference u[], size_t nu,
                                       const fmi3ValueReference k[], size_t nk, const fmi3Float64 s[],
                                       size_t ns, fmi3Float64 o[], size_t no),
            (void)u; (void)nu; (void)k; (void)nk; (void)s; (void)ns; (void)o; (void)no)
UNSUPPORTED(fmi3GetOutputDerivatives, (fmi3Instance instance, const fmi3ValueReference v[], size_t nv,
                                       const fmi3Int32 o[], fmi3Float64 x[], size_t n),
            (void)v; (void)nv; (void)o; (void)x; (void)n)
UNSUPPORTED(fmi3GetIntervalDecimal, (fmi3Instance instance, const fmi3ValueReference v[], size_t n,
                                     fmi3Float64 i[], fmi3IntervalQualifier q[]),
            (void)v; (void)n; (void)i; (void)q)
UNSUPPORTED(fmi3GetIntervalFraction, (fmi3Instance instance, const fmi3ValueReference v[], size_t n,
                                      fmi3UInt64 c[], fmi3UInt64 r[], fmi3IntervalQualifier q[]),
            (void)v; (void)n; (void)c; (void)r; (void)q)
UNSUPPORTED(fmi3GetShiftDecimal, (fmi3Instance instance, const fmi3ValueReference v[], size_t n,
                                  fmi3Float64 s[]), (void)v; (void)n; (void)s)
UNSUPPORTED(fmi3GetShiftFraction, (fmi3Instance instance, const fmi3ValueReference v[], size_t n,
                                   fmi3UInt64 c[], fmi3UInt64 r[]), (void)v; (void)n; (void)c; (void)r)
UNSUPPORTED(fmi3SetIntervalDecimal, (fmi3Instance instance, const fmi3ValueReference v[], size_t n,
                                     const fmi3Float64 i[]), (void)v; (void)n; (void)i)
UNSUPPORTED(fmi3SetIntervalFraction, (fmi3Instance instance, const fmi3ValueReference v[], size_t n,
                                      const fmi3UInt64 c[], const fmi3UInt64 r[]),
            (void)v; (void)n; (void)c; (void)r)
UNSUPPORTED(fmi3SetShiftDecimal, (fmi3Instance instance, const fmi3ValueReference v[], size_t n,
                                  const fmi3Float64 s[]), (void)v; (void)n; (void)s)
UNSUPPORTED(fmi3SetShiftFraction, (fmi3Instance instance, const fmi3ValueReference v[], size_t n,
                                   const fmi3UInt64 c[], const fmi3UInt64 r[]),
            (void)v; (void)n; (void)c; (void)r)
UNSUPPORTED(fmi3ActivateModelPartition, (fmi3Instance instance, fmi3ValueReference c, fmi3Float64 t),
            (void)c; (void)t)
UNSUPPORTED(fmi3CompletedIntegratorStep, (fmi3Instance instance, fmi3Boolean a, fmi3Boolean *b,
                                          fmi3Boolean *c), (void)a; (void)b; (void)c)
UNSUPPORTED(fmi3SetTime, (fmi3Instance instance, fmi3Float64 t), (void)t)
UNSUPPORTED(fmi3SetContinuousStates, (fmi3Instance instance, const fmi3Float64 s[], size_t n), (void)s; (void)n)
UNSUPPORTED(fmi3GetContinuousStateDerivatives, (fmi3Instance instance, fmi3Float64 d[], size_t n),
            (void)d; (void)n)
UNSUPPORTED(fmi3GetEventIndicators, (fmi3Instance instance, fmi3Float64 e[], size_t n), (void)e; (void)n)
UNSUPPORTED(fmi3GetContinuousStates, (fmi3Instance instance, fmi3Float64 s[], size_t n), (void)s; (void)n)
UNSUPPORTED(fmi3GetNominalsOfContinuousStates, (fmi3Instance instance, fmi3Float64 s[], size_t n),
            (void)s; (void)n)
UNSUPPORTED(fmi3GetNumberOfEventIndicators, (fmi3Instance instance, size_t *n), (void)n)
UNSUPPORTED(fmi3GetNumberOfContinuousStates, (fmi3Instance instance, size_t *n), (void)n)
