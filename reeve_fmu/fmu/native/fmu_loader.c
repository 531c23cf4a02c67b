/* reeve_fmu native loader: makes a pythonfmu 0.7.0 FMU a drop-in component for any FMI 2.0 host.
 *
 * Compiled by reeve_fmu.fmu.native when an FMU is built (never committed as a binary). The FMU then has
 *
 *   binaries/linux64/<id>.so            this loader (the host dlopens it like any FMU binary)
 *   binaries/linux64/<id>_pythonfmu.so  pythonfmu's prebuilt binary, renamed
 *   binaries/linux64/<id>_pyexit.so     this file compiled with -DREEVE_EXIT_HELPER: an empty
 *                                       finalizePythonInterpreter() and nothing else
 *
 * What the loader does, in fmi2Instantiate (once per process for the loading part):
 *
 * 1. Python in global scope. pythonfmu's binary links no libpython; its Py* symbols are resolved from
 *    the process's global symbol scope. If the process has no Python there (a C/C++ host), the loader
 *    promotes a libpython the process already loaded privately, or dlopens one with RTLD_GLOBAL:
 *    $REEVE_FMU_LIBPYTHON if set, else the libpython of the interpreter the FMU was built with
 *    (REEVE_LIBPYTHON, recorded at build time), else the standard sonames libpython3.X.so.1.0. A
 *    standalone FMU (`reeve-fmu build --standalone`) carries its interpreter in resources/reeve_runtime/
 *    and that one comes before the build's and the system's. It checks the version (>= 3.10) and
 *    initializes the interpreter itself, without signal handlers, with its home configured, never
 *    guessed: $REEVE_FMU_PYTHONHOME, else $PYTHONHOME (read by Python itself), else the prefix the
 *    loaded libpython lives in (the directory above it holding lib/python3.X/os.py), else the build
 *    interpreter's prefix. So a PATH whose first python3 is another build does not matter (Python
 *    would otherwise take its prefix from there). PyConfig (pyinit.c) when the loaded libpython is the
 *    build's minor version, else Py_SetPythonHome. pythonfmu then never finalizes it, so there is no
 *    interpreter shutdown at exit. In a Python host (fmpy, libcosimpy, ...) the host's interpreter is
 *    used as it is.
 *
 * 2. Clean exit. pythonfmu's library destructor calls finalizePythonInterpreter(), which resets a
 *    static std::shared_ptr that a C++ static destructor has already destroyed at exit (double free:
 *    "corrupted double-linked list", exit 134). The call goes through the PLT, and a library that was
 *    loaded into global scope *before* pythonfmu's binary takes precedence over the binary's own
 *    definition. So the loader dlopens <id>_pyexit.so with RTLD_GLOBAL first (it defines only an empty
 *    finalizePythonInterpreter), then pythonfmu's binary with RTLD_LOCAL | RTLD_NODELETE (never
 *    unloaded: unloading would tear down pythonfmu's interpreter bookkeeping).
 *
 * 3. One Python thread state per host thread. pythonfmu wraps every call in PyGILState_Ensure/Release;
 *    on a thread without a Python thread state that creates and destroys one per call (about 10 us on
 *    Python >= 3.11). Before forwarding a call the loader gives a thread without a thread state a
 *    persistent one: one PyGILState_Ensure whose count is never released (then PyEval_SaveThread to
 *    drop the GIL), remembered in thread-local storage. pythonfmu's own Ensure/Release then only take
 *    and drop the GIL. Python threads (fmpy's) already have a thread state and are left alone.
 *
 * 4. Visible errors. Before pythonfmu instantiates the model, the loader runs preflight() of the
 *    FMU's bootstrap (resources/reeve_fmu.py): it adds the build environment's site-packages
 *    (resources/reeve_env.json) when the loader started the interpreter, and checks that the model's
 *    packages import; a failure becomes a logged reason and fmi2Instantiate returns NULL. pythonfmu
 *    only forwards messages when debug logging is on, so it always gets loggingOn = true and a relay
 *    logger; the relay passes warnings and errors to the host always and OK messages only when the
 *    host asked for logging (fmi2Instantiate's loggingOn, fmi2SetDebugLogging with its categories).
 *    Messages are passed on as printf formats with every '%' escaped.
 *
 * 5. A fast path for reeve_fmu's slaves. pythonfmu turns every call into a Python method call looked up
 *    by name, with lists built per call and its log queue polled after it (about 1 us per call).
 *    A reeve_fmu slave (reeve_fmu.fmu.slave.ReeveSlave) instead shares tables with the loader
 *    (ReeveLink below; it appends itself to a list the loader puts into sys while pythonfmu constructs
 *    it): fmi2SetReal of its Real inputs writes the values into the table, fmi2GetReal of the outputs
 *    its step() writes reads them from it, both without Python (no GIL); fmi2DoStep calls the slave's
 *    do_step directly, then lets pythonfmu forward queued log messages. A value outside its bounds, any
 *    other variable, or a slave not in step mode takes pythonfmu's path, which checks and logs as
 *    before. REEVE_FMU_FAST_PATH=0 in the environment switches it off (the slave declines the link).
 *
 * Every other fmi2 function is forwarded unchanged to pythonfmu's binary.
 *
 * Compiled with -DREEVE_FMI3 (an FMI 3.0 FMU) the loader also exports the fmi3 API: fmi3.c, an adapter
 * over the fmi2 functions here (each FMI 3.0 instance runs on one FMI 2.0 instance of this loader).
 */
#define _GNU_SOURCE
#include <dlfcn.h>
#include <link.h>
#include <math.h>
#include <pthread.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#define EXPORT __attribute__((visibility("default")))

#ifdef REEVE_EXIT_HELPER
/* Replaces pythonfmu's finalizePythonInterpreter (see 2. above): the interpreter bookkeeping is left
 * to the C++ static destructors, which already run at exit. */
EXPORT void finalizePythonInterpreter(void) {}
#else

#ifndef REEVE_MODEL_IDENTIFIER
#error "compile with -DREEVE_MODEL_IDENTIFIER=\"<modelIdentifier>\""
#endif
#ifndef REEVE_LIBPYTHON
#define REEVE_LIBPYTHON ""
#endif
#ifndef REEVE_PY_VERSION
#define REEVE_PY_VERSION "3.11"
#endif
#ifndef REEVE_PYHOME
#define REEVE_PYHOME ""
#endif
#define REEVE_RUNTIME_DIR "reeve_runtime"
#define REEVE_MIN_PY_MINOR 10

/* ------------------------------------------------------------------ FMI 2.0 types (fmi2TypesPlatform) */
typedef void *fmi2Component;
typedef void *fmi2ComponentEnvironment;
typedef void *fmi2FMUstate;
typedef unsigned int fmi2ValueReference;
typedef double fmi2Real;
typedef int fmi2Integer;
typedef int fmi2Boolean;
typedef char fmi2Char;
typedef const fmi2Char *fmi2String;
typedef char fmi2Byte;
typedef enum { fmi2OK, fmi2Warning, fmi2Discard, fmi2Error, fmi2Fatal, fmi2Pending } fmi2Status;
typedef enum { fmi2ModelExchange, fmi2CoSimulation } fmi2Type;
typedef enum { fmi2DoStepStatus, fmi2PendingStatus, fmi2LastSuccessfulTime, fmi2Terminated } fmi2StatusKind;
typedef void (*fmi2CallbackLogger)(fmi2ComponentEnvironment, fmi2String, fmi2Status, fmi2String,
                                   fmi2String, ...);
