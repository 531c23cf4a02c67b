"""A standalone FMU: the interpreter travels with it (`reeve-fmu build --standalone`).

`add_to_fmu(fmu, requirements)` puts the runtime of the Python that builds the FMU into
resources/reeve_runtime/:

    manifest.json                        Python version, packages and their versions, sizes
    lib/libpython3.X.so.1.0              the shared interpreter
    lib/python3.X/                       its standard library and lib-dynload (no tests, tkinter,
                                         idlelib, ensurepip, lib2to3, static library)
    lib/python3.X/site-packages/         the packages the model imports (numpy, numba and what they
                                         need: llvmlite), with their metadata, no tests

Every module is byte-compiled as an unchecked-hash .pyc: the host's extraction sets its own file times,
and a timestamp-checked .pyc would be recompiled (or, in a read-only folder, compiled again on every
run). The native loader (fmu_loader.c) finds the bundle in a host without Python and starts that
interpreter with the bundle as its home; in a Python host of the same minor version the bundle's
packages fill in what the host lacks (`_bootstrap.preflight`).
"""
from __future__ import annotations

import compileall
import json
import os
import py_compile
import re
import shutil
import sys
import sysconfig
import tempfile
import zipfile
from importlib import metadata
from pathlib import Path

from ._bootstrap import RUNTIME_DIR
from .native import libpython_path

__all__ = ["add_to_fmu", "stage_runtime", "RUNTIME_DIR"]

#: stdlib parts a model never imports (tests, GUI, packaging tools, the static library)
_STDLIB_SKIP = {"test", "tests", "idlelib", "tkinter", "turtledemo", "ensurepip", "lib2to3", "pydoc_data",
                "__pycache__", "site-packages", "dist-packages"}
_DYNLOAD_SKIP = re.compile(r"^(_tkinter|_test|xxlimited|_xxtestfuzz|_ctypes_test|xxsubtype)")


def _copy_stdlib(dst: Path) -> None:
    std = Path(sysconfig.get_paths()["stdlib"])
    for root, dirs, files in os.walk(std):
        rel = Path(root).relative_to(std)
        dirs[:] = sorted(d for d in dirs if d not in _STDLIB_SKIP and not d.startswith("config-"))
        for f in files:
            if f.endswith((".pyc", ".pyo")) or (rel.name == "lib-dynload" and _DYNLOAD_SKIP.match(f)):
                continue
            target = dst / rel / f
            target.parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(Path(root) / f, target)
    dynload = Path(sysconfig.get_paths().get("platstdlib", std)) / "lib-dynload"
    if dynload.is_dir() and not (dst / "lib-dynload").is_dir():   # a distribution's separate platstdlib
        for f in dynload.iterdir():
            if f.is_file() and not _DYNLOAD_SKIP.match(f.name):
                (dst / "lib-dynload").mkdir(exist_ok=True)
                shutil.copy2(f, dst / "lib-dynload" / f.name)


def _distribution_names(requirements) -> list:
    """The distributions the model imports and, recursively, what they require (markers of extras
    excluded)."""
    todo = [r["module"] for r in requirements if not r.get("python_below")
            or sys.version_info[:2] < tuple(int(x) for x in str(r["python_below"]).split("."))]
    seen = {}
    while todo:
        name = todo.pop()
        key = name.lower().replace("_", "-")
        if key in seen:
            continue
        try:
            dist = metadata.distribution(name)
        except metadata.PackageNotFoundError:
            continue                      # an optional package the build has not got
        seen[key] = dist
        for req in dist.requires or []:
            if "extra ==" in req:
                continue
            todo.append(re.split(r"[ ;<>=!~\[(]", req.strip(), 1)[0])
    return sorted(seen.values(), key=lambda d: d.metadata["Name"].lower())


#: subpackages a distribution keeps (the rest is never imported by the model): scipy's model use is
#: scipy.sparse (with csgraph and linalg), which needs scipy.linalg and scipy._lib
_KEEP_SUBPACKAGES = {"scipy": {"_lib", "linalg", "sparse"}}
#: files only a build uses: bytecode of other kinds, stubs, static libraries, C/Cython sources
_NOT_RUN = (".pyc", ".pyi", ".a", ".pxd", ".pyx", ".c", ".cpp")


def _copy_distribution(dist, site: Path) -> int:
    n = 0
    keep = _KEEP_SUBPACKAGES.get(dist.metadata["Name"].lower())
    for f in dist.files or []:
        parts = Path(f).parts
        if parts[0] == ".." or "__pycache__" in parts or "tests" in parts or str(f).endswith(_NOT_RUN):
            continue
        if keep and len(parts) > 2 and parts[0] in _KEEP_SUBPACKAGES and parts[1] not in keep:
            continue
        src = Path(dist.locate_file(f))
        if src.is_file():
            target = site / f
            target.parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(src, target)
            n += 1
    return n


def _tops(dist) -> set:
    """The top-level names a distribution installs into site-packages (package, .libs, .dist-info)."""
    return {Path(f).parts[0] for f in dist.files or [] if Path(f).parts[0] != ".."}


def _link_tree(src: Path, dst: Path) -> None:
    if src.is_dir():
        shutil.copytree(src, dst, copy_function=os.link)
    else:
        os.link(src, dst)


