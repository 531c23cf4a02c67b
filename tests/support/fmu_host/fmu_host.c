/* A minimal native FMI 2.0 / 3.0 co-simulation host (stands in for C/C++ tools such as fmuCheck, the
 * OMSimulator CLI or a Simulink S-function): dlopen, fmi2Instantiate, SetupExperiment, a Gauss-Seidel
 * DoStep loop, Terminate, FreeInstance, dlclose, normal exit. No Python, no LD_PRELOAD.
 *
 *   fmu_host PLAN OUT.csv
 *
 * PLAN, one directive per line ('#' comments):
 *   fmu NAME UNZIPDIR MODELIDENTIFIER GUID   an FMU (stepped in the order given)
 *   real NAME VR VALUE                       start value, set in initialization mode
 *   integer NAME VR VALUE
 *   input DST VR SRC VR                      before DST's doStep: DST.VR := latest SRC.VR
 *   output NAME VR                           a recorded column (read after every step)
 *   step H | steps N | logging 0/1 | stoptime T
 *   fmi 3                                    the FMUs are FMI 3.0 co-simulation FMUs: binaries/x86_64-linux,
 *                                            fmi3InstantiateCoSimulation, fmi3EnterInitializationMode,
 *                                            fmi3Set/GetFloat64, fmi3SetInt32, fmi3DoStep (value references
 *                                            as in their modelDescription)
 * OUT.csv: time and the outputs at t = 0 and after every step, as %.17g (exact round trip).
 * stdout: "steps N", "loop_s S" (wall time of the DoStep loop), "loop_cpu_s S" (its thread CPU time). Exit code 0 when every call returned
 * OK/Warning, 1 otherwise (the reason is on stderr).
 */
#define _GNU_SOURCE
#include <dlfcn.h>
#include <stdarg.h>
#include <stdbool.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

typedef void *fmi2Component;
typedef unsigned int fmi2ValueReference;
typedef int fmi2Status;
typedef struct {
    void (*logger)(void *, const char *, fmi2Status, const char *, const char *, ...);
    void *(*allocateMemory)(size_t, size_t);
    void (*freeMemory)(void *);
    void (*stepFinished)(void *, fmi2Status);
    void *componentEnvironment;
} fmi2CallbackFunctions;

#define MAXF 8
#define MAXV 256
typedef struct {
    char name[64], dir[2048], id[128], guid[256];
    void *lib;
    fmi2Component c;
    fmi2Component (*instantiate)(const char *, int, const char *, const char *,
                                 const fmi2CallbackFunctions *, int, int);
    fmi2Status (*setup)(fmi2Component, int, double, double, int, double);
    fmi2Status (*enter)(fmi2Component);
    fmi2Status (*exit_)(fmi2Component);
    fmi2Status (*terminate)(fmi2Component);
    void (*free_)(fmi2Component);
    fmi2Status (*setReal)(fmi2Component, const fmi2ValueReference *, size_t, const double *);
    fmi2Status (*getReal)(fmi2Component, const fmi2ValueReference *, size_t, double *);
    fmi2Status (*setInteger)(fmi2Component, const fmi2ValueReference *, size_t, const int *);
    fmi2Status (*doStep)(fmi2Component, double, double, int);
    /* FMI 3.0 (fmi 3) */
    void *(*instantiate3)(const char *, const char *, const char *, bool, bool, bool, bool,
                          const unsigned *, size_t, void *,
                          void (*)(void *, int, const char *, const char *), void *);
    fmi2Status (*enter3)(fmi2Component, bool, double, double, bool, double);
    fmi2Status (*setFloat64)(fmi2Component, const unsigned *, size_t, const double *, size_t);
    fmi2Status (*getFloat64)(fmi2Component, const unsigned *, size_t, double *, size_t);
    fmi2Status (*setInt32)(fmi2Component, const unsigned *, size_t, const int *, size_t);
    fmi2Status (*doStep3)(fmi2Component, double, double, bool, bool *, bool *, bool *, double *);
    /* inputs: dst vr <- (src fmu, src output index) */
    int nin;
    fmi2ValueReference in_vr[MAXV];
    int in_src[MAXV], in_idx[MAXV];
    double in_val[MAXV];
    /* outputs read after each step (recorded ones and the sources of inputs) */
    int nout;
    fmi2ValueReference out_vr[MAXV];
    double out_val[MAXV];
    int nstart_r, nstart_i;
    fmi2ValueReference sr_vr[MAXV], si_vr[MAXV];
    double sr_val[MAXV];
    int si_val[MAXV];
} Fmu;