typedef void *(*fmi2CallbackAllocateMemory)(size_t, size_t);
typedef void (*fmi2CallbackFreeMemory)(void *);
typedef void (*fmi2StepFinished)(fmi2ComponentEnvironment, fmi2Status);
typedef struct {
    fmi2CallbackLogger logger;
    fmi2CallbackAllocateMemory allocateMemory;
    fmi2CallbackFreeMemory freeMemory;
    fmi2StepFinished stepFinished;
    fmi2ComponentEnvironment componentEnvironment;
} fmi2CallbackFunctions;

/* ------------------------------------------------------------------ the CPython functions used */
typedef void PyObject;
typedef void PyThreadState;
#define PY_FILE_INPUT 257
static struct {
    int (*IsInitialized)(void);
    void (*InitializeEx)(int);
    const char *(*GetVersion)(void);
    PyThreadState *(*EvalSaveThread)(void);
    int (*GILStateEnsure)(void);
    void (*GILStateRelease)(int);
    PyThreadState *(*GILStateGetThisThreadState)(void);
    PyObject *(*DictNew)(void);
    int (*DictSetItemString)(PyObject *, const char *, PyObject *);
    PyObject *(*DictGetItemString)(PyObject *, const char *);
    PyObject *(*EvalGetBuiltins)(void);
    PyObject *(*UnicodeDecodeFSDefault)(const char *);
    PyObject *(*BoolFromLong)(long);
    PyObject *(*CompileString)(const char *, const char *, int);
    PyObject *(*EvalEvalCode)(PyObject *, PyObject *, PyObject *);
    void (*ErrFetch)(PyObject **, PyObject **, PyObject **);
    PyObject *(*ObjectStr)(PyObject *);
    const char *(*UnicodeAsUTF8AndSize)(PyObject *, ptrdiff_t *);
    void (*DecRef)(PyObject *);
    /* the fast path (5.) */
    void (*IncRef)(PyObject *);
    PyObject *(*FloatFromDouble)(double);
    PyObject *(*CallFunctionObjArgs)(PyObject *, ...);
    int (*ObjectIsTrue)(PyObject *);
    PyObject *(*ListNew)(ptrdiff_t);
    ptrdiff_t (*ListSize)(PyObject *);
    PyObject *(*ListGetItem)(PyObject *, ptrdiff_t);
    PyObject *(*SysGetObject)(const char *);
    int (*SysSetObject)(const char *, PyObject *);
    PyObject *(*ObjectGetAttrString)(PyObject *, const char *);
    void *(*LongAsVoidPtr)(PyObject *);
    void (*ErrClear)(void);
#ifdef REEVE_FMI3
    double (*FloatAsDouble)(PyObject *); /* the slave's time (FMI 3.0's `time`), refused steps */
    PyObject *(*ErrOccurred)(void);
#endif
} py;

static const char *py_names[] = {
    "Py_IsInitialized", "Py_InitializeEx", "Py_GetVersion", "PyEval_SaveThread", "PyGILState_Ensure",
    "PyGILState_Release", "PyGILState_GetThisThreadState", "PyDict_New", "PyDict_SetItemString",
    "PyDict_GetItemString", "PyEval_GetBuiltins", "PyUnicode_DecodeFSDefault", "PyBool_FromLong",
    "Py_CompileString", "PyEval_EvalCode", "PyErr_Fetch", "PyObject_Str", "PyUnicode_AsUTF8AndSize",
    "Py_DecRef", "Py_IncRef", "PyFloat_FromDouble", "PyObject_CallFunctionObjArgs", "PyObject_IsTrue",
    "PyList_New", "PyList_Size", "PyList_GetItem", "PySys_GetObject", "PySys_SetObject",
    "PyObject_GetAttrString", "PyLong_AsVoidPtr", "PyErr_Clear",
#ifdef REEVE_FMI3
    "PyFloat_AsDouble", "PyErr_Occurred",
#endif
};

/* ------------------------------------------------------------------ the fmi2 functions */
#define FMI2_FORWARDED(X)                                                                            \
    X(fmi2Status, fmi2SetupExperiment, (fmi2Component c, fmi2Boolean a, fmi2Real b, fmi2Real d,      \
                                        fmi2Boolean e, fmi2Real f), (W, a, b, d, e, f))                 \
    X(fmi2Status, fmi2EnterInitializationMode, (fmi2Component c), (W))                                \
    X(fmi2Status, fmi2Terminate, (fmi2Component c), (W))                                              \
    X(fmi2Status, fmi2GetInteger, (fmi2Component c, const fmi2ValueReference *v, size_t n,           \
                                   fmi2Integer *x), (W, v, n, x))                                       \
    X(fmi2Status, fmi2GetBoolean, (fmi2Component c, const fmi2ValueReference *v, size_t n,           \
                                   fmi2Boolean *x), (W, v, n, x))                                       \
    X(fmi2Status, fmi2GetString, (fmi2Component c, const fmi2ValueReference *v, size_t n,            \
                                  fmi2String *x), (W, v, n, x))                                         \
    X(fmi2Status, fmi2SetInteger, (fmi2Component c, const fmi2ValueReference *v, size_t n,           \
                                   const fmi2Integer *x), (W, v, n, x))                                 \
    X(fmi2Status, fmi2SetBoolean, (fmi2Component c, const fmi2ValueReference *v, size_t n,           \
                                   const fmi2Boolean *x), (W, v, n, x))                                 \
    X(fmi2Status, fmi2SetString, (fmi2Component c, const fmi2ValueReference *v, size_t n,            \
                                  const fmi2String *x), (W, v, n, x))                                   \
    X(fmi2Status, fmi2GetFMUstate, (fmi2Component c, fmi2FMUstate *s), (W, s))                          \
    X(fmi2Status, fmi2SetFMUstate, (fmi2Component c, fmi2FMUstate s), (W, s))                           \
    X(fmi2Status, fmi2FreeFMUstate, (fmi2Component c, fmi2FMUstate *s), (W, s))                         \
    X(fmi2Status, fmi2SerializedFMUstateSize, (fmi2Component c, fmi2FMUstate s, size_t *n), (W, s, n))  \
    X(fmi2Status, fmi2SerializeFMUstate, (fmi2Component c, fmi2FMUstate s, fmi2Byte *b, size_t n),   \
      (W, s, b, n))                                                                                     \
    X(fmi2Status, fmi2DeSerializeFMUstate, (fmi2Component c, const fmi2Byte *b, size_t n,            \
                                            fmi2FMUstate *s), (W, b, n, s))                             \
    X(fmi2Status, fmi2GetDirectionalDerivative, (fmi2Component c, const fmi2ValueReference *u,       \
      size_t nu, const fmi2ValueReference *z, size_t nz, const fmi2Real *du, fmi2Real *dz),          \
      (W, u, nu, z, nz, du, dz))                                                                        \
    X(fmi2Status, fmi2SetRealInputDerivatives, (fmi2Component c, const fmi2ValueReference *v,        \
      size_t n, const fmi2Integer *o, const fmi2Real *x), (W, v, n, o, x))                              \
    X(fmi2Status, fmi2GetRealOutputDerivatives, (fmi2Component c, const fmi2ValueReference *v,       \
      size_t n, const fmi2Integer *o, fmi2Real *x), (W, v, n, o, x))                                    \
    X(fmi2Status, fmi2CancelStep, (fmi2Component c), (W))                                             \
    X(fmi2Status, fmi2GetStatus, (fmi2Component c, const fmi2StatusKind k, fmi2Status *v), (W, k, v))   \
    X(fmi2Status, fmi2GetIntegerStatus, (fmi2Component c, const fmi2StatusKind k, fmi2Integer *v),   \
      (W, k, v))                                                                                        \
    X(fmi2Status, fmi2GetStringStatus, (fmi2Component c, const fmi2StatusKind k, fmi2String *v),     \
      (W, k, v))

