/* reeve_fmu native loader, second translation unit: start an embedded interpreter with a configured home.
 *
 * Compiled into the loader (<id>.so) next to fmu_loader.c. With -DREEVE_HAVE_PYCONFIG it includes the
 * headers of the Python that builds the FMU: PyConfig's layout differs between minor versions, so the
 * loader only calls reeve_init_configured() when the libpython it loaded is that minor version. The
 * CPython entry points are looked up with dlsym (the loader links no libpython; it dlopens one).
 * Without the headers (a Python without its development files) reeve_init_configured() returns -2 and
 * the loader falls back to Py_SetPythonHome + Py_InitializeEx.
 */
#include <stddef.h>

#ifdef REEVE_HAVE_PYCONFIG
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <dlfcn.h>
#include <stdio.h>

/* 0: initialized; -1: initialization failed, the reason in err; -2: PyConfig entry points missing */
int reeve_init_configured(const char *home, char *err, size_t esize)
{
    void (*init_config)(PyConfig *) = (void (*)(PyConfig *))dlsym(RTLD_DEFAULT, "PyConfig_InitPythonConfig");
    PyStatus (*set_bytes)(PyConfig *, wchar_t **, const char *) =
        (PyStatus(*)(PyConfig *, wchar_t **, const char *))dlsym(RTLD_DEFAULT, "PyConfig_SetBytesString");
    PyStatus (*init_from)(const PyConfig *) =
        (PyStatus(*)(const PyConfig *))dlsym(RTLD_DEFAULT, "Py_InitializeFromConfig");
    void (*clear)(PyConfig *) = (void (*)(PyConfig *))dlsym(RTLD_DEFAULT, "PyConfig_Clear");
    PyConfig config;
    PyStatus status;

    if (!init_config || !set_bytes || !init_from || !clear) return -2;
    init_config(&config);
    config.install_signal_handlers = 0; /* the host owns the signals */
    config.parse_argv = 0;
    if (home && *home) {
        status = set_bytes(&config, &config.home, home);
        if (status._type != 0) {
            snprintf(err, esize, "setting the Python home to %s failed: %s", home,
                     status.err_msg ? status.err_msg : "unknown error");
            clear(&config);
            return -1;
        }
    }
    status = init_from(&config);
    clear(&config);
    if (status._type != 0) {
        snprintf(err, esize, "Python failed to initialize with home %s: %s%s%s", home && *home ? home : "(none)",
                 status.func ? status.func : "", status.func ? ": " : "",
                 status.err_msg ? status.err_msg : "unknown error");
        return -1;
    }
    return 0;
}
#else
int reeve_init_configured(const char *home, char *err, size_t esize)
{
    (void)home;
    (void)err;
    (void)esize;
    return -2;
}
#endif