def stage_runtime(dest: Path, requirements, reuse: Path = None) -> dict:
    """Lay out the runtime under dest (see the module doc); returns the manifest. `reuse`: a runtime
    this process staged before; its interpreter, byte-compiled standard library and the distributions
    both need are hard-linked, so only the new distributions are copied and compiled."""
    version = f"{sys.version_info.major}.{sys.version_info.minor}"
    lib = libpython_path()
    if not lib:
        raise RuntimeError(f"this Python ({sys.executable}) has no shared libpython: a standalone FMU "
                           f"needs a Python built with --enable-shared (python.org, pyenv with "
                           f"PYTHON_CONFIGURE_OPTS=--enable-shared, or a distribution's libpython{version})")
    stdlib = dest / "lib" / f"python{version}"
    site = stdlib / "site-packages"
    if reuse is None:
        (dest / "lib").mkdir(parents=True)
        shutil.copy2(os.path.realpath(lib), dest / "lib" / f"libpython{version}.so.1.0")
        _copy_stdlib(stdlib)
        compile_dirs = [stdlib]
    else:
        old_site = reuse / "lib" / f"python{version}" / "site-packages"
        shutil.copytree(reuse / "lib", dest / "lib", copy_function=os.link,
                        ignore=lambda d, names: ["site-packages"] if Path(d) == old_site.parent else [])
        compile_dirs = []
    site.mkdir()
    packages = {}
    for dist in _distribution_names(requirements):
        tops = _tops(dist)
        if reuse is not None and tops and all((old_site / t).exists() for t in tops):
            for t in tops:
                _link_tree(old_site / t, site / t)
        else:
            _copy_distribution(dist, site)
            if reuse is not None:    # a first staging compiles the whole stdlib, site-packages included
                compile_dirs += [site / t for t in tops if (site / t).is_dir()]
        packages[dist.metadata["Name"]] = dist.version
    for d in compile_dirs:
        compileall.compile_dir(str(d), quiet=2, workers=0 if os.cpu_count() else 1,
                               invalidation_mode=py_compile.PycInvalidationMode.UNCHECKED_HASH)
    libs = {p.relative_to(dest).as_posix(): p.stat().st_size for p in sorted(dest.rglob("*.so*")) if p.is_file()}
    manifest = {"format": "reeve_fmu.runtime/1", "python_version": version,
                "python_full_version": sys.version.split()[0], "packages": packages,
                "bytes": sum(p.stat().st_size for p in dest.rglob("*") if p.is_file()),
                "libraries": libs}   # sizes checked before use: a damaged library would crash the host
    (dest / "manifest.json").write_text(json.dumps(manifest, indent=1) + "\n", encoding="utf-8")
    return manifest


_STAGED: dict = {}   # distributions -> (TemporaryDirectory, manifest): the plant and drive FMUs share one


#: deflate level of the runtime's entries: level 1 compresses the ~360 MB runtime 3.2x faster than
#: zlib's default 6 (6.7 s against 21.7 s) for an 11 % larger archive (134 against 120 MB)
RUNTIME_COMPRESSLEVEL = 1


def _zip_runtime(stage: Path, zip_path: Path, prefix: str) -> None:
    """The staged runtime as zip entries under `prefix`, compressed once: every FMU of the process starts
    from a copy of this file (compressing the ~360 MB runtime is most of a standalone build)."""
    with zipfile.ZipFile(zip_path, "w", zipfile.ZIP_DEFLATED) as zout:
        for p in sorted(stage.rglob("*")):
            if p.is_file():
                zi = zipfile.ZipInfo(prefix + p.relative_to(stage).as_posix(), date_time=(2020, 1, 1, 0, 0, 0))
                zi.compress_type = zipfile.ZIP_DEFLATED
                zi.external_attr = (0o755 if p.suffix == ".so" or ".so." in p.name else 0o644) << 16
                with open(p, "rb") as fh:
                    zout.writestr(zi, fh.read(), compresslevel=RUNTIME_COMPRESSLEVEL)


def _staged(requirements, prefix: str):
    key = tuple(d.metadata["Name"].lower() for d in _distribution_names(requirements))
    if key not in _STAGED:
        tmp = tempfile.TemporaryDirectory(prefix="reeve_runtime_")
        earlier = next(iter(_STAGED.values()), None)
        manifest = stage_runtime(Path(tmp.name) / RUNTIME_DIR, requirements,
                                 reuse=Path(earlier[0].name) / RUNTIME_DIR if earlier else None)
        _zip_runtime(Path(tmp.name) / RUNTIME_DIR, Path(tmp.name) / "runtime.zip", prefix)
        _STAGED[key] = (tmp, manifest)
    tmp, manifest = _STAGED[key]
    return Path(tmp.name) / "runtime.zip", manifest


def add_to_fmu(fmu_path, requirements) -> dict:
    """Stage the runtime (once per process and set of packages) and write it into the FMU's
    resources/reeve_runtime/; returns the manifest."""
    fmu_path = Path(fmu_path)
    prefix = f"resources/{RUNTIME_DIR}/"
    runtime_zip, manifest = _staged(requirements, prefix)
    with tempfile.TemporaryDirectory(prefix="reeve_runtime_fmu_", dir=fmu_path.parent) as tmp:
        new = Path(tmp) / "new.fmu"
        shutil.copyfile(runtime_zip, new)
        with zipfile.ZipFile(fmu_path) as zin, zipfile.ZipFile(new, "a") as zout:
            for item in zin.infolist():
                if not item.filename.startswith(prefix):
                    zout.writestr(item, zin.read(item.filename))
        shutil.move(str(new), fmu_path)
    return manifest
