"""The native loader in front of pythonfmu's binary (Linux x86-64): compile it and put it into an FMU.

pythonfmu 0.7.0's binary (binaries/linux64/<id>.so) needs a Python in the process's global symbol
scope, leaves the embedded interpreter without the build environment's packages, reports errors only
in debug-logging mode, and double-frees a shared_ptr at exit. `fmu_loader.c` (next to this file,
mechanism described at its top) fixes all four in front of it. `install_loader(fmu)` compiles it for
the FMU's model identifier and rewrites the FMU:

    binaries/linux64/<id>.so            the loader (what every host loads)
    binaries/linux64/<id>_pythonfmu.so  pythonfmu's binary, renamed
    binaries/linux64/<id>_pyexit.so     helper: an empty finalizePythonInterpreter in global scope

The C compiler: $CC, else cc / gcc / clang on PATH, else the `ziglang` package (`python -m ziglang
cc`, pip-installable, targets glibc 2.17 so the FMU runs on older Linux too). Without any of them the
FMU keeps pythonfmu's binary and `NoCompiler` says what to install.

`environment_record()` is what the build stores as resources/reeve_env.json: the interpreter, its
libpython and site-packages, and the model's requirements; the loader and the FMU's bootstrap use it
to start the same Python with the same packages in a non-Python host.
"""
from __future__ import annotations

import json
import os
import shutil
import site
import subprocess
import sys
import sysconfig
import tempfile
import zipfile
from pathlib import Path
from typing import Optional, Sequence

__all__ = ["SOURCE", "ENV_NAME", "NoCompiler", "find_compiler", "compile_loader", "install_loader",
           "environment_record", "libpython_path", "loader_supported"]

SOURCE = Path(__file__).resolve().with_name("fmu_loader.c")
PYINIT = SOURCE.with_name("pyinit.c")   # the interpreter's start with PyConfig (the build Python's headers)
ENV_NAME = "reeve_env.json"
PLATFORM_DIR = "binaries/linux64"


class NoCompiler(RuntimeError):
    """No C compiler: the message says what to install."""


def loader_supported() -> bool:
    """The loader exists for Linux x86-64 (pythonfmu's linux64 binary)."""
    import platform

    return sys.platform.startswith("linux") and platform.machine() in ("x86_64", "AMD64")


def libpython_path() -> Optional[str]:
    """Absolute path of this interpreter's shared libpython, or None (statically linked build)."""
    libdir = sysconfig.get_config_var("LIBDIR")
    name = sysconfig.get_config_var("INSTSONAME") or sysconfig.get_config_var("LDLIBRARY")
    for base in (libdir, os.path.join(sys.base_prefix, "lib")):
        if base and name and ".so" in name:
            p = os.path.join(base, name)
            if os.path.isfile(p):
                return os.path.abspath(p)
    return None


def _site_dirs() -> list:
    dirs = []
    try:
        dirs += list(site.getsitepackages())
    except AttributeError:  # pragma: no cover - old virtualenv
        pass
    try:
        if site.ENABLE_USER_SITE and os.path.isdir(site.getusersitepackages()):
            dirs.append(site.getusersitepackages())
    except Exception:  # pragma: no cover
        pass
    return [os.path.abspath(d) for d in dirs if os.path.isdir(d)]


def environment_record(requirements: Sequence[dict]) -> dict:
    """What resources/reeve_env.json holds (see the module doc).

    requirements: [{"module": "numpy", "requirement": "numpy>=1.24", "optional": False,
                    "python_below": None or "3.11"}, ...]"""
    return {
        "format": "reeve_fmu.env/1",
        "python_version": f"{sys.version_info.major}.{sys.version_info.minor}",
        "python_full_version": sys.version.split()[0],
        "executable": os.path.abspath(sys.executable),
        "prefix": sys.prefix,
        "base_prefix": sys.base_prefix,
        "libpython": libpython_path(),
        "site_packages": _site_dirs(),
        "requirements": list(requirements),
    }


def find_compiler() -> list:
    """The command (argv prefix) of a C compiler, or raise NoCompiler saying what to install."""
    cc = os.environ.get("CC")
    if cc:
        import shlex

        argv = shlex.split(cc)
        if argv and shutil.which(argv[0]):
            return argv
    for name in ("cc", "gcc", "clang"):
        if shutil.which(name):
            return [name]
    try:
        import ziglang  # noqa: F401

        return [sys.executable, "-m", "ziglang", "cc", "-target", "x86_64-linux-gnu.2.17"]
    except ImportError:
        pass
    raise NoCompiler(
        "no C compiler found for the FMU's native loader (tried $CC, cc, gcc, clang and the Python "
        "package 'ziglang'). Install one: 'pip install ziglang' (a compiler packaged as a wheel), or "
        "'apt install gcc' / 'dnf install gcc'. Without the loader the FMU still runs in Python hosts "
        "(fmpy, libcosimpy) but needs LD_PRELOAD=<libpython> in C hosts and may abort at exit.")


def _pyconfig_flags() -> list:
    """Compiler flags for pyinit.c's PyConfig start: this interpreter's headers, when it has them
    (a Python without its development files: none, and the loader uses Py_SetPythonHome)."""
    inc = sysconfig.get_paths().get("include")
    plat = sysconfig.get_paths().get("platinclude")
    if not inc or not os.path.isfile(os.path.join(inc, "Python.h")):
        return []
    dirs = [inc] + ([plat] if plat and plat != inc else [])
    return ["-DREEVE_HAVE_PYCONFIG", *(f"-I{d}" for d in dirs)]