static Fmu fmus[MAXF];
static int nf;
static int rec_f[MAXV * MAXF], rec_i[MAXV * MAXF], nrec;
static int failed;
static int fmi3; /* plan: fmi 3 */

static void logger3(void *env, int status, const char *category, const char *message)
{
    static const char *names[] = {"OK", "WARNING", "DISCARD", "ERROR", "FATAL"};
    (void)category;
    fprintf(stderr, "[%s] %s: %s\n", status >= 0 && status < 5 ? names[status] : "?", (const char *)env, message);
}

/* the calls of the loop, FMI 2.0 or 3.0 */
static fmi2Status set_real(Fmu *f, const fmi2ValueReference *v, size_t n, const double *x)
{
    return fmi3 ? f->setFloat64(f->c, v, n, x, n) : f->setReal(f->c, v, n, x);
}

static fmi2Status get_real(Fmu *f, const fmi2ValueReference *v, size_t n, double *x)
{
    return fmi3 ? f->getFloat64(f->c, v, n, x, n) : f->getReal(f->c, v, n, x);
}

static fmi2Status do_step(Fmu *f, double t, double h)
{
    bool event, stop, early;
    double last;
    return fmi3 ? f->doStep3(f->c, t, h, true, &event, &stop, &early, &last) : f->doStep(f->c, t, h, 1);
}

static void logger(void *env, const char *instance, fmi2Status status, const char *category,
                   const char *message, ...)
{
    static const char *names[] = {"OK", "WARNING", "DISCARD", "ERROR", "FATAL", "PENDING"};
    va_list ap;
    (void)env;
    (void)category;
    fprintf(stderr, "[%s] %s: ", status >= 0 && status < 6 ? names[status] : "?", instance);
    va_start(ap, message);
    vfprintf(stderr, message, ap);
    va_end(ap);
    fputc('\n', stderr);
}

static int find(const char *name)
{
    int i;
    for (i = 0; i < nf; i++)
        if (strcmp(fmus[i].name, name) == 0) return i;
    fprintf(stderr, "plan: unknown FMU %s\n", name);
    exit(2);
}

static int out_index(Fmu *f, fmi2ValueReference vr)
{
    int i;
    for (i = 0; i < f->nout; i++)
        if (f->out_vr[i] == vr) return i;
    f->out_vr[f->nout] = vr;
    return f->nout++;
}

static void check(fmi2Status s, const char *what, const Fmu *f, double t)
{
    if (s > 1) {
        fprintf(stderr, "%s of %s at t = %.9g returned status %d\n", what, f->name, t, s);
        failed = 1;
    }
}

#define SYM(f, field, sym)                                                                           \
    do {                                                                                             \
        *(void **)&(f)->field = dlsym((f)->lib, sym);                                                \
        if (!(f)->field) {                                                                           \
            fprintf(stderr, "%s: no symbol %s\n", (f)->name, sym);                                   \
            return 1;                                                                                \
        }                                                                                            \
    } while (0)

