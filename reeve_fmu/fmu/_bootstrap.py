"""Stdlib-only bootstrap of the vendored ``reeve_fmu`` package inside an FMU (and the source hash).

Why this exists
---------------
The package uses numba with ``cache=True``. Inside an FMU the package is extracted by the importer to
a fresh temporary directory on every run (fmpy ``extract``, libcosim, ...). numba keys its on-disk
cache by the source file's path and stamp (mtime, size), so a fresh directory is a guaranteed cache
miss: every instantiate would pay the full JIT compile again.

The fix (verified by tests/test_fmu_machinery.py): the FMU does not expose the package directly.
``build_fmu`` puts

* ``resources/reeve_fmu_vendor/reeve_fmu/``  the package sources (no ``__pycache__``),
* ``resources/reeve_fmu_stamp.json``         version + sha256 of those sources,
* ``resources/reeve_fmu.py``                 a copy of *this file* (the "shim").

pythonfmu puts ``resources/`` first on ``sys.path`` and imports the entry module, whose
``import reeve_fmu`` then finds the shim (unless the host already imported reeve_fmu). When executed
under the module name ``reeve_fmu`` the shim

1. copies ``reeve_fmu_vendor/reeve_fmu`` once to a stable per-user directory keyed by the source
   hash, ``<cache>/<sha256[:16]>/reeve_fmu`` (``<cache>`` = ``$REEVE_FMU_CACHE_DIR`` or
   ``$XDG_CACHE_HOME/reeve_fmu`` or ``~/.cache/reeve_fmu``). The copy is made in a sibling temp
   directory and renamed into place atomically, so concurrent processes never see half a copy;
   an existing directory is reused untouched (its mtimes and numba cache stay valid);
2. loads the real package from there and replaces itself in ``sys.modules`` (the import system
   returns ``sys.modules[name]`` after executing a module, so ``import reeve_fmu`` yields the real
   package, and all its submodules load from the stable directory);
3. records what it did in ``reeve_fmu._reeve_fmu_boot`` (dict: hash, location, warning).

If the cache directory cannot be written, the package is loaded straight from the extracted
resources (correct, only slower: numba compiles each run) and the reason is recorded as a warning,
which ``ReeveSlave`` logs.

If the host process already imported ``reeve_fmu`` (e.g. the CLI running a co-simulation), the
shim is never executed and the host's package is used; ``ReeveSlave`` then compares the FMU's stamp
with the hash of the loaded package and logs a warning when they differ.

This module must stay importable without numpy/pythonfmu and without the rest of the package.
"""
from __future__ import annotations

import hashlib
import json
import os
import shutil
import sys
import tempfile

STAMP_NAME = "reeve_fmu_stamp.json"
VENDOR_DIR = "reeve_fmu_vendor"
PACKAGE = "reeve_fmu"

_SKIP_DIRS = {"__pycache__"}
_SKIP_SUFFIXES = (".pyc", ".pyo", ".nbi", ".nbc", ".so.tmp")


def _wanted(name: str, is_dir: bool) -> bool:
    if name.startswith("."):
        return False
    if is_dir:
        return name not in _SKIP_DIRS
    return not name.endswith(_SKIP_SUFFIXES)


def package_files(pkg_dir: str) -> list:
    """Relative posix paths of the package's source/data files (sorted; what gets vendored/hashed)."""
    out = []
    for root, dirs, files in os.walk(pkg_dir):
        dirs[:] = sorted(d for d in dirs if _wanted(d, True))
        for f in files:
            if _wanted(f, False):
                rel = os.path.relpath(os.path.join(root, f), pkg_dir)
                out.append(rel.replace(os.sep, "/"))
    return sorted(out)


def package_hash(pkg_dir: str) -> str:
    """sha256 over (relative path, content) of every vendored file of the package directory."""
    h = hashlib.sha256()
    for rel in package_files(pkg_dir):
        with open(os.path.join(pkg_dir, *rel.split("/")), "rb") as fh:
            data = fh.read()
        h.update(rel.encode("utf-8") + b"\0" + str(len(data)).encode() + b"\0" + data)
    return h.hexdigest()


def copy_package(src_pkg_dir: str, dst_pkg_dir: str) -> None:
    """Copy the package (only the files `package_files` lists), preserving mtimes."""
    for rel in package_files(src_pkg_dir):
        src = os.path.join(src_pkg_dir, *rel.split("/"))
        dst = os.path.join(dst_pkg_dir, *rel.split("/"))
        os.makedirs(os.path.dirname(dst), exist_ok=True)
        shutil.copy2(src, dst)


def cache_root() -> str:
    env = os.environ.get("REEVE_FMU_CACHE_DIR")
    if env:
        return env
    if sys.platform.startswith("win"):
        base = os.environ.get("LOCALAPPDATA") or os.path.expanduser("~")
        return os.path.join(base, "reeve_fmu", "cache")
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return os.path.join(base, "reeve_fmu")


def ensure_cached_copy(src_pkg_dir: str, digest: str) -> str:
    """Return ``<cache>/<digest[:16]>`` holding ``reeve_fmu/``; create it atomically if missing."""
    root = cache_root()
    final = os.path.join(root, digest[:16])
    if os.path.isfile(os.path.join(final, PACKAGE, "__init__.py")):
        return final
    os.makedirs(root, exist_ok=True)
    tmp = tempfile.mkdtemp(prefix=f".{digest[:16]}-", dir=root)
    try:
        copy_package(src_pkg_dir, os.path.join(tmp, PACKAGE))
        with open(os.path.join(tmp, STAMP_NAME), "w") as fh:
            json.dump({"sha256": digest}, fh)
        try:
            os.rename(tmp, final)
        except OSError:
            # another process won the race (or a broken leftover is in the way)
            if not os.path.isfile(os.path.join(final, PACKAGE, "__init__.py")):
                shutil.rmtree(final, ignore_errors=True)
                os.rename(tmp, final)
    finally:
        if os.path.isdir(tmp):
            shutil.rmtree(tmp, ignore_errors=True)
    return final


def _install_from_resources() -> None:  # pragma: no cover - runs inside FMUs (tested via subprocess)
    """Executed when this file is imported as the module ``reeve_fmu`` from an FMU's resources."""
    import importlib.util

    here = os.path.dirname(os.path.abspath(__file__))
    src_pkg = os.path.join(here, VENDOR_DIR, PACKAGE)
    info = {"hash": None, "location": None, "warning": None, "resources": here}
    try:
        with open(os.path.join(here, STAMP_NAME)) as fh:
            digest = json.load(fh)["sha256"]
        info["hash"] = digest
        base = ensure_cached_copy(src_pkg, digest)
        pkg_dir = os.path.join(base, PACKAGE)
    except Exception as exc:  # read-only home, full disk, ...: run from the extracted copy
        pkg_dir = src_pkg
        info["warning"] = (f"reeve_fmu: could not use the package cache ({exc!r}); running from the "
                           f"extracted FMU resources, numba will recompile on every run")
    info["location"] = pkg_dir
    spec = importlib.util.spec_from_file_location(
        PACKAGE, os.path.join(pkg_dir, "__init__.py"), submodule_search_locations=[pkg_dir])
    module = importlib.util.module_from_spec(spec)
    module._reeve_fmu_boot = info
    sys.modules[PACKAGE] = module
    try:
        spec.loader.exec_module(module)
    except BaseException:
        sys.modules.pop(PACKAGE, None)
        raise


if __name__ == PACKAGE:  # imported as the shim `reeve_fmu` (resources/reeve_fmu.py)
    _install_from_resources()
