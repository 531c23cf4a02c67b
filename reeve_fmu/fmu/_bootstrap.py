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
ENV_NAME = "reeve_env.json"
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
        with open(os.path.join(tmp, STAMP_NAME), "w", encoding="utf-8") as fh:
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


def _site_dirs_first(dirs) -> list:
    """site.addsitedir each directory (with its .pth files) and move what that added in front of the
    interpreter's own site-packages, so that the recorded environment wins over the base one."""
    import site

    before = list(sys.path)
    for d in dirs:
        if os.path.isdir(d):
            site.addsitedir(d)
    added = [p for p in sys.path if p not in before]
    if not added:
        return []
    rest = [p for p in sys.path if p not in added]
    pos = next((i for i, p in enumerate(rest) if os.path.basename(p) in ("site-packages", "dist-packages")),
               len(rest))
    sys.path[:] = rest[:pos] + added + rest[pos:]
    return added


def _applies(req: dict) -> bool:
    below = req.get("python_below")
    if not below:
        return True
    major, minor = (int(x) for x in str(below).split(".")[:2])
    return sys.version_info[:2] < (major, minor)


def preflight(resources: str, embedded: bool = False, where: str = "") -> tuple:
    """Run by the FMU's native loader before pythonfmu instantiates the model: returns
    (error or None, warning or None), both plain text for the host's logger.

    * REEVE_FMU_SITE_PACKAGES (os.pathsep-separated directories) is added in any host;
    * otherwise, when the loader started the interpreter itself (a non-Python host) and it is the
      Python version the FMU was built with, the build environment's site-packages recorded in
      resources/reeve_env.json are added (before the interpreter's own);
    * then every requirement recorded there is imported; a missing one is an error naming the
      package, the Python in use and what to install (an optional one only a warning)."""
    try:
        with open(os.path.join(resources, ENV_NAME), encoding="utf-8") as fh:
            env = json.load(fh)
    except FileNotFoundError:
        return None, None
    except Exception as exc:
        return f"resources/{ENV_NAME} is unreadable: {exc!r}", None
    import importlib

    cur = f"{sys.version_info.major}.{sys.version_info.minor}"
    built = env.get("python_version")
    override = os.environ.get("REEVE_FMU_SITE_PACKAGES", "")
    added = []
    if override:
        added = _site_dirs_first([d for d in override.split(os.pathsep) if d])
    elif embedded and built == cur:
        added = _site_dirs_first(env.get("site_packages") or [])
    missing, optional = [], []
    for req in env.get("requirements") or []:
        if not _applies(req):
            continue
        try:
            importlib.import_module(req["module"])
        except Exception as exc:  # ImportError, or a broken/incompatible binary package
            (optional if req.get("optional") else missing).append((req, f"{type(exc).__name__}: {exc}"))
    python = (f"Python {sys.version.split()[0]} ("
              + (f"loaded by the FMU from {where}" if embedded else f"the host's, {sys.executable}") + ")")
    if embedded:
        exe = env.get("executable") if built == cur else f"python{cur}"
    else:
        exe = sys.executable or f"python{cur}"
    warning = None
    if optional:
        warning = "; ".join(f"optional package {r['module']} is not usable in {python} ({why}): "
                            f"{r.get('why') or 'the model runs without it'}" for r, why in optional)
    if not missing:
        return None, warning
    pkgs = ", ".join(r["module"] for r, _ in missing)
    reqs = " ".join(f"'{r['requirement'].split(';')[0].strip()}'" for r, _ in missing)
    lines = [f"the Python package(s) {pkgs} the model needs cannot be imported in {python}:"]
    lines += [f"  {r['module']}: {why}" for r, why in missing]
    lines.append(f"Install them into that Python: {exe} -m pip install {reqs} (the FMU's "
                 f"resources/requirements.txt lists all it needs).")
    if embedded:
        lines.append(
            f"This FMU was built with Python {env.get('python_full_version')} ({env.get('executable')}; "
            f"site-packages {', '.join(env.get('site_packages') or []) or 'none recorded'}"
            + (", added to sys.path" if added else "") + "). Or point REEVE_FMU_SITE_PACKAGES to a "
            f"site-packages directory of a Python {cur} environment that has them, or "
            f"REEVE_FMU_LIBPYTHON to the libpython of another Python.")
    else:
        lines.append("Or set REEVE_FMU_SITE_PACKAGES to a site-packages directory of a Python "
                     f"{cur} environment that has them.")
    return "\n".join(lines), warning


def _install_from_resources() -> None:  # pragma: no cover - runs inside FMUs (tested via subprocess)
    """Executed when this file is imported as the module ``reeve_fmu`` from an FMU's resources."""
    import importlib.util

    here = os.path.dirname(os.path.abspath(__file__))
    src_pkg = os.path.join(here, VENDOR_DIR, PACKAGE)
    info = {"hash": None, "location": None, "warning": None, "resources": here}
    try:
        with open(os.path.join(here, STAMP_NAME), encoding="utf-8") as fh:
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