def _c_string(s: str) -> str:
    return '"' + s.replace("\\", "\\\\").replace('"', '\\"') + '"'


def compile_loader(model_identifier: str, out_dir, *, libpython: Optional[str] = None,
                   py_version: Optional[str] = None, compiler: Optional[list] = None,
                   fmi_version: int = 2) -> dict:
    """Compile the loader and the exit helper for `model_identifier` into out_dir (fmi_version 3:
    with the FMI 3.0 adapter, fmi3.c).

    Returns {"loader": path, "helper": path, "compiler": argv}. Raises NoCompiler, or RuntimeError
    with the compiler's output."""
    if not model_identifier.isidentifier():
        raise ValueError(f"model identifier {model_identifier!r} is not a C identifier")
    cc = list(compiler) if compiler else find_compiler()
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    if py_version is None:
        py_version = f"{sys.version_info.major}.{sys.version_info.minor}"
    if libpython is None:
        libpython = libpython_path() or ""
    same_python = py_version == f"{sys.version_info.major}.{sys.version_info.minor}"
    home = sys.base_prefix if same_python else ""
    common = ["-shared", "-fPIC", "-O2", "-fvisibility=hidden", "-Wl,-z,nodelete", "-Wl,-Bsymbolic"]
    loader = out / f"{model_identifier}.so"
    helper = out / f"{model_identifier}_pyexit.so"
    jobs = [
        [*cc, *common, f"-DREEVE_MODEL_IDENTIFIER={_c_string(model_identifier)}",
         f"-DREEVE_LIBPYTHON={_c_string(libpython)}", f"-DREEVE_PY_VERSION={_c_string(py_version)}",
         f"-DREEVE_PYHOME={_c_string(home)}", *(_pyconfig_flags() if same_python else []),
         *(["-DREEVE_FMI3"] if fmi_version == 3 else []),
         "-o", str(loader), str(SOURCE), str(PYINIT), "-ldl", "-lpthread"],
        [*cc, *common, "-DREEVE_EXIT_HELPER", "-o", str(helper), str(SOURCE)],
    ]
    for argv in jobs:
        try:
            p = subprocess.run(argv, capture_output=True, text=True, encoding="utf-8",
                               errors="replace", timeout=300)
        except (OSError, subprocess.TimeoutExpired) as exc:
            raise RuntimeError(f"compiling the FMU loader failed: {' '.join(argv)}: {exc}") from exc
        if p.returncode != 0:
            raise RuntimeError(f"compiling the FMU loader failed ({p.returncode}): {' '.join(argv)}\n"
                               f"{p.stdout}{p.stderr}")
    return {"loader": str(loader), "helper": str(helper), "compiler": cc}


def install_loader(fmu_path, model_identifier: str, *, compiler: Optional[list] = None,
                   libpython: Optional[str] = None, py_version: Optional[str] = None,
                   fmi_version: int = 2) -> dict:
    """Compile the loader and rewrite the FMU at fmu_path in place (see the module doc).

    Returns the compile info. The FMU must hold pythonfmu's binaries/linux64/<id>.so."""
    fmu_path = Path(fmu_path)
    orig = f"{PLATFORM_DIR}/{model_identifier}.so"
    with tempfile.TemporaryDirectory(prefix="reeve_loader_") as tmp:
        info = compile_loader(model_identifier, tmp, libpython=libpython, py_version=py_version,
                              compiler=compiler, fmi_version=fmi_version)
        new = Path(tmp) / "new.fmu"
        with zipfile.ZipFile(fmu_path) as zin, zipfile.ZipFile(new, "w", zipfile.ZIP_DEFLATED) as zout:
            names = zin.namelist()
            pyfmu = f"{PLATFORM_DIR}/{model_identifier}_pythonfmu.so"
            helper = f"{PLATFORM_DIR}/{model_identifier}_pyexit.so"
            if orig not in names:
                raise RuntimeError(f"{fmu_path.name} has no {orig} (not a pythonfmu FMU?)")
            again = pyfmu in names   # the FMU has a loader already: <id>.so is that loader
            for item in zin.infolist():
                data = zin.read(item.filename)
                if item.filename == orig:
                    if again:
                        continue
                    item.filename = pyfmu
                elif item.filename == helper:
                    continue
                zout.writestr(item, data)
            for src, name in ((info["loader"], f"{model_identifier}.so"),
                              (info["helper"], f"{model_identifier}_pyexit.so")):
                zi = zipfile.ZipInfo(f"{PLATFORM_DIR}/{name}", date_time=(2020, 1, 1, 0, 0, 0))
                zi.compress_type = zipfile.ZIP_DEFLATED
                zi.external_attr = 0o755 << 16
                zout.writestr(zi, Path(src).read_bytes())
        os.replace(new, fmu_path)
    return {"compiler": info["compiler"], "libpython": libpython if libpython is not None else libpython_path(),
            "files": [f"{model_identifier}.so", f"{model_identifier}_pythonfmu.so",
                      f"{model_identifier}_pyexit.so"]}


def read_env(fmu_path) -> Optional[dict]:
    """The FMU's resources/reeve_env.json, or None."""
    try:
        with zipfile.ZipFile(fmu_path) as zf:
            return json.loads(zf.read(f"resources/{ENV_NAME}").decode("utf-8"))
    except (OSError, KeyError, ValueError, zipfile.BadZipFile):
        return None