/* the functions the loader defines itself (the fast path, 5.), forwarding what it does not handle */
#define FMI2_OWN(X)                                                                                  \
    X(fmi2Status, fmi2Reset, (fmi2Component c), (W))                                                  \
    X(fmi2Status, fmi2ExitInitializationMode, (fmi2Component c), (W))                                 \
    X(fmi2Status, fmi2GetReal, (fmi2Component c, const fmi2ValueReference *v, size_t n, fmi2Real *x), \
      (W, v, n, x))                                                                                     \
    X(fmi2Status, fmi2SetReal, (fmi2Component c, const fmi2ValueReference *v, size_t n,              \
                                const fmi2Real *x), (W, v, n, x))                                       \
    X(fmi2Status, fmi2DoStep, (fmi2Component c, fmi2Real t, fmi2Real h, fmi2Boolean p), (W, t, h, p))   \
    X(fmi2Status, fmi2GetRealStatus, (fmi2Component c, const fmi2StatusKind k, fmi2Real *v), (W, k, v)) \
    X(fmi2Status, fmi2GetBooleanStatus, (fmi2Component c, const fmi2StatusKind k, fmi2Boolean *v),   \
      (W, k, v))

/* the inner (pythonfmu) function pointers */
#define DECLARE_INNER(ret, name, params, args) static ret(*inner_##name) params;
FMI2_FORWARDED(DECLARE_INNER)
FMI2_OWN(DECLARE_INNER)
static fmi2Component (*inner_fmi2Instantiate)(fmi2String, fmi2Type, fmi2String, fmi2String,
                                              const fmi2CallbackFunctions *, fmi2Boolean, fmi2Boolean);
static void (*inner_fmi2FreeInstance)(fmi2Component);
static fmi2Status (*inner_fmi2SetDebugLogging)(fmi2Component, fmi2Boolean, size_t, const fmi2String *);

/* The tables a reeve_fmu slave shares with the loader (reeve_fmu/fmu/fastlink.py, same layout), all
 * indexed by value reference and owned by the Python slave (the loader holds a reference to it). */
#define REEVE_LINK_VERSION 1
typedef struct ReeveLink {
    int version;       /* REEVE_LINK_VERSION */
    int n_vr;          /* length of every table */
    int *state;        /* [0] setReal may be done here, [1] getReal may be done here,
                        * [2] some input was written here and is not yet pulled into Python */
    const int *kind;   /* 1: a Real input without side effects, 2: an output kept current in val */
    const double *lo;  /* bounds of an input (+-DBL_MAX when none: inf and NaN fail them) */
    const double *hi;
    double *val;       /* the value */
    int *dirty;        /* 1: written here, not yet pulled */
} ReeveLink;

/* one wrapper per instance: the host sees this, pythonfmu sees `inner` */
typedef struct {
    fmi2Component inner;
    fmi2CallbackFunctions host;   /* the host's callbacks */
    fmi2CallbackFunctions relay;  /* what pythonfmu gets: relay_logger with this wrapper as environment */
    int logging_on;
    size_t ncat;
    char **categories;
    char *instance_name;
    /* the fast path (5.): NULL/0 when the model did not link */
    struct ReeveLink *link;
    PyObject *obj, *do_step, *log_queue; /* the Python slave, its bound do_step, its log queue */
    PyObject *slave;                     /* the Python slave, linked or not (its initialization_failed) */
    double last_ok_time;                 /* fmi2LastSuccessfulTime of the loader's doSteps */
    int stepped, wants_terminate;
} Wrap;

/* ------------------------------------------------------------------ process-wide loading state */
static pthread_mutex_t load_lock = PTHREAD_MUTEX_INITIALIZER;
static int loaded;                /* 1: Python + pythonfmu ready */
static int we_initialized;        /* the loader started the interpreter (a non-Python host) */
static char python_where[2048];   /* where Python came from, for messages */
static char python_home[4096];    /* the home the loader gave the interpreter ("" none) */
static char runtime_dir[4096];    /* the FMU's runtime bundle in use ("" none) */
static char load_error[8192];     /* sticky reason when loading failed */
static __thread int thread_ready; /* this host thread has a Python thread state */

/* ------------------------------------------------------------------ logging */
static const char *status_category(fmi2Status s)
{
    switch (s) {
    case fmi2Warning: return "logStatusWarning";
    case fmi2Discard: return "logStatusDiscard";
    case fmi2Error: return "logStatusError";
    case fmi2Fatal: return "logStatusFatal";
    case fmi2Pending: return "logStatusPending";
    default: return "logAll";
    }
}

/* The text a printf-conforming host would show for `msg` passed as a format without arguments
 * ("%%" -> "%", any other '%' kept literally), escaped again so that it is a safe format. */
static char *safe_format(const char *msg)
{
    size_t n = strlen(msg), i, j = 0;
    char *out = (char *)malloc(2 * n + 1);
    if (!out) return NULL;
    for (i = 0; i < n; i++) {
        if (msg[i] == '%') {
            if (msg[i + 1] == '%') i++;
            out[j++] = '%';
            out[j++] = '%';
        } else {
            out[j++] = msg[i];
        }
    }
    out[j] = 0;
    return out;
}

static int wants(const Wrap *w, fmi2Status status, const char *category)
{
    size_t i;
    if (status >= fmi2Warning && status != fmi2Pending) return 1; /* problems: always */
    if (!w->logging_on) return 0;
    if (w->ncat == 0) return 1;
    for (i = 0; i < w->ncat; i++)
        if (category && strcmp(category, w->categories[i]) == 0) return 1;
    return 0;
}

static void emit(const Wrap *w, fmi2String instance, fmi2Status status, fmi2String category,
                 const char *text)
{
    char *fmt = safe_format(text ? text : "");
    if (!fmt) return;
    if (w && w->host.logger)
        w->host.logger(w->host.componentEnvironment, instance ? instance : "", status,
                       category ? category : status_category(status), fmt);
    else
        fprintf(stderr, "[%s] %s: %s\n", status_category(status), REEVE_MODEL_IDENTIFIER, text);
    free(fmt);
}