int main(int argc, char **argv)
{
    FILE *plan, *out;
    char line[4096], a[64], b[2048], c[128], d[256], e[256];
    double h = 1e-3, stop = -1.0, ns, t;
    long steps = 1000, k;
    int logging = 0, i, j;
    fmi2CallbackFunctions cb = {logger, calloc, free, NULL, NULL};
    struct timespec t0, t1, c0, c1;
    static const char *names2[] = {"fmi2SetReal", "fmi2GetReal", "fmi2DoStep", "fmi2ExitInitializationMode",
                                   "fmi2SetInteger"};
    static const char *names3[] = {"fmi3SetFloat64", "fmi3GetFloat64", "fmi3DoStep", "fmi3ExitInitializationMode",
                                   "fmi3SetInt32"};
    const char **fn;

    if (argc != 3) {
        fprintf(stderr, "usage: fmu_host PLAN OUT.csv\n");
        return 2;
    }
    plan = fopen(argv[1], "r");
    if (!plan) {
        perror(argv[1]);
        return 2;
    }
    while (fgets(line, sizeof line, plan)) {
        if (line[0] == '#' || line[0] == '\n') continue;
        if (sscanf(line, "fmu %63s %2047s %127s %255s", a, b, c, d) == 4) {
            Fmu *f = &fmus[nf++];
            snprintf(f->name, sizeof f->name, "%s", a);
            snprintf(f->dir, sizeof f->dir, "%s", b);
            snprintf(f->id, sizeof f->id, "%s", c);
            snprintf(f->guid, sizeof f->guid, "%s", d);
        } else if (sscanf(line, "real %63s %127s %255s", a, c, d) == 3) {
            Fmu *f = &fmus[find(a)];
            f->sr_vr[f->nstart_r] = (fmi2ValueReference)strtoul(c, NULL, 10);
            f->sr_val[f->nstart_r++] = strtod(d, NULL);
        } else if (sscanf(line, "integer %63s %127s %255s", a, c, d) == 3) {
            Fmu *f = &fmus[find(a)];
            f->si_vr[f->nstart_i] = (fmi2ValueReference)strtoul(c, NULL, 10);
            f->si_val[f->nstart_i++] = atoi(d);
        } else if (sscanf(line, "input %63s %127s %63s %255s", a, c, e, d) == 4) {
            Fmu *f = &fmus[find(a)];
            int s = find(e);
            f->in_vr[f->nin] = (fmi2ValueReference)strtoul(c, NULL, 10);
            f->in_src[f->nin] = s;
            f->in_idx[f->nin++] = out_index(&fmus[s], (fmi2ValueReference)strtoul(d, NULL, 10));
        } else if (sscanf(line, "output %63s %127s", a, c) == 2) {
            int s = find(a);
            rec_f[nrec] = s;
            rec_i[nrec++] = out_index(&fmus[s], (fmi2ValueReference)strtoul(c, NULL, 10));
        } else if (sscanf(line, "steps %255s", e) == 1) {
            steps = strtol(e, NULL, 10);
        } else if (sscanf(line, "step %255s", e) == 1) {
            h = strtod(e, NULL);
        } else if (sscanf(line, "stoptime %255s", e) == 1) {
            stop = strtod(e, NULL);
        } else if (sscanf(line, "logging %255s", e) == 1) {
            logging = atoi(e);
        } else if (sscanf(line, "fmi %255s", e) == 1) {
            fmi3 = atoi(e) == 3;
        } else {
            fprintf(stderr, "plan: cannot parse: %s", line);
            return 2;
        }
    }
    fclose(plan);

    /* the names in messages: set, get, step, exit initialization, set integer */
    fn = fmi3 ? names3 : names2;
    for (i = 0; i < nf; i++) {
        Fmu *f = &fmus[i];
        char path[4200], uri[4200];
        snprintf(path, sizeof path, "%s/binaries/%s/%s.so", f->dir, fmi3 ? "x86_64-linux" : "linux64", f->id);
        f->lib = dlopen(path, RTLD_NOW | RTLD_LOCAL);
        if (!f->lib) {
            fprintf(stderr, "dlopen failed: %s\n", dlerror());
            return 1;
        }
        if (fmi3) {
            SYM(f, instantiate3, "fmi3InstantiateCoSimulation");
            SYM(f, enter3, "fmi3EnterInitializationMode");
            SYM(f, exit_, "fmi3ExitInitializationMode");
            SYM(f, terminate, "fmi3Terminate");
            SYM(f, free_, "fmi3FreeInstance");
            SYM(f, setFloat64, "fmi3SetFloat64");
            SYM(f, getFloat64, "fmi3GetFloat64");
            SYM(f, setInt32, "fmi3SetInt32");
            SYM(f, doStep3, "fmi3DoStep");
            snprintf(path, sizeof path, "%s/resources/", f->dir);
            f->c = f->instantiate3(f->name, f->guid, path, false, logging, false, false, NULL, 0, f->name,
                                   logger3, NULL);
        } else {
            SYM(f, instantiate, "fmi2Instantiate");
            SYM(f, setup, "fmi2SetupExperiment");
            SYM(f, enter, "fmi2EnterInitializationMode");
            SYM(f, exit_, "fmi2ExitInitializationMode");
            SYM(f, terminate, "fmi2Terminate");
            SYM(f, free_, "fmi2FreeInstance");
            SYM(f, setReal, "fmi2SetReal");
            SYM(f, getReal, "fmi2GetReal");
            SYM(f, setInteger, "fmi2SetInteger");
            SYM(f, doStep, "fmi2DoStep");
            snprintf(uri, sizeof uri, "file://%s/resources", f->dir);
            f->c = f->instantiate(f->name, 1, f->guid, uri, &cb, 0, logging);
        }
        if (!f->c) {
            fprintf(stderr, "%s of %s returned NULL\n", fmi3 ? "fmi3InstantiateCoSimulation" : "fmi2Instantiate",
                    f->name);
            return 1;
        }
        if (fmi3) {
            check(f->enter3(f->c, false, 0.0, 0.0, stop > 0, stop > 0 ? stop : 0.0), "fmi3EnterInitializationMode", f, 0);
        } else {
            check(f->setup(f->c, 0, 0.0, 0.0, stop > 0, stop > 0 ? stop : 0.0), "fmi2SetupExperiment", f, 0);
            check(f->enter(f->c), "fmi2EnterInitializationMode", f, 0);
        }
        if (f->nstart_r) check(set_real(f, f->sr_vr, f->nstart_r, f->sr_val), fn[0], f, 0);
        if (f->nstart_i)
            check(fmi3 ? f->setInt32(f->c, f->si_vr, f->nstart_i, f->si_val, f->nstart_i)
                       : f->setInteger(f->c, f->si_vr, f->nstart_i, f->si_val), fn[4], f, 0);
        check(f->exit_(f->c), fn[3], f, 0);
        if (f->nout) check(get_real(f, f->out_vr, f->nout, f->out_val), fn[1], f, 0);
    }
    if (failed) return 1;
    out = fopen(argv[2], "w");
    if (!out) {
        perror(argv[2]);
        return 2;
    }
    fprintf(out, "%.17g", 0.0);
    for (j = 0; j < nrec; j++) fprintf(out, ",%.17g", fmus[rec_f[j]].out_val[rec_i[j]]);
    fputc('\n', out);

    /* communication points as reeve_fmu.fmu.cosim computes them: (k * step_ns) / 1e9 */
    ns = (double)(long long)(h * 1e9 + 0.5);
    clock_gettime(CLOCK_MONOTONIC, &t0);
    clock_gettime(CLOCK_THREAD_CPUTIME_ID, &c0);
    for (k = 0; k < steps && !failed; k++) {
        t = ((double)k * ns) / 1e9;
        for (i = 0; i < nf; i++) {
            Fmu *f = &fmus[i];
            if (f->nin) {
                for (j = 0; j < f->nin; j++) f->in_val[j] = fmus[f->in_src[j]].out_val[f->in_idx[j]];
                check(set_real(f, f->in_vr, f->nin, f->in_val), fn[0], f, t);
            }
            check(do_step(f, t, h), fn[2], f, t);
            if (f->nout) check(get_real(f, f->out_vr, f->nout, f->out_val), fn[1], f, t);
        }
        fprintf(out, "%.17g", ((double)(k + 1) * ns) / 1e9);
        for (j = 0; j < nrec; j++) fprintf(out, ",%.17g", fmus[rec_f[j]].out_val[rec_i[j]]);
        fputc('\n', out);
    }
    clock_gettime(CLOCK_THREAD_CPUTIME_ID, &c1);
    clock_gettime(CLOCK_MONOTONIC, &t1);
    fclose(out);
    printf("steps %ld\nloop_s %.9f\nloop_cpu_s %.9f\n", k, (t1.tv_sec - t0.tv_sec) + 1e-9 * (t1.tv_nsec - t0.tv_nsec),
           (c1.tv_sec - c0.tv_sec) + 1e-9 * (c1.tv_nsec - c0.tv_nsec));
    for (i = 0; i < nf; i++) {
        fmus[i].terminate(fmus[i].c);
        fmus[i].free_(fmus[i].c);
        dlclose(fmus[i].lib);
    }
    fflush(stdout);
    return failed;
}