static void relay_logger(fmi2ComponentEnvironment env, fmi2String instance, fmi2Status status,
                         fmi2String category, fmi2String message, ...)
{
    const Wrap *w = (const Wrap *)env;
    if (w && wants(w, status, category)) emit(w, instance, status, category, message);
}

static void loader_log(const Wrap *w, fmi2Status status, const char *fmt, ...)
{
    char buf[12000];
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(buf, sizeof buf, fmt, ap);
    va_end(ap);
    if (!w || wants(w, status, NULL))
        emit(w, w ? w->instance_name : "", status, status_category(status), buf);
}

/* ------------------------------------------------------------------ paths */
static void own_dir(char *out, size_t size)
{
    Dl_info info;
    char *slash;
    out[0] = 0;
    if (dladdr((void *)&own_dir, &info) && info.dli_fname) {
        snprintf(out, size, "%s", info.dli_fname);
        slash = strrchr(out, '/');
        if (slash) *slash = 0;
        else snprintf(out, size, ".");
    }
}

static int hexval(char c)
{
    if (c >= '0' && c <= '9') return c - '0';
    if (c >= 'a' && c <= 'f') return c - 'a' + 10;
    if (c >= 'A' && c <= 'F') return c - 'A' + 10;
    return -1;
}

/* file:///abs, file:/abs, file://localhost/abs (percent-decoded) or a plain path -> a local path */
static int uri_to_path(const char *uri, char *out, size_t size)
{
    const char *p = uri;
    size_t j = 0;
    if (!uri) return -1;
    if (strncmp(p, "file://localhost/", 17) == 0) p += 16;
    else if (strncmp(p, "file:///", 8) == 0) p += 7;
    else if (strncmp(p, "file:/", 6) == 0) p += 5;
    else if (strncmp(p, "file:", 5) == 0) return -1; /* file://host/...: not local */
    for (; *p && j + 1 < size; p++) {
        if (*p == '%' && hexval(p[1]) >= 0 && hexval(p[2]) >= 0) {
            out[j++] = (char)(hexval(p[1]) * 16 + hexval(p[2]));
            p += 2;
        } else {
            out[j++] = *p;
        }
    }
    out[j] = 0;
    while (j > 1 && out[j - 1] == '/') out[--j] = 0;
    return j ? 0 : -1;
}

/* ------------------------------------------------------------------ Python */
static int find_loaded_libpython(struct dl_phdr_info *info, size_t size, void *data)
{
    (void)size;
    if (info->dlpi_name && strstr(info->dlpi_name, "/libpython3.")) {
        snprintf((char *)data, 1024, "%s", info->dlpi_name);
        return 1;
    }
    return 0;
}

static int resolve_python(char *err, size_t esize)
{
    size_t i;
    void **slots = (void **)&py;
    for (i = 0; i < sizeof py_names / sizeof py_names[0]; i++) {
        slots[i] = dlsym(RTLD_DEFAULT, py_names[i]);
        if (!slots[i]) {
            snprintf(err, esize, "the Python in this process (%s) lacks the function %s", python_where,
                     py_names[i]);
            return -1;
        }
    }
    return 0;
}

/* ELF checks before dlopen of a file the FMU carries: a truncated or foreign-architecture library gets a
 * reason a user can act on (dlopen's "invalid ELF header" does not say which). */
static unsigned long long le(const unsigned char *b, int n)
{
    unsigned long long v = 0;
    while (n--) v = (v << 8) | b[n];
    return v;
}

static int check_elf(const char *path, char *err, size_t esize)
{
    unsigned char h[64], ph[56];
    unsigned long long size, phoff, shoff, end, i;
    unsigned phnum, phentsize, shnum, shentsize;
    FILE *f = fopen(path, "rb");
    if (!f) {
        snprintf(err, esize, "%s is missing or unreadable", path);
        return -1;
    }
    if (fread(h, 1, sizeof h, f) < sizeof h || memcmp(h, "\177ELF", 4) != 0) {
        fclose(f);
        snprintf(err, esize, "%s is not a shared library (truncated or corrupted)", path);
        return -1;
    }
    if (h[4] != 2 || h[18] != 62 || h[19] != 0) { /* ELFCLASS64, EM_X86_64 */
        fclose(f);
        snprintf(err, esize, "%s is built for another architecture (ELF class %d, machine %d); this "
                 "process is x86-64 (machine 62)", path, h[4], h[18] | (h[19] << 8));
        return -1;
    }
    /* every segment and the section table inside the file: a truncated library would otherwise be
     * mapped past its end and the first access to it kills the host (SIGBUS) */
    fseek(f, 0, SEEK_END);
    size = (unsigned long long)ftell(f);
    phoff = le(h + 32, 8), shoff = le(h + 40, 8);
    phentsize = (unsigned)le(h + 54, 2), phnum = (unsigned)le(h + 56, 2);
    shentsize = (unsigned)le(h + 58, 2), shnum = (unsigned)le(h + 60, 2);
    end = shoff + (unsigned long long)shnum * shentsize;
    for (i = 0; i < phnum && end <= size && phentsize >= sizeof ph; i++) {
        if (fseek(f, (long)(phoff + i * phentsize), SEEK_SET) != 0 || fread(ph, 1, sizeof ph, f) < sizeof ph) {
            end = size + 1;
            break;
        }
        if (le(ph + 8, 8) + le(ph + 32, 8) > end) end = le(ph + 8, 8) + le(ph + 32, 8);
    }
    fclose(f);
    if (end > size) {
        snprintf(err, esize, "%s is truncated (%llu bytes; its headers need %llu)", path, size, end);
        return -1;
    }
    return 0;
}

static int is_file(const char *path)
{
    FILE *f = fopen(path, "rb");
    if (!f) return 0;
    fclose(f);
    return 1;
}

/* The prefix a libpython at lib_path belongs to: the nearest of its directory's first three
 * ancestors holding lib/python<ver>/os.py (pyenv/python.org: <prefix>/lib/libpython..., Debian:
 * /usr/lib/x86_64-linux-gnu/libpython...). "" when none. */
static void prefix_of(const char *lib_path, const char *ver, char *out, size_t size)
{
    char dir[4096], probe[4400];
    int up;
    char *slash;
    out[0] = 0;
    snprintf(dir, sizeof dir, "%s", lib_path);
    for (up = 0; up < 3; up++) {
        slash = strrchr(dir, '/');
        if (!slash || slash == dir) return;
        *slash = 0;
        if (up == 0) continue; /* the library's own directory is lib/, not the prefix */
        snprintf(probe, sizeof probe, "%s/lib/python%s/os.py", dir, ver);
        if (is_file(probe)) {
            snprintf(out, size, "%s", dir);
            return;
        }
    }
}

/* the home to configure (see 1. at the top); "" leaves it to Python ($PYTHONHOME or its own search) */
static void choose_home(const char *ver, char *out, size_t size)
{
    const char *env = getenv("REEVE_FMU_PYTHONHOME");
    Dl_info info;
    out[0] = 0;
    if (env && *env) {
        snprintf(out, size, "%s", env);
        return;
    }
    env = getenv("PYTHONHOME");
    if (env && *env) return;
    if (runtime_dir[0]) {
        snprintf(out, size, "%s", runtime_dir);
        return;
    }
    if (dladdr((void *)py.GetVersion, &info) && info.dli_fname) prefix_of(info.dli_fname, ver, out, size);
    if (!out[0] && REEVE_PYHOME[0] && strcmp(ver, REEVE_PY_VERSION) == 0) snprintf(out, size, "%s", REEVE_PYHOME);
}

int reeve_init_configured(const char *home, char *err, size_t esize); /* pyinit.c */

static int initialize_python(const char *ver, char *err, size_t esize)
{
    char probe[4400];
    int rc = -2;
    choose_home(ver, python_home, sizeof python_home);
    if (python_home[0]) {
        snprintf(probe, sizeof probe, "%s/lib/python%s/encodings/__init__.py", python_home, ver);
        if (!is_file(probe)) {
            snprintf(err, esize, "Python %s (%s) has no standard library under its home %s (%s is "
                     "missing)%s", ver, python_where, python_home, probe,
                     runtime_dir[0] ? ": the FMU's runtime bundle is incomplete; rebuild the FMU"
                                    : ". Set REEVE_FMU_PYTHONHOME to the prefix of that Python");
            return -1;
        }
    }
    if (strcmp(ver, REEVE_PY_VERSION) == 0) rc = reeve_init_configured(python_home, err, esize);
    if (rc == -1) return -1;
    if (rc == -2) { /* another minor version, or no PyConfig compiled in */
        void (*set_home)(const wchar_t *) = (void (*)(const wchar_t *))dlsym(RTLD_DEFAULT, "Py_SetPythonHome");
        wchar_t *(*decode)(const char *, size_t *) =
            (wchar_t * (*)(const char *, size_t *)) dlsym(RTLD_DEFAULT, "Py_DecodeLocale");
        if (python_home[0] && set_home && decode) {
            static wchar_t *home_w; /* must outlive the interpreter */
            home_w = decode(python_home, NULL);
            if (home_w) set_home(home_w);
        }
        py.InitializeEx(0); /* no signal handlers: the host owns the signals */
    }
    if (!py.IsInitialized()) {
        snprintf(err, esize, "Python (%s, home %s) failed to initialize", python_where,
                 python_home[0] ? python_home : "not set");
        return -1;
    }
    return 0;
}

/* resources/reeve_runtime/lib/libpython<build version>.so.1.0 of a standalone FMU: 1 found (path in
 * out), 0 none, -1 a bundle that cannot be used (reason in err) */
static int find_runtime(const char *resources, char *out, size_t size, char *err, size_t esize)
{
    char dir[4200];
    if (!resources || !resources[0]) return 0;
    snprintf(dir, sizeof dir, "%s/%s", resources, REEVE_RUNTIME_DIR);
    snprintf(out, size, "%s/lib/libpython%s.so.1.0", dir, REEVE_PY_VERSION);
    snprintf(err, esize, "%s/manifest.json", dir);
    if (!is_file(err)) {
        err[0] = 0;
        return 0;
    }
    if (check_elf(out, err, esize) != 0) {
        char why[4400];
        snprintf(why, sizeof why, "%s", err);
        snprintf(err, esize, "the FMU's Python runtime bundle (%s) cannot be used: %s. Rebuild the FMU "
                 "with 'reeve-fmu build --standalone' on an x86-64 Linux machine", dir, why);
        return -1;
    }
    snprintf(runtime_dir, sizeof runtime_dir, "%s", dir);
    return 1;
}

static int load_python(const char *resources, char *err, size_t esize)
{
    char tried[6000] = "";
    char cand[1024], bundled[4400], version[32];
    const char *env = getenv("REEVE_FMU_LIBPYTHON");
    int major = 0, minor = 0, m, in_bundle = 0;
    void *h = NULL;

    if (dlsym(RTLD_DEFAULT, "Py_IsInitialized")) {
        snprintf(python_where, sizeof python_where, "the host process");
    } else if (dl_iterate_phdr(find_loaded_libpython, cand) &&
               (h = dlopen(cand, RTLD_NOW | RTLD_NOLOAD | RTLD_GLOBAL))) {
        snprintf(python_where, sizeof python_where, "%s (already loaded by the host)", cand);
    } else if (env && *env) {
        h = dlopen(env, RTLD_NOW | RTLD_GLOBAL);
        if (!h) {
            snprintf(err, esize, "REEVE_FMU_LIBPYTHON=%s cannot be loaded: %s. Point it to the shared "
                     "library of a Python >= 3.%d (e.g. .../lib/libpython3.%s.so.1.0) or unset it.",
                     env, dlerror(), REEVE_MIN_PY_MINOR, REEVE_PY_VERSION + 2);
            return -1;
        }
        snprintf(python_where, sizeof python_where, "%s (REEVE_FMU_LIBPYTHON)", env);
    } else if ((in_bundle = find_runtime(resources, bundled, sizeof bundled, err, esize)) != 0) {
        if (in_bundle < 0) return -1;
        h = dlopen(bundled, RTLD_NOW | RTLD_GLOBAL);
        if (!h) {
            snprintf(err, esize, "the FMU's Python runtime bundle cannot be loaded: %s", dlerror());
            return -1;
        }
        snprintf(python_where, sizeof python_where, "%s (the FMU's runtime)", bundled);
    } else {
        /* the build's libpython, then the standard sonames: the build's version first, then
         * 3.17 .. 3.10 (newest first) */
        char cands[2 + 2 * 8 + 1][1024];
        int n = 0, mi;
        if (REEVE_LIBPYTHON[0]) snprintf(cands[n++], sizeof cands[0], "%s", REEVE_LIBPYTHON);
        snprintf(cands[n++], sizeof cands[0], "libpython%s.so.1.0", REEVE_PY_VERSION);
        for (mi = 17; mi >= REEVE_MIN_PY_MINOR; mi--) {
            char v[16];
            snprintf(v, sizeof v, "3.%d", mi);
            if (strcmp(v, REEVE_PY_VERSION) == 0) continue;
            snprintf(cands[n++], sizeof cands[0], "libpython3.%d.so.1.0", mi);
        }
        for (m = 0; m < n && !h; m++) {
            h = dlopen(cands[m], RTLD_NOW | RTLD_GLOBAL);
            if (h) {
                snprintf(python_where, sizeof python_where, "%s", cands[m]);
            } else {
                size_t used = strlen(tried);
                snprintf(tried + used, sizeof tried - used, "\n  %s: %s", cands[m], dlerror());
            }
        }
        if (!h) {
            snprintf(err, esize,
                     "no Python found. This FMU runs its model in Python (>= 3.%d; built with Python "
                     "%s) and this process has none. Tried:%s\nInstall Python %s with its shared "
                     "library (e.g. 'apt install libpython%s', or a python.org / pyenv build with "
                     "--enable-shared) and the packages in the FMU's resources/requirements.txt, or "
                     "set REEVE_FMU_LIBPYTHON to the path of a libpython3.X.so.1.0, or use an FMU "
                     "that carries its runtime ('reeve-fmu build --standalone').",
                     REEVE_MIN_PY_MINOR, REEVE_PY_VERSION, tried, REEVE_PY_VERSION, REEVE_PY_VERSION);
            return -1;
        }
    }
    if (resolve_python(err, esize) != 0) return -1;
    snprintf(version, sizeof version, "%s", py.GetVersion());
    version[strcspn(version, " ")] = 0;
    if (sscanf(version, "%d.%d", &major, &minor) != 2 || major != 3 || minor < REEVE_MIN_PY_MINOR) {
        snprintf(err, esize, "wrong Python version: %s is Python %s, but this FMU needs Python >= "
                 "3.%d (it was built with %s). Use a newer Python (set REEVE_FMU_LIBPYTHON to its "
                 "libpython3.X.so.1.0 in a non-Python host).",
                 python_where, version, REEVE_MIN_PY_MINOR, REEVE_PY_VERSION);
        return -1;
    }
    if (!py.IsInitialized()) {
        char ver[16];
        snprintf(ver, sizeof ver, "%d.%d", major, minor);
        if (initialize_python(ver, err, esize) != 0) return -1;
        we_initialized = 1;
        py.EvalSaveThread(); /* drop the GIL; the main thread state stays with this thread */
    } else {
        runtime_dir[0] = 0; /* the host's interpreter: the bundle's packages only by preflight's choice */
    }
    return 0;
}

static void ensure_thread_state_slow(void)
{
    if (!py.GILStateGetThisThreadState()) {
        py.GILStateEnsure(); /* never released: the thread state lives as long as the thread */
        py.EvalSaveThread();
    }
    thread_ready = 1;
}

static inline void ensure_thread_state(void)
{
    if (__builtin_expect(!thread_ready, 0)) ensure_thread_state_slow();
}

static int load_pythonfmu(char *err, size_t esize)
{
    char dir[1024], path[1200];
    void *h;
    own_dir(dir, sizeof dir);
    snprintf(path, sizeof path, "%s/%s_pyexit.so", dir, REEVE_MODEL_IDENTIFIER);
    if (!dlopen(path, RTLD_NOW | RTLD_GLOBAL | RTLD_NODELETE)) {
        snprintf(err, esize, "cannot load %s: %s", path, dlerror());
        return -1;
    }
    snprintf(path, sizeof path, "%s/%s_pythonfmu.so", dir, REEVE_MODEL_IDENTIFIER);
    h = dlopen(path, RTLD_NOW | RTLD_LOCAL | RTLD_NODELETE);
    if (!h) {
        snprintf(err, esize, "cannot load pythonfmu's binary %s: %s", path, dlerror());
        return -1;
    }
#define RESOLVE(ret, name, params, args)                                                            \
    if (!(*(void **)&inner_##name = dlsym(h, #name))) {                                              \
        snprintf(err, esize, "%s lacks %s", path, #name);                                            \
        return -1;                                                                                   \
    }
    FMI2_FORWARDED(RESOLVE)
    FMI2_OWN(RESOLVE)
    RESOLVE(, fmi2Instantiate, , )
    RESOLVE(, fmi2FreeInstance, , )
    RESOLVE(, fmi2SetDebugLogging, , )
#undef RESOLVE
    return 0;
}

/* Python-side checks (resources/reeve_fmu.py: preflight). Returns 0, or -1 with the reason in err;
 * warnings are logged. */
static const char PREFLIGHT[] =
    "import importlib.util as _u, os as _o\n"
    "ERROR = WARNING = None\n"
    "_p = _o.path.join(RESOURCES, 'reeve_fmu.py')\n"
    "if _o.path.isfile(_p):\n"
    "    _s = _u.spec_from_file_location('_reeve_fmu_preflight', _p)\n"
    "    _m = _u.module_from_spec(_s)\n"
    "    _s.loader.exec_module(_m)\n"
    "    ERROR, WARNING = _m.preflight(RESOURCES, EMBEDDED, WHERE, HOME)\n";

static void copy_str(PyObject *o, char *out, size_t size)
{
    ptrdiff_t n = 0;
    const char *s;
    PyObject *str = o ? py.ObjectStr(o) : NULL;
    out[0] = 0;
    if (!str) return;
    s = py.UnicodeAsUTF8AndSize(str, &n);
    if (s) snprintf(out, size, "%s", s);
    py.DecRef(str);
}

static int preflight(const Wrap *w, const char *resources, char *err, size_t esize)
{
    int rc = 0, gil = py.GILStateEnsure();
    PyObject *g = py.DictNew(), *code = NULL, *r = NULL, *o;
    err[0] = 0;
    if (!g) goto fail;
    py.DictSetItemString(g, "__builtins__", py.EvalGetBuiltins());
    o = py.UnicodeDecodeFSDefault(resources);
    py.DictSetItemString(g, "RESOURCES", o);
    py.DecRef(o);
    o = py.BoolFromLong(we_initialized);
    py.DictSetItemString(g, "EMBEDDED", o);
    py.DecRef(o);
    o = py.UnicodeDecodeFSDefault(python_where);
    py.DictSetItemString(g, "WHERE", o);
    py.DecRef(o);
    o = py.UnicodeDecodeFSDefault(we_initialized ? python_home : "");
    py.DictSetItemString(g, "HOME", o);
    py.DecRef(o);
    code = py.CompileString(PREFLIGHT, "<reeve_fmu loader>", PY_FILE_INPUT);
    if (code) r = py.EvalEvalCode(code, g, g);
    if (!r) goto fail;
    o = py.DictGetItemString(g, "WARNING");
    if (o && o != py.DictGetItemString(py.EvalGetBuiltins(), "None")) {
        char buf[8192];
        copy_str(o, buf, sizeof buf);
        if (buf[0] && strcmp(buf, "None") != 0) loader_log(w, fmi2Warning, "%s", buf);
    }
    o = py.DictGetItemString(g, "ERROR");
    if (o) {
        copy_str(o, err, esize);
        if (strcmp(err, "None") == 0) err[0] = 0;
    }
    rc = err[0] ? -1 : 0;
    goto done;
fail : {
    PyObject *t = NULL, *v = NULL, *tb = NULL;
    char buf[4096];
    py.ErrFetch(&t, &v, &tb);
    copy_str(v ? v : t, buf, sizeof buf);
    snprintf(err, esize, "the FMU's Python bootstrap failed: %s", buf[0] ? buf : "unknown error");
    if (t) py.DecRef(t);
    if (v) py.DecRef(v);
    if (tb) py.DecRef(tb);
    rc = -1;
}
done:
    if (r) py.DecRef(r);
    if (code) py.DecRef(code);
    if (g) py.DecRef(g);
    py.GILStateRelease(gil);
    return rc;
}


/* ------------------------------------------------------------------ the fast path (5.) */
#define LINK_BOX "_reeve_fmu_link_box"
static pthread_mutex_t link_lock = PTHREAD_MUTEX_INITIALIZER; /* one construction at a time */

/* Before pythonfmu constructs the Python slave: a list in sys that ReeveSlave.__init__ appends itself
 * to (pythonfmu gives the loader no handle on the object). Returns a new reference or NULL. */
static PyObject *open_box(void)
{
    int gil = py.GILStateEnsure();
    PyObject *box = py.ListNew(0);
    if (box && py.SysSetObject(LINK_BOX, box) != 0) {
        py.ErrClear();
        py.DecRef(box);
        box = NULL;
    }
    py.GILStateRelease(gil);
    return box;
}

static void unlink_instance(Wrap *w)
{
    int gil;
    if (!w->obj && !w->slave) return;
    gil = py.GILStateEnsure();
    if (w->obj) {
        py.DecRef(w->do_step);
        py.DecRef(w->log_queue);
        py.DecRef(w->obj);
    }
    if (w->slave) py.DecRef(w->slave);
    py.GILStateRelease(gil);
    w->obj = w->do_step = w->log_queue = w->slave = NULL;
    w->link = NULL;
}

/* After the construction: if exactly this box holds one slave with _native_link(), take its tables.
 * Anything unexpected leaves the instance on pythonfmu's path (correct, only slower). */
static void close_box(Wrap *w, PyObject *box)
{
    int gil = py.GILStateEnsure();
    PyObject *obj = NULL, *r = NULL, *m = NULL;
    ReeveLink *L = NULL;
    if (box && py.SysGetObject(LINK_BOX) == box && py.ListSize(box) == 1)
        obj = py.ListGetItem(box, 0); /* borrowed */
    if (obj) {
        py.IncRef(obj);
        w->slave = obj;
    }
    if (obj && (m = py.ObjectGetAttrString(obj, "_native_link")) != NULL &&
        (r = py.CallFunctionObjArgs(m, NULL)) != NULL)
        L = (ReeveLink *)py.LongAsVoidPtr(r);
    if (L && L->version == REEVE_LINK_VERSION && L->n_vr >= 0) {
        w->do_step = py.ObjectGetAttrString(obj, "do_step");
        w->log_queue = py.ObjectGetAttrString(obj, "log_queue");
        if (w->do_step && w->log_queue) {
            py.IncRef(obj);
            w->obj = obj;
            w->link = L;
        } else {
            if (w->do_step) py.DecRef(w->do_step);
            if (w->log_queue) py.DecRef(w->log_queue);
            w->do_step = w->log_queue = NULL;
        }
    }
    py.ErrClear();
    if (r) py.DecRef(r);
    if (m) py.DecRef(m);
    if (box) {
        if (py.SysGetObject(LINK_BOX) == box) py.SysSetObject(LINK_BOX, NULL);
        py.ErrClear();
        py.DecRef(box);
    }
    py.GILStateRelease(gil);
}

/* doStep without pythonfmu's C++ layer: one call of the slave's do_step (ReeveSlave never raises out
 * of it); queued log messages are then handed to pythonfmu, which forwards them to the logger. */
static fmi2Status fast_step(Wrap *w, fmi2Real t, fmi2Real h)
{
    int ok = 0, gil = py.GILStateEnsure();
    char err[4096] = "";
    ptrdiff_t nlog;
    PyObject *a = py.FloatFromDouble(t), *b = py.FloatFromDouble(h), *r = NULL;
    if (a && b) r = py.CallFunctionObjArgs(w->do_step, a, b, NULL);
    if (r) {
        ok = py.ObjectIsTrue(r) == 1;
        py.DecRef(r);
    } else {
        PyObject *et = NULL, *ev = NULL, *tb = NULL;
        py.ErrFetch(&et, &ev, &tb);
        copy_str(ev ? ev : et, err, sizeof err);
        if (et) py.DecRef(et);
        if (ev) py.DecRef(ev);
        if (tb) py.DecRef(tb);
        if (!err[0]) snprintf(err, sizeof err, "unknown error");
    }
    if (a) py.DecRef(a);
    if (b) py.DecRef(b);
    nlog = py.ListSize(w->log_queue);
    py.GILStateRelease(gil);
    if (nlog > 0) inner_fmi2SetReal(w->inner, NULL, 0, NULL); /* pythonfmu flushes its log queue */
    if (err[0]) {
        loader_log(w, fmi2Error, "%s: doStep(t=%.17g, h=%.17g) raised: %s", REEVE_MODEL_IDENTIFIER, t, h,
                   err);
        return fmi2Error;
    }
    w->stepped = 1;
    if (ok) {
        w->last_ok_time = t + h;
        return fmi2OK;
    }
    w->last_ok_time = t;
    w->wants_terminate = 1;
    return fmi2Discard;
}

/* ------------------------------------------------------------------ exported fmi2 functions */
EXPORT const char *fmi2GetTypesPlatform(void) { return "default"; }
EXPORT const char *fmi2GetVersion(void) { return "2.0"; }

static void free_wrap(Wrap *w)
{
    size_t i;
    if (!w) return;
    for (i = 0; i < w->ncat; i++) free(w->categories[i]);
    free(w->categories);
    free(w->instance_name);
    free(w);
}

EXPORT fmi2Component fmi2Instantiate(fmi2String instanceName, fmi2Type fmuType, fmi2String fmuGUID,
                                     fmi2String fmuResourceLocation,
                                     const fmi2CallbackFunctions *functions, fmi2Boolean visible,
                                     fmi2Boolean loggingOn)
{
    char resources[4096], uri[8300], err[8192];
    size_t i, j;
    PyObject *box;
    Wrap *w = (Wrap *)calloc(1, sizeof(Wrap));
    if (!w) return NULL;
    if (functions) w->host = *functions;
    w->logging_on = loggingOn != 0;
    w->instance_name = strdup(instanceName ? instanceName : "");

    if (uri_to_path(fmuResourceLocation, resources, sizeof resources) != 0) {
        loader_log(w, fmi2Error, "%s: fmuResourceLocation '%s' is not a local file URI",
                   REEVE_MODEL_IDENTIFIER, fmuResourceLocation ? fmuResourceLocation : "(null)");
        free_wrap(w);
        return NULL;
    }
    pthread_mutex_lock(&load_lock);
    if (!loaded && !load_error[0]) {
        if (load_python(resources, err, sizeof err) == 0 && load_pythonfmu(err, sizeof err) == 0) loaded = 1;
        else snprintf(load_error, sizeof load_error, "%s", err);
    }
    pthread_mutex_unlock(&load_lock);
    if (!loaded) {
        loader_log(w, fmi2Fatal, "%s: cannot instantiate: %s", REEVE_MODEL_IDENTIFIER, load_error);
        free_wrap(w);
        return NULL;
    }
    ensure_thread_state();
    if (preflight(w, resources, err, sizeof err) != 0) {
        loader_log(w, fmi2Error, "%s: cannot instantiate: %s", REEVE_MODEL_IDENTIFIER, err);
        free_wrap(w);
        return NULL;
    }
    /* pythonfmu strips "file://" and decodes only %20: hand it that form */
    memcpy(uri, "file://", 7);
    for (i = 0, j = 7; resources[i] && j + 4 < sizeof uri; i++) {
        if (resources[i] == ' ') {
            memcpy(uri + j, "%20", 3);
            j += 3;
        } else {
            uri[j++] = resources[i];
        }
    }
    uri[j] = 0;
    w->relay = w->host;
    w->relay.logger = relay_logger;
    w->relay.componentEnvironment = w;
    w->last_ok_time = NAN; /* before the first step, as pythonfmu */
    pthread_mutex_lock(&link_lock);
    box = open_box();
    w->inner = inner_fmi2Instantiate(instanceName, fmuType, fmuGUID, uri, &w->relay, visible, 1);
    close_box(w, box);
    if (!w->inner) unlink_instance(w);
    pthread_mutex_unlock(&link_lock);
    if (!w->inner) {
        loader_log(w, fmi2Error, "%s: pythonfmu could not instantiate the model (reason above)",
                   REEVE_MODEL_IDENTIFIER);
        free_wrap(w);
        return NULL;
    }
    return (fmi2Component)w;
}

EXPORT void fmi2FreeInstance(fmi2Component c)
{
    Wrap *w = (Wrap *)c;
    if (!w) return;
    ensure_thread_state();
    unlink_instance(w);
    inner_fmi2FreeInstance(w->inner);
    free_wrap(w);
}

EXPORT fmi2Status fmi2SetDebugLogging(fmi2Component c, fmi2Boolean loggingOn, size_t nCategories,
                                      const fmi2String categories[])
{
    Wrap *w = (Wrap *)c;
    size_t i;
    char **cats = NULL;
    if (!w) return fmi2Error;
    if (nCategories && categories) {
        cats = (char **)calloc(nCategories, sizeof(char *));
        if (!cats) return fmi2Error;
        for (i = 0; i < nCategories; i++) cats[i] = strdup(categories[i] ? categories[i] : "");
    }
    for (i = 0; i < w->ncat; i++) free(w->categories[i]);
    free(w->categories);
    w->categories = cats;
    w->ncat = cats ? nCategories : 0;
    w->logging_on = loggingOn != 0;
    return fmi2OK; /* pythonfmu keeps debug logging on; the relay filters */
}

#define DEFINE_FORWARD(ret, name, params, args)                                                     \
    EXPORT ret name params                                                                           \
    {                                                                                                \
        Wrap *w = (Wrap *)c;                                                                         \
        if (!w) return fmi2Error;                                                                    \
        ensure_thread_state();                                                                       \
        return inner_##name args;                                                 \
    }
#define W w->inner
FMI2_FORWARDED(DEFINE_FORWARD)

/* pythonfmu 0.7.0 returns fmi2OK from exitInitializationMode whatever the model's initialize did (an
 * exception would be fmi2Fatal and end the instance): a reeve_fmu slave records the failure, logged with
 * its reason, in initialization_failed, and the host gets fmi2Error here */
EXPORT fmi2Status fmi2ExitInitializationMode(fmi2Component c)
{
    Wrap *w = (Wrap *)c;
    fmi2Status s;
    if (!w) return fmi2Error;
    ensure_thread_state();
    s = inner_fmi2ExitInitializationMode(w->inner);
    if (s < fmi2Error && w->slave) {
        int gil = py.GILStateEnsure();
        PyObject *failed = py.ObjectGetAttrString(w->slave, "initialization_failed");
        if (failed) {
            if (py.ObjectIsTrue(failed) == 1) s = fmi2Error;
            py.DecRef(failed);
        } else {
            py.ErrClear();
        }
        py.GILStateRelease(gil);
    }
    return s;
}

/* pythonfmu constructs a new Python slave: link to that one */
EXPORT fmi2Status fmi2Reset(fmi2Component c)
{
    Wrap *w = (Wrap *)c;
    fmi2Status s;
    PyObject *box;
    if (!w) return fmi2Error;
    ensure_thread_state();
    pthread_mutex_lock(&link_lock);
    unlink_instance(w);
    box = open_box();
    s = inner_fmi2Reset(w->inner);
    close_box(w, box);
    pthread_mutex_unlock(&link_lock);
    return s;
}

/* Real inputs straight into the slave's table (it pulls them at its next call); anything else, a
 * value outside its bounds, or a slave not in step mode: pythonfmu's path, which checks and logs. */
EXPORT fmi2Status fmi2SetReal(fmi2Component c, const fmi2ValueReference *v, size_t n, const fmi2Real *x)
{
    Wrap *w = (Wrap *)c;
    const ReeveLink *L;
    size_t i;
    if (!w) return fmi2Error;
    L = w->link;
    if (L && L->state[0]) {
        for (i = 0; i < n; i++) {
            unsigned k = v[i];
            if (k >= (unsigned)L->n_vr || L->kind[k] != 1 || !(x[i] >= L->lo[k] && x[i] <= L->hi[k]))
                goto slow;
        }
        for (i = 0; i < n; i++) {
            L->val[v[i]] = x[i];
            L->dirty[v[i]] = 1;
        }
        if (n) L->state[2] = 1;
        return fmi2OK;
    }
slow:
    ensure_thread_state();
    return inner_fmi2SetReal(w->inner, v, n, x);
}

/* outputs the slave keeps current in its table (what step() writes each step); others: pythonfmu */
EXPORT fmi2Status fmi2GetReal(fmi2Component c, const fmi2ValueReference *v, size_t n, fmi2Real *x)
{
    Wrap *w = (Wrap *)c;
    const ReeveLink *L;
    size_t i;
    if (!w) return fmi2Error;
    L = w->link;
    if (L && L->state[1]) {
        for (i = 0; i < n; i++)
            if (v[i] >= (unsigned)L->n_vr || L->kind[v[i]] != 2) goto slow;
        for (i = 0; i < n; i++) x[i] = L->val[v[i]];
        return fmi2OK;
    }
slow:
    ensure_thread_state();
    return inner_fmi2GetReal(w->inner, v, n, x);
}

EXPORT fmi2Status fmi2DoStep(fmi2Component c, fmi2Real t, fmi2Real h, fmi2Boolean p)
{
    Wrap *w = (Wrap *)c;
    if (!w) return fmi2Error;
    ensure_thread_state();
    if (w->link) return fast_step(w, t, h);
    return inner_fmi2DoStep(w->inner, t, h, p);
}

/* pythonfmu's answers, for the steps the loader made */
EXPORT fmi2Status fmi2GetRealStatus(fmi2Component c, const fmi2StatusKind k, fmi2Real *x)
{
    Wrap *w = (Wrap *)c;
    if (!w) return fmi2Error;
    if (w->stepped && k == fmi2LastSuccessfulTime && x) {
        *x = w->last_ok_time;
        return fmi2OK;
    }
    ensure_thread_state();
    return inner_fmi2GetRealStatus(w->inner, k, x);
}

EXPORT fmi2Status fmi2GetBooleanStatus(fmi2Component c, const fmi2StatusKind k, fmi2Boolean *x)
{
    Wrap *w = (Wrap *)c;
    if (!w) return fmi2Error;
    if (w->stepped && k == fmi2Terminated && x) {
        *x = w->wants_terminate;
        return fmi2OK;
    }
    ensure_thread_state();
    return inner_fmi2GetBooleanStatus(w->inner, k, x);
}

#ifdef REEVE_FMI3
#include "fmi3.c" /* the FMI 3.0 adapter over the functions above */
#endif

#endif /* REEVE_EXIT_HELPER */
